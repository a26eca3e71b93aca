//! The medium's mu_s' and mu_a from time-resolved transmittance captures of
//! slabs of known thickness: a point detector on the far face, on the
//! laser's axis or `rho` off it, recording a time histogram.
//!
//! Model of capture bin `i` (bins of width `w` from the histogram's start
//! `t_s`):
//!
//! ```text
//! mu_i = A sum_j r_j q(i - j + p) + B
//! q(k) = int over [t_s + k w - t0, t_s + (k + 1) w - t0] of T(rho, t) dt
//! ```
//!
//! `T(rho, t)` is the slab model's transmittance
//! ([`scatterscope_physics::Diffusion::log_psf`] with
//! [`MediumModel::Slab`]: extrapolated boundaries, the reflection of the
//! refractive-index mismatch), integrated over each bin by
//! [`GAUSS_NODES`]-point Gauss-Legendre, `r` the measured instrument
//! response with zero delay at index `p` (the sum by FFT,
//! [`super::response_convolution`]), `t0` the time the pulse enters the
//! slab on the capture's clock, `A` the signal and `B` the background
//! counts per bin. The shape `sum_j r_j q` is scaled to unit sum over the
//! fitted window, so `A` is the capture's signal counts there. The window
//! runs from [`PRE_LIGHT_BINS`] before the light to where the light falls
//! under [`TAIL_SHARE`] of its peak; the rising edge may be left out of
//! the likelihood ([`SlabFitOptions::rising_edge_share`]; `calibrate-slab`
//! leaves it out by default, [`RISING_EDGE_CONVENTION`]).
//!
//! mu_s', mu_a and `rho` are shared by every capture; `t0`, `A` and `B`
//! are each capture's own. The fit maximises the Poisson likelihood:
//! Nelder-Mead over ln mu_s', ln mu_a and `rho` (those fitted), for each
//! of its points a Brent search over
//! each capture's `t0`, and for each `t0` Newton's method on the convex
//! likelihood in `A` and `B`. Standard errors come from the inverse of the
//! full Hessian (all parameters, central differences) at the optimum; with
//! the chi-square per degree of freedom `X` above 1 they are also given
//! scaled by `sqrt(X)` (the quasi-likelihood correction for scatter the
//! model does not explain).

use std::path::{Path, PathBuf};

use argmin::core::{CostFunction, Executor, State};
use argmin::solver::brent::BrentOpt;
use rayon::prelude::*;
use scatterscope_physics::{Diffusion, Medium, MediumModel};

use super::CalibrateError;
use super::hessian::{invert, numerical_hessian, standard_error};
use super::histogram::{HistogramError, TimeHistogram};
use super::measured_irf::MeasuredIrf;
use super::parts::{check_parts, kept_sum};
use super::response_convolution::ResponseConvolution;
use super::search::{nelder_mead, pearson_chi2};
use crate::formats::detect::Format;

/// Nodes of the Gauss-Legendre rule integrating `T` over one bin. The
/// transmittance changes by well under a factor e per 8 ps bin wherever
/// it carries light (its rise time is hundreds of ps for centimetre
/// slabs), where a 4-point rule's relative error is below 1e-8.
pub const GAUSS_NODES: usize = 4;

const GL_X: [f64; 4] = [
    -0.861_136_311_594_052_6,
    -0.339_981_043_584_856_3,
    0.339_981_043_584_856_3,
    0.861_136_311_594_052_6,
];
const GL_W: [f64; 4] = [
    0.347_854_845_137_453_9,
    0.652_145_154_862_546_1,
    0.652_145_154_862_546_1,
    0.347_854_845_137_453_9,
];

/// Bins before the model's first light kept in the window, for the
/// background.
pub const PRE_LIGHT_BINS: usize = 50;

/// The window ends where the capture's excess over its background, averaged
/// over [`TAIL_AVERAGE_BINS`] bins, falls below this share of its peak.
pub const TAIL_SHARE: f64 = 0.01;

/// Bins averaged to find the window's end.
pub const TAIL_AVERAGE_BINS: usize = 32;

/// Most bins a window holds.
pub const MAX_WINDOW_BINS: usize = 4000;

/// Half-width of the search for each capture's `t0`, in bins around the
/// time that puts the model's peak on the capture's.
pub const T0_SEARCH_BINS: f64 = 40.0;

/// Tolerance of each capture's `t0` search (ps): well under the standard
/// error of `t0` at tens of millions of counts.
pub const T0_TOLERANCE_PS: f64 = 1e-3;

/// A fitted coefficient below this (1/cm, or cm for the detector's
/// offset) has run to its bound 0.
pub const AT_ZERO_PER_CM: f64 = 1e-7;

/// The share of the peak from which time-domain diffuse optics usually
/// fits the rising edge (with 1 % of the peak on the falling edge, as
/// [`TAIL_SHARE`]): the diffusion model is least accurate at the earliest
/// times. Taken from that practice, not chosen on any capture here;
/// `calibrate-slab`'s default since it predicted seven foam captures none
/// of the project's choices had seen better than fitting every bin did
/// (BENCHMARKS.md, rule R10).
pub const RISING_EDGE_CONVENTION: f64 = 0.8;

/// First step of the search over the detector's offset (cm).
pub const OFFSET_STEP_CM: f64 = 0.3;

