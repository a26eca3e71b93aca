//! `scatterscope fit`: lifetimes fitted pixel by pixel (or globally) from a
//! recorded file.

use std::path::PathBuf;

use scatterscope::decay::fit::FitOptions;
use scatterscope::decay::fit::file::{FitRequest, IrfRequest, fit_file};
use scatterscope::decay::fit::model::Kernel;
use scatterscope::decay::fit::optimise::Objective;
use scatterscope::tags::bin_file::BinSpec;

/// Lifetimes fitted as FLIM labs fit them, from a recorded file (PTU,
/// .spc, .sdt, .sstags): each pixel's decay (after optional binning) by 1
/// to 3 exponential components and a background, reconvolved with the
/// IRF, by Poisson maximum likelihood (or weighted least squares); or
/// globally, lifetimes shared by every pixel.
///
/// Writes fit.ome.tif (float32, one named channel per map), fit.npy with
/// fit.json, fit_lifetime.png and fit_decay.png. Pixels below
/// --min-photons and fits that do not converge are masked (NaN, mask 1)
/// and counted in the notes.
#[derive(Debug, clap::Args)]
pub struct FitArgs {
    /// The recorded file.
    file: PathBuf,
    #[command(flatten)]
    spec: BinSpec,
    /// Exponential components (1, 2 or 3).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=3))]
    components: u8,
    /// The IRF: a recorded file (the same bins), `gaussian` (centre and
    /// width fitted), `edge` (from the summed decay's rising edge) or
    /// `none` (a tail fit).
    #[arg(long, default_value = "edge")]
    irf: String,
    /// Weighted least squares (weights 1 / max(counts, 1)) instead of
    /// Poisson maximum likelihood.
    #[arg(long)]
    least_squares: bool,
    /// Bin each pixel with its neighbours: a (2B+1) x (2B+1) square.
    #[arg(long, default_value_t = 0)]
    binning: usize,
    /// Pixels with fewer photons in the window are masked.
    #[arg(long, default_value_t = 100.0)]
    min_photons: f64,
    /// Lifetimes shared by every pixel, amplitudes per pixel.
    #[arg(long)]
    global: bool,
    /// The fitted bins, FIRST:END (END excluded).
    #[arg(long, value_parser = parse_window)]
    window: Option<(usize, usize)>,
    /// Sample each exponential at the bins' starts after its IRF sample
    /// (flimlib's discrete convolution) instead of integrating it over the
    /// bins.
    #[arg(long)]
    sampled_kernel: bool,
    /// Fit a measured IRF's shift on the summed decay: an IRF recorded at
    /// another time than the sample (by default it is held at 0, aligned).
    #[arg(long)]
    irf_shift_fitted: bool,
    /// Keep every bin in the default window, also those the instrument
    /// did not record whole (outside an .sdt's TAC limits, a sync
    /// period's cut last bin).
    #[arg(long)]
    all_bins: bool,
    /// Leave out the light of earlier pulses (the incomplete decay).
    #[arg(long)]
    no_incomplete_decay: bool,
    /// Laser repetition rate (Hz), overriding the file's.
    #[arg(long, value_name = "HZ")]
    frequency: Option<f64>,
    /// Write the maps only, without the figures.
    #[arg(long)]
    no_figures: bool,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/fit")]
    out: PathBuf,
}

fn parse_window(s: &str) -> Result<(usize, usize), String> {
    let bad = || format!("window `{s}`: give FIRST:END in bins, e.g. 10:200");
    let (a, b) = s.split_once(':').ok_or_else(bad)?;
    let (a, b) = (
        a.trim().parse().map_err(|_| bad())?,
        b.trim().parse().map_err(|_| bad())?,
    );
    if a >= b {
        return Err(bad());
    }
    Ok((a, b))
}

pub fn run(args: &FitArgs) -> anyhow::Result<()> {
    let irf = match args.irf.as_str() {
        "gaussian" => IrfRequest::Gaussian,
        "edge" => IrfRequest::RisingEdge,
        "none" => IrfRequest::Tail,
        path => IrfRequest::File(PathBuf::from(path)),
    };
    let request = FitRequest {
        options: FitOptions {
            components: usize::from(args.components),
            objective: if args.least_squares {
                Objective::LeastSquares
            } else {
                Objective::Poisson
            },
            binning: args.binning,
            min_photons: args.min_photons,
            global: args.global,
            window: args.window,
            incomplete_decay: !args.no_incomplete_decay,
            fit_irf_shift: args.irf_shift_fitted,
            kernel: if args.sampled_kernel {
                Kernel::Sampled
            } else {
                Kernel::Integrated
            },
            ..FitOptions::default()
        },
        irf,
        frequency_hz: args.frequency,
        out: args.out.clone(),
        figures: !args.no_figures,
        all_bins: args.all_bins,
    };
    let done = fit_file(&args.file, &args.spec, &request)?;
    let mut summary = done.summary();
    summary.pop();
    for line in summary {
        println!("{line}");
    }
    for m in &done.stacks {
        for n in &m.notes {
            println!("note: {n}");
        }
        println!(
            "{} of {} pixels fitted ({} masked), {:.0} photons; median intensity-weighted lifetime {:.1} ps: wrote {}",
            m.pixels - m.masked,
            m.pixels,
            m.masked,
            m.photons,
            m.median_lifetime_ps,
            m.files
                .iter()
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    crate::signals::warned(done.warnings().len())
}
