//! `scatterscope simulate`: truth image, expected stack and Poisson counts.

use std::path::{Path, PathBuf};

use crate::shared_args::{PhysicsArgs, choice};
use anyhow::Context;
use scatterscope::formats::exr;
use scatterscope::formats::png::{SheetScale, write_contact_sheet, write_png};
use scatterscope::forward::Boundary;
use scatterscope::physics::Sampling;
use scatterscope::scene::Scene;
use scatterscope::simulate::simulate;
use scatterscope::stack::Stack;

use crate::physics_summary::{parse_sampling, print_setup};

/// Simulate a transient measurement of a scene through the scattering slab.
///
/// Writes truth.{exr,png}, expected.{exr,png} (noise-free expected counts)
/// and counts.{exr,png} (Poisson-sampled photon counts), plus .npy/.json
/// copies of both stacks with --npy. Bins whose ST-PSF carries fewer than
/// --min-bin-photons are left out and listed.
#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    /// Object: a built-in scene (usaf, star, text, disks) or a PNG/JPEG/EXR file.
    #[arg(long, default_value = "usaf", value_name = "SCENE|FILE")]
    scene: String,
    #[command(flatten)]
    physics: PhysicsArgs,
    /// How the sensor's edges are modelled: sensor (the scene fills the
    /// sensor's field, dark outside it; light off the sensor is lost, as on
    /// a real sensor) or periodic (wrap-around, the paper's simulation).
    #[arg(long, value_parser = choice::<Boundary>(), default_value = "sensor")]
    boundary: Boundary,
    /// Seed of the Poisson sampler (the same seed gives the same counts).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// ST-PSF discretisation: integrated (correct) or point (for comparison).
    #[arg(long, default_value = "integrated", value_parser = parse_sampling)]
    sampling: Sampling,
    /// Contact-sheet scaling.
    #[arg(long, value_parser = choice::<SheetScale>(), default_value = "shared")]
    sheet_scale: SheetScale,
    /// Also write the stacks as .npy with JSON metadata sidecars.
    #[arg(long)]
    npy: bool,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/simulate")]
    out: PathBuf,
}

pub fn run(args: &SimulateArgs) -> anyhow::Result<()> {
    let setup = args.physics.resolve()?;
    let scene = Scene::parse(&args.scene);
    let sim = simulate(&setup, &scene, args.sampling, args.boundary, args.seed)?;
    print_setup(&setup, &sim.kernels);
    let (h, w) = (setup.sensor.height_px, setup.sensor.width_px);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating output directory {}", args.out.display()))?;
    let (truth, kernels) = (&sim.truth, &sim.kernels);
    let (expected_stack, counts_stack) = (&sim.expected, &sim.counts);
    let truth_f32 = truth.mapv(|v| v as f32);
    exr::write_image(truth_f32.view(), &args.out.join("truth.exr"))?;
    write_png(truth.view(), Some(1.0), &args.out.join("truth.png"))?;
    for (name, stack) in [("expected", expected_stack), ("counts", counts_stack)] {
        write_stack(stack, &args.out, name, args.npy, args.sheet_scale)?;
    }

    println!(
        "scene {} at {}x{}: {} bins kept of {}, expected {:.1} photons, sampled {} (seed {})",
        scene.name(),
        w,
        h,
        kernels.len(),
        setup.bins.count,
        expected_stack.total(),
        counts_stack.total(),
        args.seed
    );
    println!(
        "{:>3} {:>8} {:>12} {:>10} {:>10}",
        "bin", "start ps", "expected", "counts", "max count"
    );
    for k in 0..counts_stack.bins() {
        let max = counts_stack.bin(k).iter().fold(0.0f32, |m, &v| m.max(v));
        println!(
            "{:>3} {:>8.1} {:>12.1} {:>10} {:>10}",
            k,
            counts_stack.meta.bin_starts_ps[k],
            expected_stack
                .bin(k)
                .iter()
                .map(|&v| f64::from(v))
                .sum::<f64>(),
            counts_stack
                .bin(k)
                .iter()
                .map(|&v| f64::from(v))
                .sum::<f64>(),
            max
        );
    }
    if sim.clamped > 0 {
        println!(
            "clamped {} expected-count values made negative by FFT round-off (most negative {:.3e}) to 0",
            sim.clamped, sim.most_negative
        );
    }
    let t = sim.timings;
    println!(
        "run time: PSF {:.1} ms, kernel spectra {:.1} ms, forward model {:.1} ms, Poisson {:.1} ms",
        t.psf_s * 1e3,
        t.spectra_s * 1e3,
        t.forward_s * 1e3,
        t.poisson_s * 1e3
    );
    println!("wrote {}", args.out.display());
    Ok(())
}

fn write_stack(
    stack: &Stack,
    dir: &Path,
    name: &str,
    npy: bool,
    scale: SheetScale,
) -> anyhow::Result<()> {
    stack.save(&dir.join(format!("{name}.exr")))?;
    write_contact_sheet(stack, scale, &dir.join(format!("{name}.png")))?;
    if npy {
        stack.save(&dir.join(format!("{name}.npy")))?;
    }
    Ok(())
}