/// Step of the offset in the Hessian's central differences (cm): the
/// likelihood depends on the offset's square, so a relative step would
/// vanish at an offset near 0.
pub const OFFSET_HESSIAN_STEP_CM: f64 = 1e-3;

/// One capture through a slab of known thickness.
#[derive(Debug, Clone)]
pub struct Capture {
    /// The detector's histogram.
    pub histogram: TimeHistogram,
    /// Slab thickness (cm).
    pub thickness_cm: f64,
    /// Name for the output.
    pub label: String,
}

impl Capture {
    /// The capture `FILE=THICKNESS` (THICKNESS with its unit, see
    /// [`crate::units::parse_positive_cm`]), read by [`TimeHistogram::read`] with
    /// `dataset` and `bin_width_ps`, labelled by the file's stem.
    pub fn from_spec(
        spec: &str,
        dataset: &str,
        bin_width_ps: Option<f64>,
    ) -> Result<Self, CalibrateError> {
        let (path, thickness_cm, label) = parse_spec(spec)?;
        Self::read(&path, thickness_cm, label, dataset, bin_width_ps)
    }

    fn read(
        path: &Path,
        thickness_cm: f64,
        label: String,
        dataset: &str,
        bin_width_ps: Option<f64>,
    ) -> Result<Self, CalibrateError> {
        let histogram = TimeHistogram::read(path, dataset, bin_width_ps)?;
        Ok(Self {
            histogram,
            thickness_cm,
            label,
        })
    }
}

/// The file, thickness (cm) and label of `FILE=THICKNESS`.
fn parse_spec(spec: &str) -> Result<(PathBuf, f64, String), CalibrateError> {
    let fail = |m: String| CalibrateError::Invalid(format!("capture `{spec}`: {m}"));
    let (file, thickness) = spec
        .rsplit_once('=')
        .ok_or_else(|| fail("expected FILE=THICKNESS".into()))?;
    let thickness_cm = crate::units::parse_positive_cm(thickness).map_err(fail)?;
    let path = PathBuf::from(file);
    let label = path
        .file_stem()
        .map_or_else(|| file.to_string(), |s| s.to_string_lossy().into_owned());
    Ok((path, thickness_cm, label))
}

/// The captures `specs` (see [`Capture::from_spec`]), in order, and what
/// was done to them. With `parts` named, a MATLAB capture holding that
/// cell array of per-part histograms (the shared captures' `accum`, one
/// per second) is the sum of its parts that [`check_parts`] keeps, checked
/// across all the captures given, and the lines say what was kept and
/// whether `dataset` held the sum of all parts.
pub fn read_captures(
    specs: &[&str],
    dataset: &str,
    parts: Option<&str>,
    bin_width_ps: Option<f64>,
) -> Result<(Vec<Capture>, Vec<String>), CalibrateError> {
    let parsed: Vec<(PathBuf, f64, String)> = specs
        .iter()
        .map(|s| parse_spec(s))
        .collect::<Result<_, _>>()?;
    let mut captures: Vec<Capture> = parsed
        .iter()
        .map(|(path, thickness, label)| {
            Capture::read(path, *thickness, label.clone(), dataset, bin_width_ps)
        })
        .collect::<Result<_, _>>()?;
    let Some(parts_name) = parts else {
        return Ok((captures, Vec::new()));
    };
    let invalid = |e: HistogramError| CalibrateError::Invalid(e.to_string());
    let mut notes = Vec::new();
    // (capture index, its parts) for the captures that have parts.
    let mut parted: Vec<(usize, Vec<Vec<f64>>)> = Vec::new();
    for (i, (path, _, _)) in parsed.iter().enumerate() {
        let is_mat = Format::of_file(path) == Format::Mat;
        let width = captures[i].histogram.bin_width_ps;
        let found = if is_mat {
            TimeHistogram::read_mat_parts(path, parts_name, width).map_err(invalid)?
        } else {
            None
        };
        match found {
            Some(p) if !p.is_empty() => {
                let n = captures[i].histogram.counts.len();
                if let Some(bad) = p.iter().find(|h| h.counts.len() != n) {
                    return Err(CalibrateError::Invalid(format!(
                        "{}: {} bins where `{dataset}` has {n}",
                        bad.source,
                        bad.counts.len()
                    )));
                }
                parted.push((i, p.into_iter().map(|h| h.counts).collect()));
            }
            _ => notes.push(format!(
                "{}: no per-part histograms `{parts_name}`; `{dataset}` used as it is",
                captures[i].label
            )),
        }
    }
    let (which, all): (Vec<usize>, Vec<Vec<Vec<f64>>>) = parted.into_iter().unzip();
    let checks = check_parts(&all);
    let labels: Vec<&str> = which.iter().map(|&i| captures[i].label.as_str()).collect();
    let mut rebuilt = Vec::new();
    for ((i, p), check) in which.iter().zip(&all).zip(&checks) {
        let whole: f64 = p.iter().flatten().sum();
        let stored = captures[*i].histogram.total();
        let line = check.describe(&captures[*i].label, p.len(), &labels);
        notes.push(if whole == stored {
            format!("{line} (`{dataset}` is the sum of all {} parts)", p.len())
        } else {
            format!("{line} (`{dataset}` holds {stored} counts, the parts {whole})")
        });
        rebuilt.push((*i, kept_sum(p, check)));
    }
    for (i, counts) in rebuilt {
        let h = &captures[i].histogram;
        let source = format!("{} (sum of kept `{parts_name}` parts)", h.source);
        captures[i].histogram =
            TimeHistogram::new(counts, h.bin_width_ps, h.start_ps, Path::new(&source))
                .map_err(invalid)?;
    }
    Ok((captures, notes))
}

