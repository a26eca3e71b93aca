//! `scatterscope calibrate-slab`: mu_s' and mu_a from time-resolved
//! transmittance captures of slabs of known thickness.

use std::path::PathBuf;

use anyhow::Context;
use scatterscope::calibrate::histogram::{DEFAULT_MAT_DATASET, DEFAULT_MAT_PARTS};
use scatterscope::calibrate::transmittance::{RISING_EDGE_CONVENTION, SlabFitOptions};
use scatterscope::report::calibration::{IrfExtent, SlabJob};

use crate::shared_args::{FileBinWidthArgs, choice, note_renamed_parameters};

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
    #[arg(long, value_parser = choice::<IrfExtent>(), default_value = "period")]
    irf_extent: IrfExtent,
    #[command(flatten)]
    bin_width: FileBinWidthArgs,
    /// Dataset holding the histogram in MATLAB files.
    #[arg(long, default_value = DEFAULT_MAT_DATASET)]
    dataset: String,
    /// Per-part histograms in MATLAB files (summed, parts shared with
    /// another capture dropped; the output says which), or `none`.
    #[arg(long, default_value = DEFAULT_MAT_PARTS)]
    parts: String,
    /// Refractive index of the medium (not fitted).
    #[arg(long)]
    refractive_index: f64,
    /// Starting mu_a (1/cm).
    #[arg(long, default_value_t = 0.01)]
    mu_a: f64,
    /// Starting reduced scattering coefficient mu_s' (1/cm).
    #[arg(long, default_value_t = 5.0)]
    mu_s_reduced: f64,
    /// Starting (or fixed) distance of the detector from the axis (cm).
    #[arg(long, value_name = "CM", default_value_t = 0.0)]
    detector_offset: f64,
    /// What to fit, comma-separated: mu_a, mu_s_reduced (`mu_s`, its old
    /// name, still works), detector_offset (`offset`, its old name).
    #[arg(long, value_delimiter = ',', default_value = "mu_a,mu_s_reduced")]
    fit: Vec<String>,
    /// Leave out the rising edge before the excess reaches this share of
    /// the peak's (where diffusion is least accurate; 0 fits every bin).
    #[arg(long, default_value_t = RISING_EDGE_CONVENTION)]
    rising_edge_share: f64,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/calibrate-slab")]
    out: PathBuf,
}

pub fn run(args: &CalibrateSlabArgs) -> anyhow::Result<()> {
    let mut options = SlabFitOptions {
        refractive_index: args.refractive_index,
        mu_a_per_cm: args.mu_a,
        mu_s_reduced_per_cm: args.mu_s_reduced,
        fit_mu_a: false,
        fit_mu_s_reduced: false,
        offset_cm: args.detector_offset,
        fit_offset: false,
        rising_edge_share: args.rising_edge_share,
    };
    let bin_width_ps = args.bin_width.bin_width;
    note_renamed_parameters("--fit", &args.fit);
    options.free_named(&args.fit).context("--fit")?;
    let job = SlabJob {
        irf_from: args.irf_from.clone(),
        irf_extent: args.irf_extent,
        captures: args.captures.clone(),
        predict: args.predict.clone(),
        dataset: args.dataset.clone(),
        parts: (args.parts != "none").then(|| args.parts.clone()),
        bin_width_ps,
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
    let names: Vec<String> = files
        .iter()
        .filter_map(|f| f.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    println!("wrote {}/{{{}}}", args.out.display(), names.join(", "));
    if !files.iter().any(|f| f.ends_with("material.toml")) {
        println!("material.toml not written: the fit is doubtful (see the warnings)");
    }
    crate::signals::warned(warnings.len())
}
