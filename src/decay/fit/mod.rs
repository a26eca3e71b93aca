//! Lifetimes fitted as FLIM labs fit them (SPCImage, SymPhoTime, FLIMfit,
//! FLIMJ): each pixel's decay, after optional binning of its neighbours,
//! by one to three exponential components and a constant background,
//! reconvolved with the instrument response ([`model`]), by Poisson
//! maximum likelihood or weighted least squares ([`optimise`]); or the
//! whole image at once, lifetimes shared and amplitudes per pixel
//! ([`global`]).
//!
//! The steps, each said in the notes:
//! 1. The window: every bin the instrument recorded whole (every bin
//!    when the file does not say) with an IRF; a tail fit from the second
//!    bin after the summed decay's peak (or the bins asked for).
//! 2. The IRF: measured (a decay on the same bins), a Gaussian of fitted
//!    centre and width, or estimated from the rising edge of the summed
//!    decay (its rise, mirrored about its steepest point); none for a
//!    tail fit.
//! 3. The summed decay of every pixel above the photon threshold is fitted
//!    first, from guesses made of its moments, its IRF parameters (an
//!    estimated IRF's shift, a Gaussian's centre and width, a measured
//!    IRF's shift only when asked) with it; pixels then start from its lifetimes,
//!    with its IRF parameters held (as SPCImage holds the shift).
//! 4. Each pixel (or the global fit): lifetimes, amplitudes, fractions,
//!    the amplitude- and intensity-weighted mean lifetimes, background,
//!    reduced chi-squared, Poisson deviance, and each lifetime's standard
//!    error from the curvature (the Cramer-Rao bound at the fit for
//!    maximum likelihood). Pixels below the threshold, and fits that do
//!    not converge or end at a lifetime bound, are masked (NaN in every
//!    map but photons) and counted.
//!
//! Amplitudes are photons per bin at the decay's time zero (`N_k w /
//! tau_k` for a component of `N_k` photons in bins of width `w`);
//! fractions are of photons (intensity) and of amplitudes.

pub mod file;
pub mod global;
pub mod model;
pub mod optimise;

use ndarray::{Array2, ArrayView3};
use rayon::prelude::*;

use self::model::{DecayModel, IrfShape, Kernel};
use self::optimise::{Fitted, Objective, fit};
use super::DecayError;
use crate::stack::CountsView;

/// Where the instrument response comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum IrfSource {
    /// A measured response: photons per bin on the stack's bins.
    Measured {
        /// The decay.
        decay: Vec<f64>,
        /// What it is, in words (its file).
        what: String,
    },
    /// A Gaussian whose centre and width are fitted.
    Gaussian,
    /// Estimated from the rising edge of the summed decay.
    RisingEdge,
    /// None: a tail fit.
    Tail,
}

/// How decays are fitted.
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// Exponential components, 1 to 3.
    pub components: usize,
    /// The instrument response.
    pub irf: IrfSource,
    /// What the fit minimises.
    pub objective: Objective,
    /// Neighbours binned into each pixel's decay: a square of side `2 b +
    /// 1` about it (SPCImage's binning `b`), clipped at the edges.
    pub binning: usize,
    /// Pixels with fewer photons in the window (after binning) are masked.
    pub min_photons: f64,
    /// Lifetimes shared by every unmasked pixel.
    pub global: bool,
    /// The fitted window, bins `[first, end)`; `None`: as the module says.
    pub window: Option<(usize, usize)>,
    /// The bins `[first, end)` the instrument recorded whole (a file's
    /// [`crate::stack::RecordedBins`]): the default window keeps to them.
    pub recorded: Option<(usize, usize)>,
    /// Model the light of earlier pulses (when the laser period is known).
    pub incomplete_decay: bool,
    /// Fit a measured IRF's shift on the summed decay: an IRF recorded at
    /// another time than the sample. Else (the default) it is held at 0,
    /// as an IRF recorded with the sample is aligned with it. An estimated
    /// IRF's shift is always fitted.
    pub fit_irf_shift: bool,
    /// How the IRF's exponentials are binned.
    pub kernel: Kernel,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            components: 1,
            irf: IrfSource::RisingEdge,
            objective: Objective::Poisson,
            binning: 0,
            min_photons: 100.0,
            global: false,
            window: None,
            recorded: None,
            incomplete_decay: true,
            fit_irf_shift: false,
            kernel: Kernel::Integrated,
        }
    }
}

/// The summed decay's fit, for a figure and the notes.
#[derive(Debug, Clone)]
pub struct SummedFit {
    /// The window's bins, `[first, end)` of the stack's.
    pub window: (usize, usize),
    /// The bins' starts, ps (the window's).
    pub starts_ps: Vec<f64>,
    /// Photons per bin, every unmasked pixel summed.
    pub decay: Vec<f64>,
    /// The stack's photons in the window, every pixel, each counted once.
    pub window_photons: f64,
    /// The fit.
    pub fit: Vec<f64>,
    /// The IRF the fit used on the window's bins (shifted, or the
    /// Gaussian fitted), of unit sum (empty for a tail fit).
    pub irf: Vec<f64>,
    /// The fitted parameters (the model's layout).
    pub params: Vec<f64>,
    /// The fitted values with their standard errors, in words, one per
    /// line (for the figure and the notes).
    pub values: Vec<String>,
    /// Its reduced chi-squared.
    pub reduced_chi2: f64,
}