/// What the fit assumes and where it starts. The command line's fit
/// flags are these fields (their docs are the flags' help); `--fit`
/// frees the parameters ([`SlabFitOptions::free_named`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct SlabFitOptions {
    /// Refractive index of the medium (not fitted).
    #[cfg_attr(feature = "cli", arg(long))]
    pub refractive_index: f64,
    /// Starting (or, when not fitted, fixed) mu_a (1/cm).
    #[cfg_attr(feature = "cli", arg(long = "mu-a", value_name = "MU_A", default_value_t = SlabFitOptions::START_MU_A_PER_CM))]
    pub mu_a_per_cm: f64,
    /// Starting (or fixed) reduced scattering coefficient mu_s' (1/cm).
    #[cfg_attr(feature = "cli", arg(long = "mu-s-reduced", value_name = "MU_S_REDUCED", default_value_t = SlabFitOptions::START_MU_S_REDUCED_PER_CM))]
    pub mu_s_reduced_per_cm: f64,
    /// Whether mu_a is fitted.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub fit_mu_a: bool,
    /// Whether mu_s' is fitted.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub fit_mu_s_reduced: bool,
    /// Starting (or fixed) distance of the detector from the laser's axis
    /// on the far face (cm); 0 for a detector on the axis.
    #[cfg_attr(
        feature = "cli",
        arg(long = "detector-offset", value_name = "CM", default_value_t = 0.0)
    )]
    pub offset_cm: f64,
    /// Whether the offset is fitted.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub fit_offset: bool,
    /// Leave out the rising edge before the excess over the background
    /// reaches this share of the peak's (where diffusion is least
    /// accurate; 0 fits every bin after the window's pre-light bins). The
    /// default is time-domain diffuse optics' usual choice.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = RISING_EDGE_CONVENTION))]
    pub rising_edge_share: f64,
}

impl SlabFitOptions {
    /// Where mu_a starts by default (1/cm).
    pub const START_MU_A_PER_CM: f64 = 0.01;
    /// Where mu_s' starts by default (1/cm).
    pub const START_MU_S_REDUCED_PER_CM: f64 = 5.0;

    /// Frees the parameters named in `names` (`mu_a`, `mu_s_reduced` or
    /// its old name `mu_s`, `offset`);
    /// the others stay fixed at their starting values.
    pub fn free_named<S: AsRef<str>>(&mut self, names: &[S]) -> Result<(), CalibrateError> {
        for name in names {
            match super::current_parameter_name(name.as_ref()) {
                "mu_a" => self.fit_mu_a = true,
                "mu_s_reduced" => self.fit_mu_s_reduced = true,
                "detector_offset" => self.fit_offset = true,
                other => {
                    return Err(CalibrateError::Invalid(format!(
                        "unknown parameter `{other}` (use mu_a, mu_s_reduced, detector_offset)"
                    )));
                }
            }
        }
        Ok(())
    }

    /// One line saying what the model assumes with the response `irf`.
    pub fn describe_model(&self, irf: &MeasuredIrf) -> String {
        let detector = if self.fit_offset {
            "at a fitted distance from the laser's axis".to_string()
        } else if self.offset_cm == 0.0 {
            "on the laser's axis".to_string()
        } else {
            format!("{} cm from the laser's axis", self.offset_cm)
        };
        let range = if self.rising_edge_share > 0.0 {
            format!(
                "fitted from {:.0} % of the peak on the rising edge (the window's first {PRE_LIGHT_BINS} bins kept for the background)",
                100.0 * self.rising_edge_share
            )
        } else {
            "every bin of the window fitted".to_string()
        };
        format!(
            "slab with extrapolated boundaries, n = {}, point detector {detector}, measured instrument response ({}), constant background per capture; {range}",
            self.refractive_index,
            irf.extent_name()
        )
    }

    /// Starting (or fixed) mu_a, mu_s' and offset.
    fn start(&self) -> [f64; 3] {
        [self.mu_a_per_cm, self.mu_s_reduced_per_cm, self.offset_cm]
    }

    /// Whether mu_a, mu_s' and the offset are fitted.
    fn free(&self) -> [bool; 3] {
        [self.fit_mu_a, self.fit_mu_s_reduced, self.fit_offset]
    }
}

/// One capture's part of a fit.
#[derive(Debug, Clone)]
pub struct CaptureFit {
    /// The capture's label.
    pub label: String,
    /// Slab thickness (cm).
    pub thickness_cm: f64,
    /// Time the pulse enters the slab on the capture's clock (ps).
    pub t0_ps: f64,
    /// Standard error of `t0` (ps), when determined.
    pub t0_standard_error_ps: Option<f64>,
    /// Signal counts in the window.
    pub signal: f64,
    /// Background counts per bin.
    pub background: f64,
    /// Index of the window's first bin in the histogram.
    pub window_start: usize,
    /// Measured counts in the window.
    pub measured: Vec<f64>,
    /// Fitted expected counts in the window.
    pub fitted: Vec<f64>,
    /// Window bins (indices into `measured`) left out of the likelihood:
    /// the rising edge, see [`SlabFitOptions::rising_edge_share`].
    pub left_out: std::ops::Range<usize>,
    /// Pearson chi-square over the fitted bins.
    pub chi2: f64,
    /// Fitted bins less this capture's own parameters.
    pub dof: usize,
    /// Pearson chi-square over every bin of the window, the left-out ones
    /// included.
    pub chi2_window: f64,
}

