//! `scatterscope bench-hidden`: the confocal scans of a folder through the
//! hidden-object methods, at full counts and thinned.

use std::path::PathBuf;

use scatterscope::confocal::PoissonOptions;
use scatterscope::report::hidden_bench::{
    BLUR_BASELINE, HiddenBenchConfig, rows_csv, run_hidden_bench,
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
    #[arg(long, value_name = "TIME", value_parser = parse_ps, default_value = "16")]
    bin_width: f64,
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
        bin_width_ps: args.bin_width,
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
    let (rows, md) = run_hidden_bench(&cfg, |r| {
        println!(
            "{:<14} {:>5}% {:<26} corr {:.3}  depth {:>6}  {:.3} s{}",
            r.scan,
            r.fraction * 100.0,
            r.method,
            r.correlation,
            r.depth_cm.map_or("-".into(), |d| format!("{d:.1}")),
            r.wall_s,
            r.blur
                .map_or(String::new(), |b| format!("  blur {:.2}x{:.2}", b.0, b.1))
        )
    })?;
    std::fs::create_dir_all(&args.out)?;
    scatterscope::files::write_atomic(args.out.join("rows.csv"), rows_csv(&rows))?;
    scatterscope::files::write_atomic(args.out.join("summary.md"), &md)?;
    println!("{md}");
    println!("wrote {}/{{rows.csv, summary.md}}", args.out.display());
    Ok(())
}

/// `ACROSSxDEPTH` in voxels, or `none`.
fn parse_blur(text: &str) -> Result<Option<(f64, f64)>, String> {
    if text == "none" {
        return Ok(None);
    }
    let bad = || {
        format!("blur {text:?}: give ACROSSxDEPTH, Gaussian sigma in voxels (e.g. 1.5x3), or none")
    };
    let (a, d) = text.split_once('x').ok_or_else(bad)?;
    let (a, d): (f64, f64) = (a.parse().map_err(|_| bad())?, d.parse().map_err(|_| bad())?);
    if !(a.is_finite() && d.is_finite() && a >= 0.0 && d >= 0.0) {
        return Err(bad());
    }
    Ok(Some((a, d)))
}