/// Every map of a fit, each rows x columns.
#[derive(Debug, Clone)]
pub struct FitMaps {
    /// Photons in the window (after binning).
    pub photons: Array2<f64>,
    /// Each component's lifetime, ps.
    pub lifetimes_ps: Vec<Array2<f64>>,
    /// Each lifetime's standard error, ps.
    pub lifetime_errors_ps: Vec<Array2<f64>>,
    /// Each component's amplitude, photons per bin at time zero.
    pub amplitudes: Vec<Array2<f64>>,
    /// Each component's share of the photons.
    pub intensity_fractions: Vec<Array2<f64>>,
    /// Each component's share of the amplitudes.
    pub amplitude_fractions: Vec<Array2<f64>>,
    /// Amplitude-weighted mean lifetime, ps.
    pub tau_amplitude_ps: Array2<f64>,
    /// Intensity-weighted mean lifetime, ps.
    pub tau_intensity_ps: Array2<f64>,
    /// Background, photons per bin.
    pub background: Array2<f64>,
    /// Reduced chi-squared.
    pub reduced_chi2: Array2<f64>,
    /// Poisson deviance.
    pub deviance: Array2<f64>,
    /// Masked pixels (below the threshold, or not fitted).
    pub mask: Array2<bool>,
    /// The summed decay's fit.
    pub summed: SummedFit,
    /// What was assumed, left out and masked.
    pub notes: Vec<String>,
}

/// Fits the decays of `counts` (bins x rows x columns; bins start at
/// `starts_ps`, `width_ps` wide; the laser at `frequency_hz` when known).
pub fn fit_maps(
    counts: CountsView<'_>,
    starts_ps: &[f64],
    width_ps: f64,
    frequency_hz: Option<f64>,
    options: &FitOptions,
) -> Result<FitMaps, DecayError> {
    match counts {
        CountsView::U16(c) => fit_counts(c, starts_ps, width_ps, frequency_hz, options),
        CountsView::U32(c) => fit_counts(c, starts_ps, width_ps, frequency_hz, options),
    }
}

fn input_error(what: impl Into<String>) -> DecayError {
    DecayError::Input(what.into())
}

fn check_options(
    options: &FitOptions,
    bins: usize,
    width_ps: f64,
    starts_ps: &[f64],
) -> Result<(), DecayError> {
    if !(1..=3).contains(&options.components) {
        return Err(input_error(format!(
            "components {}: a fit has 1, 2 or 3 exponential components",
            options.components
        )));
    }
    if !(width_ps.is_finite() && width_ps > 0.0) {
        return Err(input_error(format!(
            "bin width {width_ps} ps: a fit needs bins of a positive, finite width"
        )));
    }
    if starts_ps.len() != bins {
        return Err(input_error(format!(
            "{} bin starts for {bins} bins",
            starts_ps.len()
        )));
    }
    if !(options.min_photons.is_finite() && options.min_photons >= 0.0) {
        return Err(input_error(format!(
            "min_photons {}: give a finite number >= 0",
            options.min_photons
        )));
    }
    if let Some((a, b)) = options.window
        && !(a < b && b <= bins)
    {
        return Err(input_error(format!(
            "window bins {a} to {b}: give first < end <= {bins} (the stack's bins)"
        )));
    }
    if let Some((a, b)) = options.recorded
        && !(a < b && b <= bins)
    {
        return Err(input_error(format!(
            "recorded bins {a} to {b}: give first < end <= {bins} (the stack's bins)"
        )));
    }
    if let IrfSource::Measured { decay, what } = &options.irf {
        if decay.len() != bins {
            return Err(input_error(format!(
                "the IRF {what} has {} bins where the decays have {bins}: record it with the same bins (width {width_ps} ps)",
                decay.len()
            )));
        }
        if let Some(v) = decay.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
            return Err(input_error(format!(
                "the IRF {what} holds {v}: an IRF holds finite counts >= 0"
            )));
        }
        if decay.iter().sum::<f64>() <= 0.0 {
            return Err(input_error(format!(
                "the IRF {what} holds no photon: nothing to reconvolve with"
            )));
        }
    }
    Ok(())
}

