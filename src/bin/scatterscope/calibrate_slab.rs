//! `scatterscope calibrate-slab`: mu_s' and mu_a from time-resolved
//! transmittance captures of slabs of known thickness.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use scatterscope::calibrate::histogram::{DEFAULT_MAT_DATASET, DEFAULT_MAT_PARTS, TimeHistogram};
use scatterscope::calibrate::measured_irf::MeasuredIrf;
use scatterscope::calibrate::transmittance::{
    RISING_EDGE_CONVENTION, SlabFit, SlabFitOptions, fit_slab, predict_captures, read_captures,
};
use scatterscope::report::plot::{Series, chart};

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

fn print_fit(title: &str, fit: &SlabFit) {
    println!("{title}");
    for (name, est, unit) in [
        ("mu_a", fit.mu_a, "/cm"),
        ("mu_s'", fit.mu_s_reduced, "/cm"),
        ("offset", fit.offset, "cm (detector from the laser's axis)"),
    ] {
        let value = match (est.fitted, est.standard_error) {
            (true, Some(se)) => format!(
                "{:.5} +- {:.1e} {unit} (Poisson), +- {:.1e} scaled by sqrt(chi2/dof)",
                est.value,
                se,
                se * fit.scatter_factor()
            ),
            (true, None) => format!("{:.5} {unit} (not determined by the data)", est.value),
            (false, _) => format!("{:.5} {unit} (fixed)", est.value),
        };
        println!("  {name:<6} {value}");
    }
    println!(
        "  extrapolation distance {:.2} mm; chi-square per degree of freedom {:.2} ({} degrees of freedom)",
        10.0 * fit.extrapolation_cm,
        fit.chi2_per_dof,
        fit.dof
    );
    println!(
        "  capture              thickness   t0 (ps)        signal       background/bin  bins  left out  chi2/dof  (all bins)"
    );
    for c in &fit.captures {
        println!(
            "  {:<20} {:>6.2} cm  {:>12.1}  {:>12.0}  {:>14.1}  {:>5}  {:>8}  {:>8.2}  {:>10.2}",
            c.label,
            c.thickness_cm,
            c.t0_ps,
            c.signal,
            c.background,
            c.measured.len(),
            c.left_out.len(),
            c.chi2_per_dof(),
            c.chi2_per_dof_window()
        );
    }
    for u in &fit.undetermined {
        println!("  note: {u}");
    }
}

pub fn run(args: &CalibrateSlabArgs) -> anyhow::Result<()> {
    let reference = TimeHistogram::read(&args.irf_from, &args.dataset, args.bin_ps)?;
    let irf = match args.irf_extent {
        IrfExtent::Period => MeasuredIrf::from_histogram_period(&reference)?,
        IrfExtent::Peak => MeasuredIrf::from_histogram(&reference)?,
    };
    println!(
        "instrument response from {} ({}): {} bins of {} ps, FWHM {:.1} ps, mean delay after the peak {:.1} ps, {:.2} counts per bin subtracted; {:.2} % of it lies more than 1 ns before or 3 ns after the peak",
        irf.source,
        irf.extent_name(),
        irf.weights.len(),
        irf.bin_width_ps,
        irf.fwhm_ps(),
        irf.mean_delay_ps(),
        irf.background_per_bin,
        100.0 * irf.share_outside(1000.0, 3000.0)
    );
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
    print_fit(
        &format!(
            "joint fit of {} captures ({} single-capture model evaluations, {:.1} s):",
            captures.len(),
            fit.evaluations,
            started.elapsed().as_secs_f64()
        ),
        &fit,
    );
    let mut all = vec![(captures, fit.clone())];
    if !held.is_empty() {
        let pred = predict_captures(&held, &irf, &fit.fixed())?;
        print_fit(
            "prediction of captures left out of the fit (medium fixed):",
            &pred,
        );
        all.push((held, pred));
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating output directory {}", args.out.display()))?;
    let mut csv = String::from("capture,role,bin_start_ps,measured,fitted,in_fit\n");
    let mut pngs = Vec::new();
    for ((caps, f), role) in all.iter().zip(["fitted", "predicted"]) {
        for (cap, c) in caps.iter().zip(&f.captures) {
            let h = &cap.histogram;
            let first = c.window_start_ps(h.bin_width_ps, h.start_ps);
            let start = |i: usize| first + i as f64 * h.bin_width_ps;
            for (i, (m, u)) in c.measured.iter().zip(&c.fitted).enumerate() {
                let in_fit = u8::from(!c.left_out.contains(&i));
                writeln!(csv, "{},{role},{},{m},{u},{in_fit}", c.label, start(i))
                    .expect("writing to a String");
            }
            // Log counts against the time since the pulse entered the slab,
            // of the window's bins that `keep` picks.
            let points = |v: &[f64], keep: &dyn Fn(usize) -> bool| {
                v.iter()
                    .enumerate()
                    .filter(|(i, _)| keep(*i))
                    .map(|(i, &x)| {
                        (
                            start(i) + 0.5 * h.bin_width_ps - c.t0_ps,
                            x.max(0.5).log10(),
                        )
                    })
                    .collect()
            };
            let mut measured = vec![Series {
                label: "measured".into(),
                points: points(&c.measured, &|i| !c.left_out.contains(&i)),
            }];
            if !c.left_out.is_empty() {
                measured.push(Series {
                    label: "measured, left out of the fit".into(),
                    points: points(&c.measured, &|i| c.left_out.contains(&i)),
                });
            }
            let name = format!("fit_{}.png", c.label);
            let png = args.out.join(&name);
            chart(
                &png,
                &format!(
                    "{} ({role}, {:.2} cm): chi2/dof {:.2}",
                    c.label,
                    c.thickness_cm,
                    c.chi2_per_dof()
                ),
                "time after the pulse enters the slab (ps)",
                "log10 counts per bin",
                &measured,
                &[Series {
                    label: "model".into(),
                    points: points(&c.fitted, &|_| true),
                }],
                false,
            )
            .map_err(|e| anyhow::anyhow!("writing {}: {e}", png.display()))?;
            pngs.push(name);
        }
    }
    let csv_path = args.out.join("fit.csv");
    std::fs::write(&csv_path, csv).with_context(|| format!("writing {}", csv_path.display()))?;
    println!(
        "wrote {}/{{fit.csv, {}}}",
        args.out.display(),
        pngs.join(", ")
    );
    Ok(())
}
