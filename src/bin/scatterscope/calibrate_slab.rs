//! `scatterscope calibrate-slab`: mu_s' and mu_a from time-resolved
//! transmittance captures of slabs of known thickness.

use std::path::PathBuf;

use anyhow::Context;
use scatterscope::Named;
use scatterscope::calibrate::histogram::{DEFAULT_MAT_DATASET, DEFAULT_MAT_PARTS};
use scatterscope::calibrate::transmittance::SlabFitOptions;
use scatterscope::report::calibration::{IrfExtent, SlabJob};

use crate::shared_args::{choice, note_renamed_parameters};
use scatterscope::units::parse_ps;

/// Fit mu_s' and mu_a to transmittance captures through slabs.
///
/// The diffusion slab convolved with the response measured without the
/// slab (--irf-from), plus a background; mu_s' and mu_a shared by every
/// capture. --predict captures are predicted by the fitted medium. Writes
/// OUT/fit.csv and OUT/fit_LABEL.png per capture.
#[derive(Debug, clap::Args)]
pub struct CalibrateSlabArgs {
    /// Captures to fit, each FILE=THICKNESS with its unit, e.g. c.mat=1in.
    #[arg(long = "capture", required = true, value_name = "FILE=THICKNESS")]
    captures: Vec<String>,
    /// Captures the fitted medium predicts, FILE=THICKNESS.
    #[arg(long = "predict", value_name = "FILE=THICKNESS")]
    predict: Vec<String>,
    /// The instrument response: a capture without the slab.
    #[arg(long)]
    irf_from: PathBuf,
    /// How much of the reference is the response: its whole period (the
    /// peak, pedestal and tail) or the peak's run above the background.
    #[arg(long, value_parser = choice::<IrfExtent>(), default_value = IrfExtent::default().name())]
    irf_extent: IrfExtent,
    /// Bin width of MATLAB files, which do not record it (default unit ps;
    /// e.g. 16ps).
    #[arg(long = "bin-width", value_name = "TIME", value_parser = parse_ps)]
    bin_width_ps: Option<f64>,
    /// Dataset holding the histogram in MATLAB files.
    #[arg(long, default_value = DEFAULT_MAT_DATASET)]
    dataset: String,
    /// Per-part histograms in MATLAB files (summed, parts shared with
    /// another capture dropped; the output says which), or `none`.
    #[arg(long, default_value = DEFAULT_MAT_PARTS)]
    parts: String,
    #[command(flatten)]
    options: SlabFitOptions,
    /// What to fit, comma-separated: mu_a, mu_s_reduced (`mu_s`, its old
    /// name, still works), detector_offset (`offset`, its old name).
    #[arg(long, value_delimiter = ',', default_value = "mu_a,mu_s_reduced")]
    fit: Vec<String>,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/calibrate-slab")]
    out: PathBuf,
}

pub fn run(args: &CalibrateSlabArgs) -> anyhow::Result<()> {
    let mut options = args.options;
    note_renamed_parameters("--fit", &args.fit);
    options.free_named(&args.fit).context("--fit")?;
    let job = SlabJob {
        irf_from: args.irf_from.clone(),
        irf_extent: args.irf_extent,
        captures: args.captures.clone(),
        predict: args.predict.clone(),
        dataset: args.dataset.clone(),
        parts: (args.parts != "none").then(|| args.parts.clone()),
        bin_width_ps: args.bin_width_ps,
        options,
    };
    let done = job.run()?;
    for line in done.lines() {
        println!("{line}");
    }
    let warnings = done.warnings();
    for w in &warnings {
        println!("warning: {w}");
    }
    let files = done.write(&args.out)?;
    for line in done.describe_written(&args.out, &files) {
        println!("{line}");
    }
    crate::signals::warned(warnings.len())
}