fn fit_counts<T: Copy + Into<f64> + Sync>(
    counts: ArrayView3<'_, T>,
    starts_ps: &[f64],
    width_ps: f64,
    frequency_hz: Option<f64>,
    options: &FitOptions,
) -> Result<FitMaps, DecayError> {
    let (bins, h, w) = counts.dim();
    check_options(options, bins, width_ps, starts_ps)?;
    // Binning b sums the (2b + 1) x (2b + 1) pixels about each; from
    // max(h, w) - 1 on, every pixel's sum is the whole image's, and a b
    // near 2^64 would wrap the pixel ranges.
    let widest = h.max(w).saturating_sub(1);
    if options.binning > widest {
        return Err(input_error(format!(
            "binning {}: at most {widest} on a {h} x {w} image (binning {widest} already sums the whole image about every pixel)",
            options.binning
        )));
    }
    let k = options.components;
    let mut notes = Vec::new();
    if options.binning > 0 {
        let side = 2 * options.binning + 1;
        notes.push(format!(
            "each pixel's decay is the sum of the {side} x {side} pixels about it (binning {}), clipped at the edges",
            options.binning
        ));
    }
    let total: Vec<f64> = counts
        .outer_iter()
        .into_par_iter()
        .map(|plane| plane.iter().map(|&v| v.into()).sum())
        .collect();
    if total.iter().sum::<f64>() <= 0.0 {
        return Err(input_error("the stack holds no photon: nothing to fit"));
    }
    if bins < 2 * k + 2 {
        return Err(input_error(format!(
            "{bins} bins: a fit of {k} component(s) needs at least {}",
            2 * k + 2
        )));
    }
    let (lo, hi) = options.recorded.unwrap_or((0, bins));
    let peak = lo + argmax(&total[lo..hi]);
    let (first, end) = options.window.unwrap_or(match options.irf {
        IrfSource::Tail => ((peak + 2).min(hi - 1), hi),
        _ => (lo, hi),
    });
    let n = end - first;
    if n < 2 * k + 2 {
        return Err(input_error(format!(
            "the window holds {n} bins: a fit of {k} component(s) needs at least {}",
            2 * k + 2
        )));
    }
    notes.push(format!(
        "window: bins {first} to {} ({:.0} to {:.0} ps){}",
        end - 1,
        starts_ps[first],
        starts_ps[end - 1] + width_ps,
        match (options.window.is_some(), &options.irf, options.recorded.is_some()) {
            (true, _, _) => " (asked)",
            (false, IrfSource::Tail, false) =>
                " (a tail fit from the second bin after the summed decay's peak)",
            (false, IrfSource::Tail, true) =>
                " (a tail fit from the second bin after the summed decay's peak, to the last bin the instrument recorded whole)",
            (false, _, true) => " (the bins the instrument recorded whole)",
            (false, _, false) => "",
        }
    ));
    // The fit's memory, checked before it grows: the maps and their
    // masked copies and each pixel's fit, held whole; the window's decays
    // (float64) a band of rows at a time, all at once for a global fit.
    let budget = crate::memory::budget()
        .map_err(|e| input_error(e.to_string()))?
        .bytes;
    // The stack itself is held too.
    let stack = crate::memory::bytes_of([bins, h, w], std::mem::size_of::<T>() as u64);
    let held =
        crate::memory::bytes_of([h, w], 16 * (5 * k as u64 + 9) + FIT_BYTES).saturating_add(stack);
    let row_bytes = crate::memory::bytes_of([w, n], 8);
    let band_rows = if options.global {
        h
    } else {
        (budget.saturating_sub(held) / 2 / row_bytes.max(1)).clamp(1, h as u64) as usize
    };
    crate::memory::check(
        held.saturating_add(row_bytes.saturating_mul(band_rows as u64)),
        || {
            format!(
                "a {}fit of {h} x {w} pixels over {n} bins",
                if options.global { "global " } else { "" }
            )
        },
    )
    .map_err(|e| input_error(e.to_string()))?;
    if band_rows < h {
        notes.push(format!(
            "the pixels' decays made and fitted {band_rows} rows at a time, within the memory budget"
        ));
    }
    let window_total: Vec<f64> = total[first..end].to_vec();
    let (irf, irf_note) = irf_shape(&options.irf, &total, first, end, options.fit_irf_shift);
    notes.push(irf_note);
    let period_bins = match (frequency_hz, options.incomplete_decay) {
        (Some(f), true) if f > 0.0 && f.is_finite() => {
            let period = 1e12 / f / width_ps;
            notes.push(format!(
                "incomplete decay modelled: the light of earlier pulses at {:.3} MHz ({:.1} bins a period)",
                f * 1e-6,
                period
            ));
            Some(period.max(n as f64))
        }
        (None, true) => {
            notes.push("incomplete decay left out: the laser frequency is not known".into());
            None
        }
        _ => {
            notes.push("incomplete decay left out (asked)".into());
            None
        }
    };
    let model = DecayModel {
        bins: n,
        width_ps,
        components: k,
        irf,
        period_bins,
        kernel: options.kernel,
    };
    if options.kernel == Kernel::Sampled && !matches!(model.irf, IrfShape::Tail) {
        notes.push("the exponentials sampled at the bins' starts after each IRF sample (flimlib's discrete convolution), not integrated over the bins (asked)".into());
    }
    let np = model.parameters();
    let bounds = bounds(&model);
    // Which pixels are fitted, and the summed decay of those.
    let window = counts.slice(ndarray::s![first..end, .., ..]);
    let photons: Vec<f64> = {
        let mut plane = ndarray::Array3::<f64>::zeros((1, h, w));
        for bin in window.outer_iter() {
            plane.zip_mut_with(&bin, |a, &v| *a += v.into());
        }
        binned_decays(plane.view(), (0, 1), options.binning, 0..h)
    };
    let below = photons.iter().filter(|&&n| n < options.min_photons).count();
    // Planes iterate in row-major order: pixel p at row p / w, column p % w.
    let summed: Vec<f64> = window
        .outer_iter()
        .map(|bin| {
            bin.iter()
                .zip(&photons)
                .filter(|(_, n)| **n >= options.min_photons)
                .map(|(&v, _)| v.into())
                .sum()
        })
        .collect();
    let summed = if summed.iter().sum::<f64>() > 0.0 {
        summed
    } else {
        window_total.clone()
    };
    let hold_shift = matches!(options.irf, IrfSource::Measured { .. }) && !options.fit_irf_shift;
    let summed_fit = fit_summed(&model, &summed, &bounds, options.objective, hold_shift);
    // No component of the summed decay determined: pure noise, a flat
    // background. (One of several undetermined is a model with more
    // components than the light shows: its pixels are masked one by one.
    // A singular curvature leaves every error NaN when one component is
    // empty: only a component's own photons or finite error count here.)
    let no_decay = (0..k).all(|c| {
        let (photons, tau, error) = (
            summed_fit.params[2 * c],
            summed_fit.params[2 * c + 1],
            summed_fit.errors[2 * c + 1],
        );
        photons < 1.0 || error > UNDETERMINED_ERROR * tau
    });
    if no_decay {
        notes.push(format!(
            "the summed decay determines no lifetime (each a standard error above {UNDETERMINED_ERROR} times it, or a component of under one photon): it looks like noise or a flat background, not a decay; no pixel is fitted (every pixel's light together shows none)"
        ));
    } else if undetermined_by(&summed_fit, k) {
        notes.push(format!(
            "the summed decay does not determine all {k} components (a standard error above {UNDETERMINED_ERROR} times a lifetime, or a component of under one photon): fewer components may describe it"
        ));
    }
    let mut free = vec![true; np];
    for f in free.iter_mut().skip(model.background() + 1) {
        *f = false;
    }
    let start_for = |y: &[f64]| -> Vec<f64> {
        let scale = y.iter().sum::<f64>() / summed.iter().sum::<f64>().max(1.0);
        let mut s = summed_fit.params.clone();
        for c in 0..k {
            s[2 * c] *= scale;
        }
        s[model.background()] *= scale;
        s
    };
    let fits: Vec<Option<Fitted>> = if no_decay {
        // Each pixel above the threshold takes the summed decay's
        // undetermined fit, and is masked and counted with it.
        photons
            .iter()
            .map(|&n| (n >= options.min_photons).then(|| summed_fit.clone()))
            .collect()
    } else if options.global {
        let decays = binned_decays(counts, (first, end), options.binning, 0..h);
        let g = global::fit_global(
            &model,
            &decays,
            &photons,
            options.min_photons,
            &summed_fit.params,
            &bounds,
            options.objective,
        );
        notes.push(g.note);
        g.fits
    } else {
        let mut fits = Vec::with_capacity(h * w);
        for r0 in (0..h).step_by(band_rows) {
            let rows = r0..(r0 + band_rows).min(h);
            let decays = binned_decays(counts, (first, end), options.binning, rows.clone());
            let offset = r0 * w;
            fits.par_extend(decays.par_chunks_exact(n).enumerate().map(|(i, y)| {
                (photons[offset + i] >= options.min_photons)
                    .then(|| fit(&model, y, &start_for(y), &free, &bounds, options.objective))
            }));
        }
        fits
    };
    let maps = assemble(
        &model,
        &fits,
        &photons,
        (h, w),
        &bounds,
        options,
        below,
        &mut notes,
    );
    let mut fitted_sum = vec![0.0; n];
    model.evaluate(&summed_fit.params, &mut fitted_sum, None);
    let irf_used = {
        let v = model.irf(&summed_fit.params);
        let total: f64 = v.iter().sum();
        if total > 0.0 {
            v.iter().map(|x| x / total).collect()
        } else {
            v
        }
    };
    notes.push(format!(
        "summed decay: {}, reduced chi-squared {:.3}",
        describe_params(&model, &summed_fit.params),
        summed_fit.reduced_chi2
    ));
    // A decay that does not fall: its peak in the window's last fifth.
    let summed_peak = argmax(&summed);
    if !matches!(options.irf, IrfSource::Tail) && summed_peak * 5 >= 4 * n {
        notes.push(format!(
            "the summed decay peaks at bin {summed_peak} of the window's {n}: it rises instead of decaying (a ramp, or a window that ends before the decay): its lifetimes describe no decay"
        ));
    }
    if summed_fit.reduced_chi2 > POOR_FIT_CHI2 {
        notes.push(format!(
            "the model explains the summed decay poorly (reduced chi-squared {:.1}, above {POOR_FIT_CHI2}): more components, another IRF or a window that keeps only the decay may describe it; see fit_decay.png",
            summed_fit.reduced_chi2
        ));
    }
    Ok(FitMaps {
        summed: SummedFit {
            window: (first, end),
            starts_ps: starts_ps[first..end].to_vec(),
            decay: summed,
            window_photons: total[first..end].iter().sum(),
            fit: fitted_sum,
            irf: irf_used,
            values: value_lines(&model, &summed_fit, hold_shift),
            params: summed_fit.params.clone(),
            reduced_chi2: summed_fit.reduced_chi2,
        },
        notes,
        ..maps
    })
}

