//! `scatterscope simulate`: truth image, expected stack and Poisson counts.

use std::path::PathBuf;

use scatterscope::formats::png::SheetScale;
use scatterscope::forward::Boundary;
use scatterscope::physics::Sampling;
use scatterscope::physics::validity::describe_setup;
use scatterscope::scene::Scene;
use scatterscope::simulate::simulate;

use crate::shared_args::{choice, resolve};
use scatterscope::config::PhysicsOverrides;

/// Simulate a transient measurement of a scene through the scattering slab.
///
/// Writes truth.{exr,png}, expected.{exr,png} and counts.{exr,png} (and
/// .npy copies with --npy).
#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    /// Object: a built-in scene (usaf, star, text, disks) or a PNG/JPEG/EXR file.
    #[arg(long, default_value = "usaf", value_name = "SCENE|FILE")]
    scene: String,
    #[command(flatten)]
    physics: PhysicsOverrides,
    /// How the sensor's edges are modelled: sensor (the scene fills the
    /// sensor's field, dark outside it; light off the sensor is lost, as on
    /// a real sensor) or periodic (wrap-around, the paper's simulation).
    #[arg(long, value_parser = choice::<Boundary>(), default_value = "sensor")]
    boundary: Boundary,
    /// Seed of the Poisson sampler (the same seed gives the same counts).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// ST-PSF discretisation: integrated (correct) or point (for comparison).
    #[arg(long, default_value = "integrated", value_parser = choice::<Sampling>())]
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
    let setup = resolve(&args.physics)?;
    let scene = Scene::parse(&args.scene);
    let sim = simulate(&setup, &scene, args.sampling, args.boundary, args.seed)?;
    for line in describe_setup(&setup, &sim.kernels) {
        eprintln!("{line}");
    }
    sim.write(&args.out, args.npy, args.sheet_scale)?;
    for line in sim.summary(&scene, args.seed) {
        println!("{line}");
    }
    println!("wrote {}", args.out.display());
    Ok(())
}
