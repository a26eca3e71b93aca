//! `scatterscope bench-recon`: the held-out reconstruction benchmark.

use std::path::PathBuf;

use scatterscope::denoise::prior::{PriorKind, PriorSpec};
use scatterscope::reconstruct::method::Solver;
use scatterscope::report::bench::{
    BenchConfig, BenchMethod, batch_jobs, merge_benchmark, run_benchmark,
};

use crate::recon_args::ReconArgs;
use crate::shared_args::{choice, given_flags, resolve};
use scatterscope::config::PhysicsOverrides;

/// Reconstruction benchmark on images the methods were not tuned on.
///
/// Simulates each image of DIR/manifest.csv (`python3
/// scripts/bench_images.py DIR`) at each light level and runs every method
/// on it; writes OUT/rows.csv, OUT/summary.md and the traces in OUT/traces.
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
    #[arg(long, value_parser = choice::<PriorKind>(), value_delimiter = ',', default_value = "ffdnet,tv")]
    priors: Vec<PriorKind>,
    /// Skip PnP on the time-summed stack.
    #[arg(long)]
    no_sum: bool,
    /// Methods to run (RL's best iteration, the reference, always runs).
    #[arg(
        long,
        value_parser = choice::<BenchMethod>(),
        value_delimiter = ',',
        default_value = "pnp,rl-sum,rl-stack,auto"
    )]
    methods: Vec<BenchMethod>,
    /// Richardson-Lucy iterations searched for its best iteration.
    #[arg(long, default_value_t = 1000)]
    rl_best_iters: usize,
    /// Side of the simulated object grid (pixels); the sensor sees its centre.
    #[arg(long, default_value_t = 384)]
    object_px: usize,
    #[command(flatten)]
    physics: PhysicsOverrides,
    #[command(flatten)]
    recon: ReconArgs,
    /// Seed of the Poisson sampler.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output directory.
    #[arg(long, default_value = "out/bench-recon")]
    out: PathBuf,
    /// Keep the cases OUT/rows.csv already holds (an interrupted run goes
    /// on; the summary covers both).
    #[arg(long)]
    resume: bool,
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
    let cfg = BenchConfig {
        images: args.images.clone(),
        split: args.split.clone(),
        only: args.only.clone(),
        levels: args.levels.clone(),
        solvers: args.solvers.clone(),
        priors: args
            .priors
            .iter()
            .map(|&kind| PriorSpec {
                kind,
                ..args.recon.prior.clone()
            })
            .collect(),
        time_summed: !args.no_sum,
        methods: args.methods.clone(),
        rl_best_iters: args.rl_best_iters,
        rl_fixed_iters: args.recon.rl_iters,
        object_px: args.object_px,
        setup: resolve(&args.physics)?,
        opts: args.recon.options()?,
        seed: args.seed,
        out: args.out.clone(),
        resume: args.resume,
    };
    if let Some(manifest) = &args.write_batch {
        let jobs = batch_jobs(&cfg, &args.forwarded)?;
        scatterscope::batch::write_manifest(manifest, &jobs)?;
        println!(
            "wrote {} ({} jobs): run it with `scatterscope batch {} --out OUT` (or --slurm), then `scatterscope bench-recon {} --merge --out OUT` with the same flags",
            manifest.display(),
            jobs.len(),
            manifest.display(),
            args.images.display()
        );
        return Ok(());
    }
    if args.merge {
        let (_, md) = merge_benchmark(&cfg)?;
        println!("{md}");
        println!("wrote {}/{{rows.csv, summary.md}}", args.out.display());
        return Ok(());
    }
    let (_, md) = run_benchmark(&cfg, |row| println!("{}", row.line()))?;
    println!("{md}");
    println!(
        "wrote {}/{{rows.csv, summary.md, traces/}}",
        args.out.display()
    );
    Ok(())
}