/// A summed decay's reduced chi-squared above this is remarked on as a
/// poor description (at the hundreds of thousands of photons of a summed
/// decay, small departures of shape already raise it past 1).
pub const POOR_FIT_CHI2: f64 = 5.0;

/// A fitted lifetime whose standard error passes this multiple of it is
/// not determined by its decay (pure noise, a flat background, three
/// components on a few photons): its pixel is masked. A single
/// exponential of 100 photons has an error near a tenth of its lifetime.
pub const UNDETERMINED_ERROR: f64 = 1.0;

/// Whether fit `f` of `k` components leaves a lifetime undetermined: its
/// curvature singular, its standard error above [`UNDETERMINED_ERROR`]
/// times it, or its component under one photon.
fn undetermined_by(f: &Fitted, k: usize) -> bool {
    (0..k).any(|c| undetermined_component(f, c))
}

/// Whether fit `f` leaves component `c`'s lifetime undetermined.
fn undetermined_component(f: &Fitted, c: usize) -> bool {
    let (photons, tau, error) = (f.params[2 * c], f.params[2 * c + 1], f.errors[2 * c + 1]);
    !(error.is_finite() && error <= UNDETERMINED_ERROR * tau && photons >= 1.0)
}

/// Fit `f`'s values with their standard errors, one per line: each
/// component, the background, the IRF's parameters (a held shift said
/// so).
fn value_lines(model: &DecayModel, f: &Fitted, hold_shift: bool) -> Vec<String> {
    let (p, e) = (&f.params, &f.errors);
    let pm = |v: f64, err: f64, digits: usize| {
        if err.is_finite() {
            format!("{v:.digits$} +- {err:.digits$}")
        } else {
            format!("{v:.digits$} (error undetermined)")
        }
    };
    let mut lines: Vec<String> = (0..model.components)
        .map(|c| {
            format!(
                "tau{} = {} ps ({} photons)",
                c + 1,
                pm(p[2 * c + 1], e[2 * c + 1], 1),
                pm(p[2 * c], e[2 * c], 0)
            )
        })
        .collect();
    let b = model.background();
    lines.push(format!("background = {} per bin", pm(p[b], e[b], 3)));
    let w = model.width_ps;
    match model.irf {
        IrfShape::Tail => {}
        IrfShape::Measured(_) if hold_shift => lines.push("IRF shift held at 0 ps".into()),
        IrfShape::Measured(_) => lines.push(format!(
            "IRF shift = {} ps",
            pm(p[b + 1] * w, e[b + 1] * w, 1)
        )),
        IrfShape::Gaussian => lines.push(format!(
            "IRF centre = {} ps, FWHM = {} ps",
            pm(p[b + 1] * w, e[b + 1] * w, 1),
            pm(
                p[b + 2] * w * 2.354_820_045,
                e[b + 2] * w * 2.354_820_045,
                1
            )
        )),
    }
    lines.push(format!("reduced chi-squared {:.3}", f.reduced_chi2));
    lines
}

