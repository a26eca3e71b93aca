//! `scatterscope bench-hidden`: the confocal scans of a folder through the
//! hidden-object methods, at full counts and thinned.

use std::path::PathBuf;

use scatterscope::confocal::PoissonOptions;
use scatterscope::report::hidden_bench::{
    BLUR_BASELINE, HiddenBenchConfig, parse_blur, run_hidden_bench, write_results,
};
use scatterscope::units::parse_ps;

/// Benchmark the hidden-object reconstructions on the confocal scans of a
/// folder (named as the published ones: letter_s.mat, letter_u_50.mat, ...).
///
/// Each scan at each count fraction (binomially thinned, seeded) through
/// each method (the published one, its blur baselines, the default `auto`
/// and optionally `poisson`): the front projection's correlation with the published
/// method's at full counts, the object's depth, the median wall time.
/// Writes OUT/rows.csv and OUT/summary.md (with the letter-U depth series).
#[derive(Debug, clap::Args)]
pub struct BenchHiddenArgs {
    /// Folder of scans.
    dir: PathBuf,
    /// Bin width of the scans (default unit ps); MATLAB files do not
    /// record it.
    #[arg(long = "bin-width", value_name = "TIME", value_parser = parse_ps, default_value = "16")]
    bin_width_ps: f64,
    /// Fractions of the counts kept.
    #[arg(long, value_delimiter = ',', default_value = "1,0.1,0.01")]
    fractions: Vec<f64>,
    /// Seed of the thinning.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Runs per row; the time is their median.
    #[arg(long, default_value_t = 5)]
    repeats: usize,
    /// Also run the Poisson method (once per row, about 10 s each).
    #[arg(long)]
    poisson: bool,
    /// With --poisson: most iterations its stop searches.
    #[arg(long, requires = "poisson", default_value_t = PoissonOptions::default().max_iters)]
    poisson_cap: usize,
    /// Blur baselines, ACROSSxDEPTH (Gaussian sigma in voxels), comma
    /// separated: a row of the published method followed by each blur, so
    /// no method is credited for what a blur does ("none": no baseline;
    /// default: the one chosen on the shared scans, 1.5x3).
    #[arg(long, value_delimiter = ',', value_parser = parse_blur)]
    blur: Option<Vec<Option<(f64, f64)>>>,
    /// Output directory.
    #[arg(long, default_value = "out/bench-hidden")]
    out: PathBuf,
}

pub fn run(args: &BenchHiddenArgs) -> anyhow::Result<()> {
    let cfg = HiddenBenchConfig {
        dir: args.dir.clone(),
        bin_width_ps: args.bin_width_ps,
        fractions: args.fractions.clone(),
        seed: args.seed,
        repeats: args.repeats,
        poisson: args.poisson.then_some(PoissonOptions {
            max_iters: args.poisson_cap,
            ..PoissonOptions::default()
        }),
        blurs: args.blur.as_ref().map_or(vec![BLUR_BASELINE], |b| {
            b.iter().flatten().copied().collect()
        }),
    };
    let (rows, md) = run_hidden_bench(&cfg, |r| println!("{}", r.line()))?;
    write_results(&args.out, &rows, &md)?;
    println!("{md}");
    println!("wrote {}/{{rows.csv, summary.md}}", args.out.display());
    Ok(())
}