impl CaptureFit {
    /// Chi-square per degree of freedom of this capture alone.
    pub fn chi2_per_dof(&self) -> f64 {
        self.chi2 / self.dof.max(1) as f64
    }

    /// Chi-square per degree of freedom over the whole window, the
    /// left-out bins included.
    pub fn chi2_per_dof_window(&self) -> f64 {
        self.chi2_window / self.measured.len().saturating_sub(3).max(1) as f64
    }

    /// Time of the window's first bin start (ps) on the capture's clock.
    pub fn window_start_ps(&self, bin_width_ps: f64, histogram_start_ps: f64) -> f64 {
        histogram_start_ps + self.window_start as f64 * bin_width_ps
    }
}

/// A fitted or fixed parameter shared by all captures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MediumEstimate {
    /// Value (1/cm for mu_a and mu_s', cm for the detector's offset).
    pub value: f64,
    /// Standard error from the Poisson likelihood (same unit), when determined.
    pub standard_error: Option<f64>,
    /// Whether it was fitted.
    pub fitted: bool,
}

/// The result of [`fit_slab`] or [`predict_captures`].
#[derive(Debug, Clone)]
pub struct SlabFit {
    /// Absorption coefficient.
    pub mu_a: MediumEstimate,
    /// Reduced scattering coefficient.
    pub mu_s_reduced: MediumEstimate,
    /// Detector's distance from the laser's axis (cm).
    pub offset: MediumEstimate,
    /// The rising-edge share the fit left out ([`SlabFitOptions`]).
    pub rising_edge_share: f64,
    /// Refractive index assumed.
    pub refractive_index: f64,
    /// Extrapolation distance of the fitted medium's boundaries (cm).
    pub extrapolation_cm: f64,
    /// Each capture's part.
    pub captures: Vec<CaptureFit>,
    /// Chi-square per degree of freedom over all captures.
    pub chi2_per_dof: f64,
    /// Degrees of freedom: bins less every fitted parameter.
    pub dof: usize,
    /// Model evaluations of one capture the fit took.
    pub evaluations: u64,
    /// Parameters the data do not determine, and why.
    pub undetermined: Vec<String>,
}

impl SlabFit {
    /// Factor to scale standard errors by for the scatter the model does
    /// not explain: `sqrt(chi2 per dof)`, at least 1.
    pub fn scatter_factor(&self) -> f64 {
        self.chi2_per_dof.max(1.0).sqrt()
    }

    /// Options fixing every shared parameter at this fit's value, for
    /// [`predict_captures`].
    pub fn fixed(&self) -> SlabFitOptions {
        SlabFitOptions {
            refractive_index: self.refractive_index,
            mu_a_per_cm: self.mu_a.value,
            mu_s_reduced_per_cm: self.mu_s_reduced.value,
            fit_mu_a: false,
            fit_mu_s_reduced: false,
            offset_cm: self.offset.value,
            fit_offset: false,
            rising_edge_share: self.rising_edge_share,
        }
    }
}

/// The transmittance reaching the detector: the slab's diffusion, seen
/// `offset_cm` off the laser's axis on the far face.
struct AtDetector {
    diffusion: Diffusion,
    r2_cm2: f64,
}

impl AtDetector {
    /// ln of the transmittance density at `t_ps` after the pulse enters.
    fn log_transmittance(&self, t_ps: f64) -> f64 {
        self.diffusion.log_psf(self.r2_cm2, t_ps)
    }
}

/// One capture prepared for the fit: its window and response.
struct Prepared<'a> {
    label: &'a str,
    /// The window's counts.
    window: &'a [f64],
    /// The fitted bins' counts: the window less `left_out`.
    counts: Vec<f64>,
    left_out: std::ops::Range<usize>,
    start: usize,
    bin_ps: f64,
    hist_start_ps: f64,
    thickness_cm: f64,
    irf: &'a MeasuredIrf,
    convolution: ResponseConvolution,
    peak_time_ps: f64,
}