/// The parameters in words.
pub fn describe_params(model: &DecayModel, p: &[f64]) -> String {
    let mut parts: Vec<String> = (0..model.components)
        .map(|c| {
            format!(
                "tau{} {:.1} ps ({:.0} photons)",
                c + 1,
                p[2 * c + 1],
                p[2 * c]
            )
        })
        .collect();
    parts.push(format!("background {:.3} per bin", p[model.background()]));
    let q = model.background() + 1;
    match model.irf {
        IrfShape::Tail => {}
        IrfShape::Measured(_) => parts.push(format!("IRF shift {:.1} ps", p[q] * model.width_ps)),
        IrfShape::Gaussian => parts.push(format!(
            "IRF centre {:.1} ps, FWHM {:.1} ps (into the window)",
            p[q] * model.width_ps,
            p[q + 1] * model.width_ps * 2.354_820_045
        )),
    }
    parts.join(", ")
}

/// The bounds of each parameter: photons and background >= 0, lifetimes
/// from a twentieth of a bin to 50 windows, the IRF's within the window.
fn bounds(model: &DecayModel) -> Vec<(f64, f64)> {
    let n = model.bins as f64;
    let mut b = Vec::new();
    for _ in 0..model.components {
        b.push((0.0, f64::INFINITY));
        b.push((0.05 * model.width_ps, 50.0 * n * model.width_ps));
    }
    b.push((0.0, f64::INFINITY));
    match model.irf {
        IrfShape::Tail => {}
        IrfShape::Measured(_) => b.push((-n / 4.0, n / 4.0)),
        IrfShape::Gaussian => {
            b.push((-n / 4.0, n));
            b.push((0.2, n / 4.0));
        }
    }
    b
}

