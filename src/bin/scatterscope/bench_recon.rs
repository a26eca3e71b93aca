//! `scatterscope bench-recon`: the held-out reconstruction benchmark.

use std::path::PathBuf;

use scatterscope::denoise::prior::PriorSpec;
use scatterscope::report::bench::{BenchConfig, batch_jobs, merge_benchmark, run_benchmark};

use crate::recon_args::ReconArgs;
use crate::shared_args::{given_flags, resolve};
use scatterscope::config::PhysicsOverrides;

/// Reconstruction benchmark on images the methods were not tuned on.
///
/// Simulates each image of DIR/manifest.csv (`python3
/// scripts/bench_images.py DIR`) at each light level and runs every method
/// on it; writes OUT/rows.csv, OUT/summary.md and the traces in OUT/traces.
#[derive(Debug, clap::Args)]
pub struct BenchReconArgs {
    #[command(flatten)]
    config: BenchConfig,
    #[command(flatten)]
    physics: PhysicsOverrides,
    /// Write the benchmark as a batch manifest instead of running it: one
    /// job per image, the other flags passed on (run it with `batch`
    /// --out OUT, locally or with --slurm; then --merge with --out OUT).
    #[arg(long, value_name = "MANIFEST", conflicts_with_all = ["merge", "resume"])]
    write_batch: Option<PathBuf>,
    /// Gather the rows of a batch's jobs (OUT/IMAGE/rows.csv) into the one
    /// summary a single run writes.
    #[arg(long)]
    merge: bool,
    /// The flags each job of --write-batch runs with ([`forwarded`]).
    #[arg(skip)]
    pub forwarded: Vec<String>,
    #[command(flatten)]
    recon: ReconArgs,
}

/// This run's flags as parsed, without the image folder, --image, --out
/// and the batch flags: what each job of a batch runs with.
pub fn forwarded(matches: &clap::ArgMatches) -> Vec<String> {
    let command = <BenchReconArgs as clap::Args>::augment_args(clap::Command::new("bench-recon"));
    given_flags(
        matches,
        &command,
        &["images", "only", "out", "write_batch", "merge", "resume"],
    )
}

pub fn run(args: &BenchReconArgs) -> anyhow::Result<()> {
    let mut cfg = BenchConfig {
        setup: resolve(&args.physics)?,
        opts: args.recon.options()?,
        rl_fixed_iters: args.recon.rl_iters,
        ..args.config.clone()
    };
    // The prior flags' weights and gain, for every prior run.
    for prior in &mut cfg.priors {
        *prior = PriorSpec {
            kind: prior.kind,
            ..args.recon.prior.clone()
        };
    }
    if let Some(manifest) = &args.write_batch {
        let jobs = batch_jobs(&cfg, &args.forwarded)?;
        scatterscope::batch::write_manifest(manifest, &jobs)?;
        println!(
            "wrote {} ({} jobs): run it with `scatterscope batch {} --out OUT` (or --slurm), then `scatterscope bench-recon {} --merge --out OUT` with the same flags",
            manifest.display(),
            jobs.len(),
            manifest.display(),
            args.config.images.display()
        );
        return Ok(());
    }
    if args.merge {
        let (_, md) = merge_benchmark(&cfg)?;
        println!("{md}");
        println!(
            "wrote {}/{{rows.csv, summary.md}}",
            args.config.out.display()
        );
        return Ok(());
    }
    let (_, md) = run_benchmark(&cfg, |row| println!("{}", row.line()))?;
    println!("{md}");
    println!(
        "wrote {}/{{rows.csv, summary.md, traces/}}",
        args.config.out.display()
    );
    Ok(())
}