impl Prepared<'_> {
    /// Unit-sum model shape over the window for the medium and `t0`;
    /// `None` when the physics is invalid or carries no light there.
    fn shape(&self, model: &AtDetector, t0: f64) -> Option<Vec<f64>> {
        let n = self.window.len();
        let m = self.irf.weights.len();
        let p = self.irf.peak;
        // q(k) for k in [start - (m - 1 - p), start + n + p).
        let k_lo = self.start as isize - (m - 1 - p) as isize;
        let len = n + m - 1;
        let w = self.bin_ps;
        // q index i + m - 1 - j meets the peak's run (j in it) for these.
        // The others reach the window only through the slow parts of a
        // whole-period response (weights of a few parts per million per
        // bin in the foam reference): there the bin's midpoint suffices,
        // and it cuts the cost of a 12 500-entry response about threefold.
        // (Long after the peak, where most of them lie, the foam captures'
        // transmittance decays by under 3 % per 8 ps bin: the midpoint
        // rule's relative error is below 1e-4.)
        let run = &self.irf.peak_run;
        let exact = m - run.end..n + m - 1 - run.start;
        let q: Vec<f64> = (0..len)
            .map(|idx| {
                let k = k_lo + idx as isize;
                let a = self.hist_start_ps + k as f64 * w - t0;
                let half = 0.5 * w;
                let mid = a + half;
                if exact.contains(&idx) {
                    GL_X.iter()
                        .zip(GL_W)
                        .map(|(x, wt)| wt * model.log_transmittance(mid + half * x).exp())
                        .sum::<f64>()
                        * half
                } else {
                    model.log_transmittance(mid).exp() * w
                }
            })
            .collect();
        // out[i] = sum_j r_j q(start + i - j + p); q index = i - j + m - 1.
        let mut out = self.convolution.apply(&q);
        let total: f64 = out.iter().sum();
        if !(total.is_finite() && total > 0.0) {
            return None;
        }
        out.iter_mut().for_each(|v| *v /= total);
        Some(out)
    }

    /// [`Self::shape`] on the fitted bins only.
    fn fitted_shape(&self, model: &AtDetector, t0: f64) -> Option<Vec<f64>> {
        self.shape(model, t0).map(|s| self.fitted_bins(s))
    }

    /// `window_values` less the left-out bins.
    fn fitted_bins(&self, mut window_values: Vec<f64>) -> Vec<f64> {
        window_values.drain(self.left_out.clone());
        window_values
    }
}

/// Poisson negative log-likelihood (without the data's constant) of
/// `mu = a s + b`.
pub(super) fn nll(shape: &[f64], counts: &[f64], a: f64, b: f64) -> f64 {
    shape
        .iter()
        .zip(counts)
        .map(|(&s, &m)| {
            let u = a * s + b;
            if u <= 0.0 {
                if m > 0.0 { f64::INFINITY } else { 0.0 }
            } else {
                u - if m > 0.0 { m * u.ln() } else { 0.0 }
            }
        })
        .sum()
}

/// The `A >= 0`, `B >= 0` maximising the likelihood of `A s + B` (a
/// convex problem: Newton's method with step halving), and the value.
pub(super) fn amplitudes(shape: &[f64], counts: &[f64]) -> (f64, f64, f64) {
    let n = counts.len() as f64;
    let total: f64 = counts.iter().sum();
    let smax = shape.iter().copied().fold(0.0, f64::max);
    let (dark_sum, dark_n) = shape
        .iter()
        .zip(counts)
        .filter(|(s, _)| **s < 1e-3 * smax)
        .fold((0.0, 0.0), |(a, k), (_, m)| (a + m, k + 1.0));
    let floor = 1e-9 * (total / n).max(1e-9);
    let mut b = if dark_n > 0.0 { dark_sum / dark_n } else { 0.0 }.max(floor);
    let mut a = (total - b * n).max(1e-9 * total.max(1.0));
    let mut f = nll(shape, counts, a, b);
    for _ in 0..50 {
        let (mut ga, mut gb, mut haa, mut hab, mut hbb) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (&s, &m) in shape.iter().zip(counts) {
            let u = a * s + b;
            let r = m / u;
            ga += s * (1.0 - r);
            gb += 1.0 - r;
            let c = m / (u * u);
            haa += s * s * c;
            hab += s * c;
            hbb += c;
        }
        let det = haa * hbb - hab * hab;
        if !(det.is_finite() && det > 0.0) {
            break;
        }
        let da = (hbb * ga - hab * gb) / det;
        let db = (haa * gb - hab * ga) / det;
        let mut step = 1.0;
        let mut improved = false;
        for _ in 0..40 {
            let (na, nb) = ((a - step * da).max(0.0), (b - step * db).max(floor));
            let nf = nll(shape, counts, na, nb);
            if nf <= f {
                improved = (f - nf) > 1e-12 * f.abs().max(1.0);
                (a, b, f) = (na, nb, nf);
                break;
            }
            step *= 0.5;
        }
        if !improved {
            break;
        }
    }
    (a, b, f)
}

/// For a medium: each capture's best `t0`, `A`, `B` and the summed
/// negative log-likelihood.
fn profile(
    prepared: &[Prepared],
    models: &[AtDetector],
    evaluations: &mut u64,
) -> Option<(Vec<[f64; 3]>, f64)> {
    let fits: Vec<Option<([f64; 3], f64, u64)>> = prepared
        .par_iter()
        .zip(models)
        .map(|(cap, d)| best_t0(cap, d))
        .collect();
    let mut total = 0.0;
    let mut out = Vec::with_capacity(fits.len());
    for f in fits {
        let (p, v, e) = f?;
        *evaluations += e;
        total += v;
        out.push(p);
    }
    Some((out, total))
}

struct T0Search<'a> {
    cap: &'a Prepared<'a>,
    model: &'a AtDetector,
}

impl CostFunction for T0Search<'_> {
    type Param = f64;
    type Output = f64;
    fn cost(&self, t0: &f64) -> Result<f64, argmin::core::Error> {
        Ok(match self.cap.fitted_shape(self.model, *t0) {
            Some(s) => amplitudes(&s, &self.cap.counts).2,
            None => f64::MAX,
        })
    }
}