/// The summed decay's fit from guesses made of its moments: the best of a
/// few starts (lifetimes spread about the mean time) by the objective; a
/// measured IRF's shift held at 0 when `hold_shift`.
fn fit_summed(
    model: &DecayModel,
    y: &[f64],
    bounds: &[(f64, f64)],
    objective: Objective,
    hold_shift: bool,
) -> Fitted {
    let n = model.bins;
    let k = model.components;
    let w = model.width_ps;
    // Background: the mean of the bins before the peak (fewer than three
    // before it: the minimum of the window's last fifth, at least its last
    // bin; an empty fifth of a 4-bin window started the background at
    // infinity).
    let peak = argmax(y);
    let before: Vec<f64> = y[..peak.saturating_sub(2)].to_vec();
    let bg = if before.len() >= 3 {
        before.iter().sum::<f64>() / before.len() as f64
    } else {
        y[n - (n / 5).max(1)..]
            .iter()
            .cloned()
            .fold(f64::INFINITY, f64::min)
            .max(0.0)
    };
    let signal: Vec<f64> = y.iter().map(|v| (v - bg).max(0.0)).collect();
    let photons = signal.iter().sum::<f64>().max(1.0);
    let mean_bin = signal
        .iter()
        .enumerate()
        .map(|(i, v)| i as f64 * v)
        .sum::<f64>()
        / photons;
    let (irf_start, origin) = match &model.irf {
        IrfShape::Tail => (Vec::new(), 0.0),
        IrfShape::Measured(irf) => {
            let s: f64 = irf.iter().sum();
            let bary = irf
                .iter()
                .enumerate()
                .map(|(i, v)| i as f64 * v)
                .sum::<f64>()
                / s;
            (vec![0.0], bary)
        }
        IrfShape::Gaussian => {
            // The rising edge's half maximum as the centre, a bin wide.
            let half = y[peak] / 2.0;
            let c = (0..=peak).find(|&i| y[i] >= half).unwrap_or(peak) as f64;
            (vec![c, 1.0], c)
        }
    };
    let tau_mean = ((mean_bin - origin).max(0.5) * w).clamp(bounds[1].0, bounds[1].1);
    let spreads: &[&[f64]] = match k {
        1 => &[&[1.0], &[0.5], &[2.0]],
        2 => &[&[0.3, 1.5], &[0.5, 2.0], &[0.15, 1.2]],
        _ => &[&[0.15, 0.6, 2.0], &[0.3, 1.0, 3.0]],
    };
    let mut free = vec![true; model.parameters()];
    if hold_shift {
        free[model.background() + 1] = false;
    }
    spreads
        .iter()
        .map(|spread| {
            let mut p = Vec::new();
            for s in spread.iter() {
                p.push(photons / k as f64);
                p.push(tau_mean * s);
            }
            p.push(bg);
            p.extend(&irf_start);
            fit(model, y, &p, &free, bounds, objective)
        })
        .min_by(|a, b| a.objective.total_cmp(&b.objective))
        .expect("at least one start")
}

/// The IRF's shape on the window `[first, end)` and the note that says
/// where it came from.
fn irf_shape(
    source: &IrfSource,
    total: &[f64],
    first: usize,
    end: usize,
    fit_shift: bool,
) -> (IrfShape, String) {
    let normalised = |v: &[f64]| {
        let s: f64 = v.iter().sum();
        v.iter().map(|x| x / s).collect::<Vec<f64>>()
    };
    match source {
        IrfSource::Tail => (
            IrfShape::Tail,
            "IRF: none (a tail fit: the window's first bin is time zero)".into(),
        ),
        IrfSource::Gaussian => (
            IrfShape::Gaussian,
            "IRF: a Gaussian, its centre and width fitted on the summed decay".into(),
        ),
        IrfSource::Measured { decay, what } => (
            IrfShape::Measured(normalised(&decay[first..end])),
            format!(
                "IRF: measured, {what} ({} photons), {}",
                decay.iter().sum::<f64>(),
                if fit_shift {
                    "its shift fitted on the summed decay (asked: recorded at another time than the sample)"
                } else {
                    "its shift held at 0 (taken as recorded with the sample, aligned with it; --irf-shift-fitted fits it)"
                }
            ),
        ),
        IrfSource::RisingEdge => {
            let y = &total[first..end];
            let peak = argmax(y);
            let rise: Vec<f64> = (0..y.len())
                .map(|i| {
                    if i == 0 || i > peak {
                        0.0
                    } else {
                        (y[i] - y[i - 1]).max(0.0)
                    }
                })
                .collect();
            let top = argmax(&rise);
            let mut irf = vec![0.0; y.len()];
            for (i, v) in irf.iter_mut().enumerate() {
                let mirrored = if i <= top {
                    i
                } else {
                    2 * top - i.min(2 * top)
                };
                *v = if i > 2 * top { 0.0 } else { rise[mirrored] };
            }
            if irf.iter().sum::<f64>() <= 0.0 {
                irf[peak] = 1.0;
            }
            (
                IrfShape::Measured(normalised(&irf)),
                "IRF: estimated from the rising edge of the summed decay (its rise, mirrored about the steepest point), its shift fitted on the summed decay".into(),
            )
        }
    }
}

