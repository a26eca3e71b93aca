//! `scatterscope psf`: the ST-PSF kernel stack and its per-bin table.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use crate::shared_args::{PhysicsArgs, choice};
use anyhow::Context;
use ndarray::ArrayView2;
use scatterscope::formats::png::{SheetScale, write_contact_sheet};
use scatterscope::physics::{KernelStack, Sampling};
use scatterscope::stack::{Stack, StackMeta, ValueKind};

use crate::physics_summary::{parse_sampling, print_setup};

/// Compute the ST-PSF for each time bin and write it with a per-bin table.
///
/// Writes psf.exr (one channel per kept bin, centred kernels, expected
/// photons per pixel from a unit object pixel), psf_bins.csv and
/// psf_sheet.png. Both discretisations (pixel/bin-integrated and point
/// sampled) are computed and their difference and run times are reported.
#[derive(Debug, clap::Args)]
pub struct PsfArgs {
    #[command(flatten)]
    physics: PhysicsArgs,
    /// Discretisation written to psf.exr: integrated (over pixel area and
    /// bin duration) or point (samples at pixel and bin centres).
    #[arg(long, default_value = "integrated", value_parser = parse_sampling)]
    sampling: Sampling,
    /// Contact-sheet scaling.
    #[arg(long, value_parser = choice::<SheetScale>(), default_value = "per-bin")]
    sheet_scale: SheetScale,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/psf")]
    out: PathBuf,
}

pub fn run(args: &PsfArgs) -> anyhow::Result<()> {
    let setup = args.physics.resolve()?;
    let timed = |sampling| -> anyhow::Result<(KernelStack, f64)> {
        let t = Instant::now();
        let k = KernelStack::build(&setup, sampling)?;
        Ok((k, t.elapsed().as_secs_f64()))
    };
    let (integrated, t_int) = timed(Sampling::Integrated)?;
    // Point samples cannot model an instrument response: with one, they
    // are not built for comparison (and refused when asked for).
    let point = match (&setup.irf, args.sampling) {
        (Some(_), Sampling::Integrated) => None,
        _ => Some(timed(Sampling::Point)?),
    };
    let chosen = match (&point, args.sampling) {
        (Some((p, _)), Sampling::Point) => p,
        _ => &integrated,
    };
    print_setup(&setup, chosen);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating output directory {}", args.out.display()))?;

    let mut csv = String::from(
        "bin,start_ps,end_ps,photons,kept,sigma_px,peak,support_radius_px,time_nodes,point_vs_integrated_rel_l1\n",
    );
    println!(
        "{:>3} {:>13} {:>10} {:>5} {:>8} {:>10} {:>7} {:>5} {:>10}",
        "bin", "time ps", "photons", "kept", "sigma px", "peak", "support", "nodes", "point-int"
    );
    let mut worst: (f64, usize) = (0.0, 0);
    for b in &chosen.bins {
        let diff = point.as_ref().and_then(|(point, _)| {
            integrated
                .position_of_bin(b.index)
                .zip(point.position_of_bin(b.index))
                .map(|(i, p)| relative_l1(integrated.kernel(i), point.kernel(p)))
        });
        if let Some(d) = diff.filter(|d| *d > worst.0) {
            worst = (d, b.index);
        }
        let diff_text = diff.map_or("-".to_string(), |d| format!("{d:.2e}"));
        println!(
            "{:>3} {:>6.1}-{:<6.1} {:>10.4} {:>5} {:>8.3} {:>10.3e} {:>7} {:>5} {:>10}",
            b.index,
            b.start_ps,
            b.end_ps,
            b.photons,
            b.kept,
            b.sigma_px,
            b.peak,
            b.support_radius_px,
            b.time_nodes,
            diff_text
        );
        writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{},{}",
            b.index,
            b.start_ps,
            b.end_ps,
            b.photons,
            b.kept,
            b.sigma_px,
            b.peak,
            b.support_radius_px,
            b.time_nodes,
            diff.map_or(String::new(), |d| d.to_string())
        )
        .expect("writing to a String");
    }
    match &point {
        Some((point, t_point)) => {
            println!(
                "run time: integrated {:.1} ms, point {:.1} ms; largest point-vs-integrated relative L1 difference {:.3e} (bin {}); written: {}",
                t_int * 1e3,
                t_point * 1e3,
                worst.0,
                worst.1,
                args.sampling.name()
            );
            if point.len() != integrated.len() {
                println!(
                    "note: point sampling keeps {} bins, integrated keeps {}",
                    point.len(),
                    integrated.len()
                );
            }
        }
        None => println!(
            "run time: integrated {:.1} ms; point sampling not compared (it cannot model the instrument response); written: integrated",
            t_int * 1e3
        ),
    }

    let csv_path = args.out.join("psf_bins.csv");
    std::fs::write(&csv_path, csv).with_context(|| format!("writing {}", csv_path.display()))?;
    let stack = Stack {
        data: chosen.kernels.mapv(|v| v as f32),
        meta: StackMeta::simulated(chosen, ValueKind::Kernel, "scatterscope psf".into()),
    };
    if stack.bins() == 0 {
        anyhow::bail!(
            "no bin carries at least {} photons; lower --min-bin-photons",
            setup.min_bin_photons
        );
    }
    stack.save(&args.out.join("psf.exr"))?;
    write_contact_sheet(&stack, args.sheet_scale, &args.out.join("psf_sheet.png"))?;
    println!(
        "wrote {}/{{psf.exr, psf_bins.csv, psf_sheet.png}}",
        args.out.display()
    );
    Ok(())
}

fn relative_l1(a: ArrayView2<f64>, b: ArrayView2<f64>) -> f64 {
    let diff: f64 = a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum();
    diff / a.sum()
}