/// The `t0` (with its `A`, `B`) maximising one capture's likelihood.
fn best_t0(cap: &Prepared, model: &AtDetector) -> Option<([f64; 3], f64, u64)> {
    let guess = cap.peak_time_ps - model_peak_ps(model);
    let half = T0_SEARCH_BINS * cap.bin_ps;
    let solver = BrentOpt::new(guess - half, guess + half).set_tolerance(1e-12, T0_TOLERANCE_PS);
    let res = Executor::new(T0Search { cap, model }, solver)
        .configure(|c| c.max_iters(200))
        .run()
        .ok()?;
    let evals = res.problem.counts.get("cost_count").copied().unwrap_or(0);
    let t0 = *res.state().get_best_param()?;
    let shape = cap.fitted_shape(model, t0)?;
    let (a, b, v) = amplitudes(&shape, &cap.counts);
    v.is_finite().then_some(([t0, a, b], v, evals + 1))
}

/// Time of the transmittance's maximum at the detector after the pulse
/// enters (ps), by golden-section search on its logarithm.
fn model_peak_ps(m: &AtDetector) -> f64 {
    let f = |t: f64| -m.log_transmittance(t);
    let (mut lo, mut hi) = (1e-3, 10.0 * m.diffusion.peak_time_ps().max(1.0));
    let g = 0.5 * (5f64.sqrt() - 1.0);
    for _ in 0..100 {
        let (x1, x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
        if f(x1) < f(x2) { hi = x2 } else { lo = x1 }
    }
    0.5 * (lo + hi)
}

fn at_detector(
    opts: &SlabFitOptions,
    [mu_a, mu_s, offset_cm]: [f64; 3],
    thickness_cm: f64,
) -> Option<AtDetector> {
    let diffusion = Diffusion::new(&Medium {
        mu_a_per_cm: mu_a,
        mu_s_per_cm: mu_s,
        g: 0.0,
        refractive_index: opts.refractive_index,
        thickness_cm,
        model: MediumModel::Slab,
    })
    .ok()?;
    offset_cm.is_finite().then_some(AtDetector {
        diffusion,
        r2_cm2: offset_cm * offset_cm,
    })
}

/// The fitted window of one capture, and its peak time.
fn prepare<'a>(
    capture: &'a Capture,
    irf: &'a MeasuredIrf,
    opts: &SlabFitOptions,
) -> Result<Prepared<'a>, CalibrateError> {
    let h = &capture.histogram;
    let fail = |m: String| CalibrateError::Invalid(format!("{}: {m}", capture.label));
    if (h.bin_width_ps - irf.bin_width_ps).abs() > 1e-9 * irf.bin_width_ps {
        return Err(fail(format!(
            "bins of {} ps, but the instrument response's are {} ps",
            h.bin_width_ps, irf.bin_width_ps
        )));
    }
    if !(capture.thickness_cm.is_finite() && capture.thickness_cm > 0.0) {
        return Err(fail(format!(
            "thickness {} cm must be positive",
            capture.thickness_cm
        )));
    }
    let start_d = at_detector(opts, opts.start(), capture.thickness_cm)
        .ok_or_else(|| fail("the starting medium is invalid for this slab".into()))?;
    let peak = h.peak_index();
    let w = h.bin_width_ps;
    let rise_bins = (model_peak_ps(&start_d) / w).ceil() as usize;
    let (background, _) = h.background_before(peak, rise_bins).ok_or_else(|| {
        fail(format!(
            "the peak (bin {peak}) leaves too few bins before the light ({rise_bins} bins of rise) to measure the background"
        ))
    })?;
    let peak_excess = h.counts[peak] - background;
    if peak_excess <= super::measured_irf::PEAK_SIGNIFICANCE * background.max(1.0).sqrt() {
        return Err(fail(format!(
            "no transmitted light: the fullest bin ({peak}) holds {peak_excess} counts over a background of {background}"
        )));
    }
    let start = peak.saturating_sub(rise_bins + PRE_LIGHT_BINS);
    let mut end = peak + 1;
    while end + TAIL_AVERAGE_BINS <= h.counts.len() && end - start < MAX_WINDOW_BINS {
        let mean =
            h.counts[end..end + TAIL_AVERAGE_BINS].iter().sum::<f64>() / TAIL_AVERAGE_BINS as f64;
        if mean - background < TAIL_SHARE * peak_excess {
            break;
        }
        end += 1;
    }
    let window = &h.counts[start..end];
    let left_out = if opts.rising_edge_share > 0.0 {
        let from = PRE_LIGHT_BINS.min(peak - start);
        let to = (from..=peak - start)
            .find(|&i| window[i] - background >= opts.rising_edge_share * peak_excess)
            .unwrap_or(peak - start);
        from..to
    } else {
        0..0
    };
    Ok(Prepared {
        label: &capture.label,
        window,
        counts: window[..left_out.start]
            .iter()
            .chain(&window[left_out.end..])
            .copied()
            .collect(),
        left_out,
        start,
        bin_ps: w,
        hist_start_ps: h.start_ps,
        thickness_cm: capture.thickness_cm,
        irf,
        convolution: ResponseConvolution::new(&irf.weights, end - start),
        peak_time_ps: h.start_ps + (peak as f64 + 0.5) * w,
    })
}

struct Outer<'a> {
    prepared: &'a [Prepared<'a>],
    opts: SlabFitOptions,
    evaluations: std::cell::Cell<u64>,
}