fn argmax(v: &[f64]) -> usize {
    v.iter()
        .enumerate()
        .fold((0, f64::NEG_INFINITY), |(bi, bv), (i, &x)| {
            if x > bv { (i, x) } else { (bi, bv) }
        })
        .0
}

/// Each pixel's decay over the bins `[first, end)` of `counts`, summed
/// with its neighbours within `b` (a square, clipped at the edges), for
/// the pixels of `rows`: pixels x window bins.
fn binned_decays<T: Copy + Into<f64> + Sync>(
    counts: ArrayView3<'_, T>,
    (first, end): (usize, usize),
    b: usize,
    rows: std::ops::Range<usize>,
) -> Vec<f64> {
    let (_, h, w) = counts.dim();
    let n = end - first;
    let mut out = vec![0.0; rows.len() * w * n];
    if out.is_empty() {
        return out;
    }
    // Running sums, as a summed-area table gives them: down the rows (the
    // rows of a band slide one at a time) and along each row, so that a
    // pixel's sum costs the same at any binning. Counts are integers,
    // summed exactly in float64.
    let band = rows.len().div_ceil(4 * rayon::current_num_threads()).max(1);
    out.par_chunks_mut(band * w * n)
        .enumerate()
        .for_each(|(i, chunk)| {
            let r0 = rows.start + i * band;
            // Column sums over the rows about the current one: [c * n + k].
            let mut columns = vec![0.0; w * n];
            let add_row = |columns: &mut [f64], rr: usize, sign: f64| {
                for k in 0..n {
                    let row = counts.slice(ndarray::s![first + k, rr, ..]);
                    for (c, &v) in row.iter().enumerate() {
                        columns[c * n + k] += sign * v.into();
                    }
                }
            };
            for rr in r0.saturating_sub(b)..(r0 + b + 1).min(h) {
                add_row(&mut columns, rr, 1.0);
            }
            let mut along = vec![0.0; n];
            for (j, row_out) in chunk.chunks_mut(w * n).enumerate() {
                let r = r0 + j;
                if j > 0 {
                    if r + b < h {
                        add_row(&mut columns, r + b, 1.0);
                    }
                    if r > b {
                        add_row(&mut columns, r - b - 1, -1.0);
                    }
                }
                along.iter_mut().for_each(|a| *a = 0.0);
                for cc in 0..(b + 1).min(w) {
                    along
                        .iter_mut()
                        .zip(&columns[cc * n..(cc + 1) * n])
                        .for_each(|(a, v)| *a += v);
                }
                for c in 0..w {
                    row_out[c * n..(c + 1) * n].copy_from_slice(&along);
                    if c + b + 1 < w {
                        let add = &columns[(c + b + 1) * n..(c + b + 2) * n];
                        along.iter_mut().zip(add).for_each(|(a, v)| *a += v);
                    }
                    if c >= b {
                        let sub = &columns[(c - b) * n..(c - b + 1) * n];
                        along.iter_mut().zip(sub).for_each(|(a, v)| *a -= v);
                    }
                }
            }
        });
    out
}

/// Bytes of one pixel's fit beyond its decay and maps: its parameters,
/// errors and the fit's fields.
const FIT_BYTES: u64 = 256;

