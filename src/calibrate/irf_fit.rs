//! The parametric instrument response ([`Irf`]: a Gaussian plus an
//! exponential tail) fitted to a reference histogram (laser into the
//! detector without the medium), for kernels that take the parametric form.
//!
//! Model of reference bin `i` (`[ta, tb)`): `A W_i(tc) + B`, `W_i(tc)` the
//! IRF's probability of recording a photon that arrives at `tc` in bin `i`
//! ([`Irf::bin_weight`], exact), `tc` the Gaussian's centre (the time zero
//! the kernels assume), `A` the counts, `B` a constant background. Fitted
//! over the response's extent ([`MeasuredIrf`]) widened by
//! [`WINDOW_MARGIN_BINS`] on each side: Nelder-Mead over `tc`, ln FWHM and
//! ln tail, the convex likelihood in `A` and `B` solved by Newton's method
//! at each point. A chi-square per degree of freedom far above 1 says the
//! parametric form does not describe the reference (a sharp peak with a
//! long diffusion tail, say); the caller reports it.

use argmin::core::CostFunction;
use scatterscope_physics::Irf;

use super::CalibrateError;
use super::hessian::{invert, numerical_hessian, standard_error};
use super::histogram::{DEFAULT_MAT_DATASET, TimeHistogram};
use super::measured_irf::MeasuredIrf;
use super::search::{nelder_mead, pearson_chi2};
use super::transmittance::{amplitudes, nll};

/// Bins added on each side of the response's extent for the fit.
pub const WINDOW_MARGIN_BINS: usize = 16;

/// Shortest tail time constant the fit represents (ps); shorter tails are
/// reported as none.
pub const MIN_TAIL_PS: f64 = 1e-3;

/// Chi-square per degree of freedom above which the parametric form is
/// taken as not describing the reference.
pub const FORM_CHI2: f64 = 2.0;

/// The fitted response.
#[derive(Debug, Clone, PartialEq)]
pub struct IrfFit {
    /// The fitted parametric response.
    pub irf: Irf,
    /// Standard errors of FWHM and tail (ps), when determined.
    pub standard_errors_ps: (Option<f64>, Option<f64>),
    /// The Gaussian's centre on the reference's clock (ps): its time zero.
    pub centre_ps: f64,
    /// Background counts per bin.
    pub background_per_bin: f64,
    /// Counts in the response.
    pub signal: f64,
    /// Pearson chi-square per degree of freedom over the fitted window.
    pub chi2_per_dof: f64,
    /// Bins fitted less parameters.
    pub dof: usize,
}

struct Model<'a> {
    counts: &'a [f64],
    /// Bin edges (ps) of the window's bins.
    starts: Vec<f64>,
    width: f64,
}

impl Model<'_> {
    /// Unit-sum shape over the window for centre, FWHM and tail.
    fn shape(&self, tc: f64, fwhm: f64, tail: f64) -> Option<Vec<f64>> {
        let irf = Irf {
            fwhm_ps: fwhm,
            tail_ps: if tail < MIN_TAIL_PS { 0.0 } else { tail },
        };
        irf.validate().ok()?;
        let w: Vec<f64> = self
            .starts
            .iter()
            .map(|&a| irf.bin_weight(a, a + self.width, tc))
            .collect();
        let total: f64 = w.iter().sum();
        (total.is_finite() && total > 0.0).then(|| w.iter().map(|v| v / total).collect())
    }

    fn cost_at(&self, tc: f64, fwhm: f64, tail: f64) -> f64 {
        self.shape(tc, fwhm, tail)
            .map_or(f64::MAX, |s| amplitudes(&s, self.counts).2)
    }
}

impl CostFunction for Model<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, x: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        let v = self.cost_at(x[0], x[1].exp(), x[2].exp());
        Ok(if v.is_finite() { v } else { f64::MAX })
    }
}