impl Outer<'_> {
    /// mu_a, mu_s' and the offset at the search's point `x` (ln mu_a,
    /// ln mu_s', offset, for those fitted).
    fn globals(&self, x: &[f64]) -> [f64; 3] {
        let mut it = x.iter();
        let mut g = self.opts.start();
        for (i, free) in self.opts.free().into_iter().enumerate() {
            if free {
                let v = it.next().copied().unwrap_or(0.0);
                g[i] = if i < 2 { v.exp() } else { v.abs() };
            }
        }
        g
    }

    fn models(&self, g: [f64; 3]) -> Option<Vec<AtDetector>> {
        self.prepared
            .iter()
            .map(|c| at_detector(&self.opts, g, c.thickness_cm))
            .collect()
    }
}

impl CostFunction for Outer<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, x: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        let Some(d) = self.models(self.globals(x)) else {
            return Ok(f64::MAX);
        };
        let mut e = 0;
        let v = profile(self.prepared, &d, &mut e).map_or(f64::MAX, |(_, v)| v);
        self.evaluations.set(self.evaluations.get() + e);
        Ok(if v.is_finite() { v } else { f64::MAX })
    }
}

/// Fits the shared mu_s', mu_a and detector offset (those `opts` frees)
/// and each capture's `t0`, signal and background; see the module's
/// documentation.
pub fn fit_slab(
    captures: &[Capture],
    irf: &MeasuredIrf,
    opts: &SlabFitOptions,
) -> Result<SlabFit, CalibrateError> {
    if captures.is_empty() {
        return Err(CalibrateError::Invalid("no capture to fit".into()));
    }
    for (name, v) in [
        ("refractive index", opts.refractive_index),
        ("starting mu_a", opts.mu_a_per_cm),
        ("starting mu_s'", opts.mu_s_reduced_per_cm),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(CalibrateError::Invalid(format!(
                "{name} {v} must be positive and finite"
            )));
        }
    }
    if !(opts.offset_cm.is_finite() && opts.offset_cm >= 0.0) {
        return Err(CalibrateError::Invalid(format!(
            "detector offset {} cm must be finite and not negative",
            opts.offset_cm
        )));
    }
    if !(0.0..1.0).contains(&opts.rising_edge_share) {
        return Err(CalibrateError::Invalid(format!(
            "rising-edge share {} must be at least 0 and below 1",
            opts.rising_edge_share
        )));
    }
    let prepared: Vec<Prepared> = captures
        .iter()
        .map(|c| prepare(c, irf, opts))
        .collect::<Result<_, _>>()?;
    let outer = Outer {
        prepared: &prepared,
        opts: *opts,
        evaluations: std::cell::Cell::new(0),
    };
    let start = opts.start();
    let mut x0 = Vec::new();
    let mut steps = Vec::new();
    for (i, free) in opts.free().into_iter().enumerate() {
        if free {
            x0.push(if i < 2 { start[i].ln() } else { start[i] });
            steps.push(if i < 2 { 0.3 } else { OFFSET_STEP_CM });
        }
    }
    let (x, outer) = if x0.is_empty() {
        (x0, outer)
    } else {
        let (x, outer, _) = nelder_mead(outer, x0, &steps, 400, "the fit")?;
        (x, outer)
    };
    let g = outer.globals(&x);
    finish(&prepared, opts, g, outer.evaluations.get())
}

/// Each capture's `t0`, signal and background with the shared parameters
/// held at `opts`' values (its fit flags are ignored): how well known
/// parameters predict captures they were not fitted on.
pub fn predict_captures(
    captures: &[Capture],
    irf: &MeasuredIrf,
    opts: &SlabFitOptions,
) -> Result<SlabFit, CalibrateError> {
    let fixed = SlabFitOptions {
        fit_mu_a: false,
        fit_mu_s_reduced: false,
        fit_offset: false,
        ..*opts
    };
    fit_slab(captures, irf, &fixed)
}