/// The maps from the pixels' fits, masks counted in the notes.
#[allow(clippy::too_many_arguments)]
fn assemble(
    model: &DecayModel,
    fits: &[Option<Fitted>],
    photons: &[f64],
    (h, w): (usize, usize),
    bounds: &[(f64, f64)],
    options: &FitOptions,
    below: usize,
    notes: &mut Vec<String>,
) -> FitMaps {
    let k = model.components;
    let nan = || Array2::from_elem((h, w), f64::NAN);
    let mut m = FitMaps {
        photons: Array2::from_shape_vec((h, w), photons.to_vec()).expect("pixels"),
        lifetimes_ps: (0..k).map(|_| nan()).collect(),
        lifetime_errors_ps: (0..k).map(|_| nan()).collect(),
        amplitudes: (0..k).map(|_| nan()).collect(),
        intensity_fractions: (0..k).map(|_| nan()).collect(),
        amplitude_fractions: (0..k).map(|_| nan()).collect(),
        tau_amplitude_ps: nan(),
        tau_intensity_ps: nan(),
        background: nan(),
        reduced_chi2: nan(),
        deviance: nan(),
        mask: Array2::from_elem((h, w), true),
        summed: SummedFit {
            window: (0, 0),
            starts_ps: Vec::new(),
            decay: Vec::new(),
            window_photons: 0.0,
            fit: Vec::new(),
            irf: Vec::new(),
            params: Vec::new(),
            values: Vec::new(),
            reduced_chi2: f64::NAN,
        },
        notes: Vec::new(),
    };
    let (mut unconverged, mut at_bound, mut undetermined) = (0, 0, 0);
    for (p, f) in fits.iter().enumerate() {
        let Some(f) = f else { continue };
        let (r, c) = (p / w, p % w);
        let finite = f.params.iter().all(|v| v.is_finite()) && f.deviance.is_finite();
        if !(f.converged && finite) {
            unconverged += 1;
            continue;
        }
        // A lifetime at its bound did not find a minimum inside them;
        // one whose component holds no photon is not measured.
        let bounded = (0..k).any(|c| {
            let (lo, hi) = bounds[2 * c + 1];
            let t = f.params[2 * c + 1];
            f.params[2 * c] > 0.0 && (t <= lo * 1.0001 || t >= hi * 0.9999)
        });
        if bounded {
            at_bound += 1;
            continue;
        }
        // A component without photons, or lifetimes the decay cannot tell
        // apart, leave the curvature singular or nearly so: no lifetime.
        if undetermined_by(f, k) {
            undetermined += 1;
            continue;
        }
        let wps = model.width_ps;
        let photons_k: Vec<f64> = (0..k).map(|c| f.params[2 * c]).collect();
        let taus: Vec<f64> = (0..k).map(|c| f.params[2 * c + 1]).collect();
        let amps: Vec<f64> = (0..k).map(|c| photons_k[c] * wps / taus[c]).collect();
        let (sn, sa): (f64, f64) = (photons_k.iter().sum(), amps.iter().sum());
        for ci in 0..k {
            m.lifetimes_ps[ci][(r, c)] = taus[ci];
            m.lifetime_errors_ps[ci][(r, c)] = f.errors[2 * ci + 1];
            m.amplitudes[ci][(r, c)] = amps[ci];
            m.intensity_fractions[ci][(r, c)] = if sn > 0.0 { photons_k[ci] / sn } else { 0.0 };
            m.amplitude_fractions[ci][(r, c)] = if sa > 0.0 { amps[ci] / sa } else { 0.0 };
        }
        m.tau_amplitude_ps[(r, c)] = if sa > 0.0 {
            amps.iter().zip(&taus).map(|(a, t)| a * t).sum::<f64>() / sa
        } else {
            f64::NAN
        };
        m.tau_intensity_ps[(r, c)] = if sn > 0.0 {
            photons_k.iter().zip(&taus).map(|(n, t)| n * t).sum::<f64>() / sn
        } else {
            f64::NAN
        };
        m.background[(r, c)] = f.params[model.background()];
        m.reduced_chi2[(r, c)] = f.reduced_chi2;
        m.deviance[(r, c)] = f.deviance;
        let any_nan = m.tau_amplitude_ps[(r, c)].is_nan() || m.tau_intensity_ps[(r, c)].is_nan();
        if any_nan {
            unconverged += 1;
            continue;
        }
        m.mask[(r, c)] = false;
    }
    // Masked pixels hold NaN in every map but photons.
    let mask = m.mask.clone();
    for map in m
        .lifetimes_ps
        .iter_mut()
        .chain(m.lifetime_errors_ps.iter_mut())
        .chain(m.amplitudes.iter_mut())
        .chain(m.intensity_fractions.iter_mut())
        .chain(m.amplitude_fractions.iter_mut())
        .chain([
            &mut m.tau_amplitude_ps,
            &mut m.tau_intensity_ps,
            &mut m.background,
            &mut m.reduced_chi2,
            &mut m.deviance,
        ])
    {
        map.zip_mut_with(&mask, |v, &masked| {
            if masked {
                *v = f64::NAN;
            }
        });
    }
    notes.push(format!(
        "masked: {below} pixels below {} photons, {unconverged} whose fit did not converge, {at_bound} whose lifetime ended at a bound ({:.0} to {:.0} ps), {undetermined} whose lifetimes the decay does not determine (a standard error above {UNDETERMINED_ERROR} times the lifetime, or a component of under one photon); {} of {} fitted",
        options.min_photons,
        bounds[1].0,
        bounds[1].1,
        h * w - below - unconverged - at_bound - undetermined,
        h * w
    ));
    m
}

#[cfg(test)]
mod tests {
    use super::binned_decays;
    use ndarray::Array3;

    /// The running sums equal the square's sum pixel by pixel, at every
    /// binning, edges clipped, cut to the window.
    #[test]
    fn binned_decays_equal_the_squares_sums() {
        let (bins, h, w) = (6, 7, 5);
        let counts = Array3::from_shape_fn((bins, h, w), |(k, r, c)| {
            ((k * 31 + r * 17 + c * 7) % 11) as u32
        });
        for b in 0..7 {
            let got = binned_decays(counts.view(), (1, 5), b, 0..h);
            for r in 0..h {
                for c in 0..w {
                    for k in 1..5 {
                        let mut want = 0.0;
                        for rr in r.saturating_sub(b)..(r + b + 1).min(h) {
                            for cc in c.saturating_sub(b)..(c + b + 1).min(w) {
                                want += f64::from(counts[[k, rr, cc]]);
                            }
                        }
                        assert_eq!(
                            got[(r * w + c) * 4 + k - 1],
                            want,
                            "b {b} ({r}, {c}) bin {k}"
                        );
                    }
                }
            }
        }
    }
}
