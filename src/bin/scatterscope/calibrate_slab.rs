//! `scatterscope calibrate-slab`: mu_s' and mu_a from time-resolved
//! transmittance captures of slabs of known thickness.

use std::path::PathBuf;

use anyhow::Context;
use scatterscope::calibrate::histogram::{DEFAULT_MAT_DATASET, DEFAULT_MAT_PARTS, TimeHistogram};
use scatterscope::calibrate::measured_irf::MeasuredIrf;
use scatterscope::calibrate::outputs::write_slab_fits;
use scatterscope::calibrate::transmittance::{
    RISING_EDGE_CONVENTION, SlabFitOptions, fit_slab, predict_captures, read_captures,
};

/// Fit mu_s' and mu_a to transmittance captures through slabs.
///
/// Each capture is one detector's time histogram on the laser's axis
/// behind a slab of known thickness. The model is the diffusion slab with
/// extrapolated boundaries, convolved with the instrument response measured
/// without the slab (--irf-from), plus a constant background; mu_s' and
/// mu_a are shared, time zero, signal and background are each capture's.
/// Captures given with --predict are not fitted: the fitted medium predicts
/// them (only their time zero, signal and background are fitted), to test
/// the medium on data it never saw. Writes OUT/fit.csv and a plot per
/// capture, OUT/fit_LABEL.png (log counts, measured and model).
#[derive(Debug, clap::Args)]
pub struct CalibrateSlabArgs {
    /// Captures to fit, each FILE=THICKNESS (THICKNESS with its unit: cm,
    /// mm, m or in), e.g. capture_1_0_inch.mat=1in.
    #[arg(long = "capture", required = true, value_name = "FILE=THICKNESS")]
    captures: Vec<String>,
    /// Captures the fitted medium predicts, FILE=THICKNESS.
    #[arg(long = "predict", value_name = "FILE=THICKNESS")]
    predict: Vec<String>,
    /// The instrument response: a capture without the slab.
    #[arg(long)]
    irf_from: PathBuf,
    /// How much of the reference is the response: `period` keeps its whole
    /// recorded laser period (the peak plus the slow pedestal and tail
    /// that follow the light, as excess over the reference's lowest
    /// level); `peak` keeps the run of bins around the peak that stands
    /// out of the background just before it.
    #[arg(long, value_enum, default_value_t = IrfExtent::Period)]
    irf_extent: IrfExtent,
    /// Bin width (ps) of MATLAB histograms, which do not record it.
    #[arg(long)]
    bin_ps: Option<f64>,
    /// Dataset holding the histogram in MATLAB files.
    #[arg(long, default_value = DEFAULT_MAT_DATASET)]
    dataset: String,
    /// Cell array of per-part histograms in MATLAB files (e.g. one per
    /// second of acquisition), or `none`. Where a file has it, the capture
    /// is the sum of its parts, after dropping parts that also occur in
    /// another capture given here and do not match the capture's own
    /// (a buffer not cleared between captures); the output says what was
    /// kept.
    #[arg(long, default_value = DEFAULT_MAT_PARTS)]
    parts: String,
    /// Refractive index of the medium (not fitted).
    #[arg(long)]
    refractive_index: f64,
    /// Starting mu_a (1/cm).
    #[arg(long, default_value_t = 0.01)]
    mu_a: f64,
    /// Starting mu_s' (1/cm).
    #[arg(long, default_value_t = 5.0)]
    mu_s: f64,
    /// Starting (or fixed) distance of the detector from the laser's axis
    /// on the far face (cm).
    #[arg(long, default_value_t = 0.0)]
    offset_cm: f64,
    /// What to fit, comma-separated: mu_a, mu_s, offset (the detector's
    /// distance from the laser's axis); the others stay at their starting
    /// values.
    #[arg(long, value_delimiter = ',', default_value = "mu_a,mu_s")]
    fit: Vec<String>,
    /// Leave the rising edge out of the fit: the bins after the window's
    /// first 50 (kept for the background) and before the first whose
    /// excess reaches this share of the peak's (time-domain diffuse
    /// optics' usual 0.8 by default, where diffusion is least accurate;
    /// 0 fits every bin). The output gives chi-square over the fitted bins
    /// and over the whole window.
    #[arg(long, default_value_t = RISING_EDGE_CONVENTION)]
    rising_edge_share: f64,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/calibrate-slab")]
    out: PathBuf,
}

/// How much of the reference recording is the instrument response.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum IrfExtent {
    /// The whole recorded period ([`MeasuredIrf::from_histogram_period`]).
    Period,
    /// The peak's run ([`MeasuredIrf::from_histogram`]).
    Peak,
}

pub fn run(args: &CalibrateSlabArgs) -> anyhow::Result<()> {
    let reference = TimeHistogram::read(&args.irf_from, &args.dataset, args.bin_ps)?;
    let irf = match args.irf_extent {
        IrfExtent::Period => MeasuredIrf::from_histogram_period(&reference)?,
        IrfExtent::Peak => MeasuredIrf::from_histogram(&reference)?,
    };
    println!("{}", irf.describe());
    let specs: Vec<&str> = args
        .captures
        .iter()
        .chain(&args.predict)
        .map(String::as_str)
        .collect();
    let parts = (args.parts != "none").then_some(args.parts.as_str());
    let (mut captures, notes) = read_captures(&specs, &args.dataset, parts, args.bin_ps)?;
    for note in &notes {
        println!("parts: {note}");
    }
    let held = captures.split_off(args.captures.len());
    let mut opts = SlabFitOptions {
        refractive_index: args.refractive_index,
        mu_a_per_cm: args.mu_a,
        mu_s_reduced_per_cm: args.mu_s,
        fit_mu_a: false,
        fit_mu_s_reduced: false,
        offset_cm: args.offset_cm,
        fit_offset: false,
        rising_edge_share: args.rising_edge_share,
    };
    opts.free_named(&args.fit).context("--fit")?;
    println!("model: {}", opts.describe_model(&irf));
    let started = std::time::Instant::now();
    let fit = fit_slab(&captures, &irf, &opts)?;
    let title = format!(
        "joint fit of {} captures ({} single-capture model evaluations, {:.1} s):",
        captures.len(),
        fit.evaluations,
        started.elapsed().as_secs_f64()
    );
    for line in fit.lines(&title) {
        println!("{line}");
    }
    let mut groups = vec![(&captures[..], &fit, "fitted")];
    let prediction = if held.is_empty() {
        None
    } else {
        let pred = predict_captures(&held, &irf, &fit.fixed())?;
        for line in pred.lines("prediction of captures left out of the fit (medium fixed):") {
            println!("{line}");
        }
        Some(pred)
    };
    if let Some(pred) = &prediction {
        groups.push((&held[..], pred, "predicted"));
    }
    let files = write_slab_fits(&args.out, &groups)?;
    let pngs: Vec<String> = files[1..]
        .iter()
        .filter_map(|f| f.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    println!(
        "wrote {}/{{fit.csv, {}}}",
        args.out.display(),
        pngs.join(", ")
    );
    Ok(())
}