/// Natural parameters of the full Hessian: the fitted medium parameters,
/// then `t0`, `A`, `B` of each capture.
fn finish(
    prepared: &[Prepared],
    opts: &SlabFitOptions,
    shared: [f64; 3],
    mut evaluations: u64,
) -> Result<SlabFit, CalibrateError> {
    let invalid = || CalibrateError::Invalid("the fitted medium is invalid".into());
    let d: Vec<AtDetector> = prepared
        .iter()
        .map(|c| at_detector(opts, shared, c.thickness_cm))
        .collect::<Option<_>>()
        .ok_or_else(invalid)?;
    let (nuisance, _) = profile(prepared, &d, &mut evaluations).ok_or_else(invalid)?;
    let globals: Vec<usize> = (0..3).filter(|&i| opts.free()[i]).collect();
    let g = globals.len();
    let k = g + 3 * prepared.len();
    // The Hessian is block-arrow shaped: captures couple only through the
    // shared parameters. Each capture's block comes from its own
    // likelihood.
    let mut hess = vec![vec![0.0; k]; k];
    for (c, cap) in prepared.iter().enumerate() {
        let [t0, a, b] = nuisance[c];
        let base = [shared[0], shared[1], shared[2], t0, a, b];
        let free: Vec<usize> = globals.iter().copied().chain([3, 4, 5]).collect();
        let f = |v: &[f64]| {
            let mut p = base;
            for (&i, &x) in free.iter().zip(v) {
                p[i] = x;
            }
            at_detector(opts, [p[0], p[1], p[2]], cap.thickness_cm)
                .and_then(|d| cap.fitted_shape(&d, p[3]))
                .map_or(f64::INFINITY, |s| nll(&s, &cap.counts, p[4], p[5]))
        };
        let x: Vec<f64> = free.iter().map(|&i| base[i]).collect();
        let steps: Vec<f64> = free
            .iter()
            .map(|&i| match i {
                2 => OFFSET_HESSIAN_STEP_CM,
                3 => 1e-3 * cap.bin_ps,
                _ => 1e-4 * base[i].abs().max(1e-12),
            })
            .collect();
        let h = numerical_hessian(&f, &x, &steps);
        evaluations += (2 * free.len() * free.len() + 1) as u64;
        let idx: Vec<usize> = (0..g).chain((0..3).map(|j| g + 3 * c + j)).collect();
        for (a, &ia) in idx.iter().enumerate() {
            for (b, &ib) in idx.iter().enumerate() {
                hess[ia][ib] += h[a][b];
            }
        }
    }
    let inverse = invert(&hess);
    let se = |i: usize, bound: f64| standard_error(inverse.as_ref(), i, bound);
    let mut undetermined = Vec::new();
    let mut estimate = |index: usize, name: &str| {
        let (value, fitted) = (shared[index], opts.free()[index]);
        let at_bound = fitted && value < AT_ZERO_PER_CM;
        let standard_error = globals
            .iter()
            .position(|&x| x == index)
            .and_then(|i| se(i, value))
            .filter(|_| !at_bound);
        if at_bound {
            undetermined.push(format!(
                "{name}: the fit ran to its bound 0 (the captures prefer none; no standard error)"
            ));
        } else if fitted && standard_error.is_none() {
            undetermined.push(format!(
                "{name}: the captures do not determine it (standard error above its value or a flat likelihood)"
            ));
        }
        MediumEstimate {
            value,
            standard_error,
            fitted,
        }
    };
    let mu_a_est = estimate(0, "mu_a");
    let mu_s_est = estimate(1, "mu_s'");
    let offset_est = estimate(2, "detector offset");
    let mut chi2_total = 0.0;
    let mut bins = 0;
    let captures: Vec<CaptureFit> = prepared
        .iter()
        .enumerate()
        .map(|(c, cap)| {
            let [t0, a, b] = nuisance[c];
            let shape = cap.shape(&d[c], t0).unwrap_or_default();
            let fitted: Vec<f64> = shape.iter().map(|s| a * s + b).collect();
            let chi2 = pearson_chi2(&cap.fitted_bins(fitted.clone()), &cap.counts);
            chi2_total += chi2;
            // Only the fitted bins count: the left-out rising edge adds
            // neither chi-square nor degrees of freedom.
            bins += cap.counts.len();
            CaptureFit {
                label: cap.label.to_string(),
                thickness_cm: cap.thickness_cm,
                t0_ps: t0,
                t0_standard_error_ps: se(g + 3 * c, 10.0 * cap.bin_ps),
                signal: a,
                background: b,
                window_start: cap.start,
                measured: cap.window.to_vec(),
                chi2_window: pearson_chi2(&fitted, cap.window),
                fitted,
                left_out: cap.left_out.clone(),
                chi2,
                dof: cap.counts.len().saturating_sub(3),
            }
        })
        .collect();
    let dof = bins.saturating_sub(k).max(1);
    Ok(SlabFit {
        mu_a: mu_a_est,
        mu_s_reduced: mu_s_est,
        offset: offset_est,
        rising_edge_share: opts.rising_edge_share,
        refractive_index: opts.refractive_index,
        extrapolation_cm: d[0].diffusion.slab.map_or(0.0, |s| s.extrapolation_cm),
        captures,
        chi2_per_dof: chi2_total / dof as f64,
        dof,
        evaluations,
        undetermined,
    })
}

/// Expected counts in bins `0..bins` (of the response's width, from time
/// 0) of a capture through a slab `thickness_cm` thick with the shared
/// parameters of `opts`: the model of the module's documentation,
/// `signal` counts in all and `background` per bin. For simulating
/// captures and checking fits.
pub fn expected_capture(
    irf: &MeasuredIrf,
    opts: &SlabFitOptions,
    thickness_cm: f64,
    t0_ps: f64,
    signal: f64,
    background: f64,
    bins: usize,
) -> Result<Vec<f64>, CalibrateError> {
    let d = at_detector(opts, opts.start(), thickness_cm)
        .ok_or_else(|| CalibrateError::Invalid("invalid medium for this slab".into()))?;
    let zeros = vec![0.0; bins];
    let window = Prepared {
        label: "model",
        window: &zeros,
        counts: Vec::new(),
        left_out: 0..0,
        start: 0,
        bin_ps: irf.bin_width_ps,
        hist_start_ps: 0.0,
        thickness_cm,
        irf,
        convolution: ResponseConvolution::new(&irf.weights, bins),
        peak_time_ps: 0.0,
    };
    let shape = window
        .shape(&d, t0_ps)
        .ok_or_else(|| CalibrateError::Invalid("no light falls in the bins".into()))?;
    Ok(shape.iter().map(|s| signal * s + background).collect())
}