impl IrfFit {
    /// Whether the parametric form describes the reference (chi-square per
    /// degree of freedom at most [`FORM_CHI2`]).
    pub fn describes_reference(&self) -> bool {
        self.chi2_per_dof <= FORM_CHI2
    }
}

/// [`fit_irf`] on the histogram of the reference recording at `path`
/// (a tag file, a stack or a MATLAB file; see [`TimeHistogram::read`];
/// `bin_ps` for a file that does not record its bin width).
pub fn irf_from_reference(
    path: &std::path::Path,
    bin_ps: Option<f64>,
) -> Result<IrfFit, CalibrateError> {
    let histogram = TimeHistogram::read(path, DEFAULT_MAT_DATASET, bin_ps)?;
    fit_irf(&histogram)
        .map_err(|e| CalibrateError::Invalid(format!("fitting the IRF to {}: {e}", path.display())))
}

/// Fits [`Irf`] to `reference` (see the module's documentation).
pub fn fit_irf(reference: &TimeHistogram) -> Result<IrfFit, CalibrateError> {
    let measured = MeasuredIrf::from_histogram(reference)
        .map_err(|e| CalibrateError::Invalid(e.to_string()))?;
    let w = reference.bin_width_ps;
    let peak_bin = reference.peak_index();
    let first = peak_bin - measured.peak;
    let lo = first.saturating_sub(WINDOW_MARGIN_BINS);
    let hi = (first + measured.weights.len() + WINDOW_MARGIN_BINS).min(reference.counts.len());
    let counts = &reference.counts[lo..hi];
    let model = Model {
        counts,
        starts: (lo..hi)
            .map(|i| reference.start_ps + i as f64 * w)
            .collect(),
        width: w,
    };
    let fwhm0 = measured.fwhm_ps().max(w);
    let tail0 = measured.mean_delay_ps().max(0.5 * w);
    let x0 = vec![
        reference.start_ps + (peak_bin as f64 + 0.5) * w,
        fwhm0.ln(),
        tail0.ln(),
    ];
    let (x, model, _) = nelder_mead(model, x0, &[w, 0.3, 0.5], 2000, "the IRF fit")?;
    let (tc, fwhm, tail) = (x[0], x[1].exp(), x[2].exp());
    let tail = if tail < MIN_TAIL_PS { 0.0 } else { tail };
    let shape = model.shape(tc, fwhm, tail).ok_or_else(|| {
        CalibrateError::Invalid(format!("{}: the fitted IRF is invalid", reference.source))
    })?;
    let (a, b, _) = amplitudes(&shape, counts);
    let fitted: Vec<f64> = shape.iter().map(|s| a * s + b).collect();
    let chi2 = pearson_chi2(&fitted, counts);
    let dof = counts.len().saturating_sub(5).max(1);
    // Standard errors of FWHM and tail from the full Hessian in natural
    // parameters (centre, FWHM, tail, A, B).
    let f = |v: &[f64]| {
        model
            .shape(v[0], v[1], v[2])
            .map_or(f64::INFINITY, |s| nll(&s, counts, v[3], v[4]))
    };
    let p = [tc, fwhm, tail.max(MIN_TAIL_PS), a, b.max(1e-9)];
    let steps: Vec<f64> = [1e-3 * w, 1e-4 * fwhm, 1e-4 * p[2], 1e-4 * a, 1e-4 * p[4]].to_vec();
    let inverse = invert(&numerical_hessian(&f, &p, &steps));
    let se = |i: usize, bound: f64| standard_error(inverse.as_ref(), i, bound);
    Ok(IrfFit {
        irf: Irf {
            fwhm_ps: fwhm,
            tail_ps: tail,
        },
        standard_errors_ps: (se(1, fwhm), if tail > 0.0 { se(2, tail) } else { None }),
        centre_ps: tc,
        background_per_bin: b,
        signal: a,
        chi2_per_dof: chi2 / dof as f64,
        dof,
    })
}
