//! `scatterscope bench-recon`: the held-out reconstruction benchmark.

use std::path::PathBuf;

use crate::shared_args::{PhysicsArgs, choice};
use anyhow::Context;
use clap::ValueEnum;
use scatterscope::denoise::Denoiser;
use scatterscope::reconstruct::method::Solver;
use scatterscope::report::bench::{
    level_setup, pnp_entries, read_manifest, rl_default_label, rows_csv, run_case, select,
    simulate_case, summary_markdown,
};

use crate::recon_args::{DenoiserChoice, PriorArgs, ReconArgs};

/// Reconstruction benchmark on images the methods were not tuned on.
///
/// Reads DIR/manifest.csv and its images (write them with `python3
/// scripts/bench_images.py DIR`), simulates each image at each light level
/// with the object extending past the sensor, and runs PnP (each solver and
/// prior given), PnP on the time-summed stack, and Richardson-Lucy on the
/// time-summed stack (its default output, its stop chosen by
/// cross-validation on thinned halves of the counts, and its best iteration
/// chosen with the truth). Writes OUT/rows.csv, OUT/summary.md and the PnP traces (PSNR
/// against wall time) as OUT/traces/IMAGE_LEVEL_METHOD.csv.
#[derive(Debug, clap::Args)]
pub struct BenchReconArgs {
    /// Directory with manifest.csv and the images.
    images: PathBuf,
    /// Which images: tuning, held-out or all.
    #[arg(long, default_value = "held-out")]
    split: String,
    /// Only these images (by manifest name; default all of the split).
    #[arg(long = "image", value_name = "NAME")]
    only: Vec<String>,
    /// Light levels relative to the physics' budget.
    #[arg(long, value_delimiter = ',', default_value = "0.1,1,10")]
    levels: Vec<f64>,
    /// PnP solvers to run on the whole stack.
    #[arg(
        long,
        value_parser = choice::<Solver>(),
        value_delimiter = ',',
        default_value = "split,admm-lbfgs"
    )]
    solvers: Vec<Solver>,
    /// Priors to run with each solver (the first is the headline prior).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "ffdnet,tv")]
    priors: Vec<DenoiserChoice>,
    /// Skip PnP on the time-summed stack.
    #[arg(long)]
    no_sum: bool,
    /// Richardson-Lucy iterations searched for its best iteration.
    #[arg(long, default_value_t = 1000)]
    rl_best_iters: usize,
    /// Side of the simulated object grid (pixels); the sensor sees its centre.
    #[arg(long, default_value_t = 384)]
    object_px: usize,
    #[command(flatten)]
    physics: PhysicsArgs,
    #[command(flatten)]
    recon: ReconArgs,
    /// Seed of the Poisson sampler.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output directory.
    #[arg(long, default_value = "out/bench-recon")]
    out: PathBuf,
}

pub fn run(args: &BenchReconArgs) -> anyhow::Result<()> {
    let base = args.physics.resolve()?;
    let opts = args.recon.options()?;
    let images =
        select(read_manifest(&args.images)?, &args.split, &args.only).context("--split")?;
    anyhow::ensure!(
        !images.is_empty(),
        "no image of {} matches",
        args.images.display()
    );
    let setups = args
        .levels
        .iter()
        .map(|&level| Ok((level, level_setup(&base, level).context("--levels")?)))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let priors: Vec<(String, Box<dyn Denoiser>)> = args
        .priors
        .iter()
        .map(|&p| {
            let prior = PriorArgs {
                denoiser: p,
                ..args.recon.prior.clone()
            };
            let name = p
                .to_possible_value()
                .expect("every prior has a name")
                .get_name()
                .to_string();
            Ok((name, prior.denoiser()?))
        })
        .collect::<anyhow::Result<_>>()?;
    let entries = pnp_entries(&args.solvers, &priors, !args.no_sum);
    anyhow::ensure!(!entries.is_empty(), "no solver or prior given");
    let headline = entries[0].label.clone();
    let traces = args.out.join("traces");
    std::fs::create_dir_all(&traces)
        .with_context(|| format!("creating output directory {}", traces.display()))?;
    let mut rows = Vec::new();
    for image in &images {
        for &(level, ref setup) in &setups {
            let case = simulate_case(image, setup, args.object_px, args.seed)?;
            let new = run_case(
                image,
                level,
                &case,
                &entries,
                &opts,
                args.rl_best_iters,
                |label, trace| {
                    let file = traces.join(format!(
                        "{}_{level}_{}.csv",
                        image.name,
                        label.replace(' ', "_")
                    ));
                    if let Err(e) = std::fs::write(&file, trace.to_csv()) {
                        eprintln!("could not write {}: {e}", file.display());
                    }
                },
            )?;
            for r in &new {
                println!(
                    "{:<18} {:>5}x {:<36} {:>6.2} dB (best {:>6.2} @ {:>4}) {:>7.2} s{}",
                    r.image,
                    r.level,
                    r.method,
                    r.psnr,
                    r.best_psnr,
                    r.best_iteration,
                    r.wall_s,
                    r.deviance_z
                        .map_or(String::new(), |z| format!("  deviance z {z:.1}"))
                );
            }
            rows.extend(new);
            std::fs::write(args.out.join("rows.csv"), rows_csv(&rows))?;
        }
    }
    let md = summary_markdown(&rows, &headline, &rl_default_label(&opts));
    std::fs::write(args.out.join("summary.md"), &md)?;
    println!("{md}");
    println!(
        "wrote {}/{{rows.csv, summary.md, traces/}}",
        args.out.display()
    );
    Ok(())
}
