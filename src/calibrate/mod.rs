//! The medium's and the instrument's parameters from a measured stack: a
//! Poisson maximum-likelihood fit of its time profile (counts summed over
//! the sensor per bin).
//!
//! Model of bin `i`: `A p_i(mu_a, mu_s', t0, IRF) + B`, with `p` the share
//! of the ST-PSF's light in each bin over the whole sensor plane
//! ([`scatterscope_physics::kernel::bin_profile`]: light landing off the
//! sensor is assumed negligible), `A` the signal counts and `B` the
//! background counts per bin over the sensor. `t0` shifts the model's time
//! axis against the stack's. The fit is Nelder-Mead on log-parameters;
//! standard errors come from the inverse of the negative log-likelihood's
//! Hessian (numerical, central differences) at the optimum. A parameter
//! whose standard error exceeds its value, or a Hessian that is not
//! positive definite, is reported as not determined by the data.

use argmin::core::CostFunction;
use scatterscope_physics::kernel::bin_profile;
use scatterscope_physics::{InstrumentResponse, Irf, Setup};

pub mod hessian;
pub mod histogram;
pub mod irf_fit;
pub mod measured_irf;
pub mod parts;
pub mod response_convolution;
pub mod search;
pub mod transmittance;

use hessian::{invert, numerical_hessian, standard_error};
use search::{nelder_mead, pearson_chi2};

/// Which parameters are fitted; the others keep the setup's values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Free {
    /// Absorption coefficient.
    pub mu_a: bool,
    /// Reduced scattering coefficient `(1 - g) mu_s`.
    pub mu_s_reduced: bool,
    /// Shift of time zero.
    pub t0: bool,
    /// FWHM of the instrument response (a Gaussian if the setup has none).
    pub irf_fwhm: bool,
}

/// Parameter names that changed, old and new: `mu_s` named the reduced
/// scattering coefficient mu_s', which the physics settings call `mu_s`
/// only for the scattering coefficient itself (mu_s' = (1 - g) mu_s).
pub const RENAMED_PARAMETERS: [(&str, &str); 2] =
    [("mu_s", "mu_s_reduced"), ("offset", "detector_offset")];

/// `name` as the fits read it: an old name ([`RENAMED_PARAMETERS`]) as its
/// new one, any other as it is.
pub fn current_parameter_name(name: &str) -> &str {
    RENAMED_PARAMETERS
        .iter()
        .find(|(old, _)| *old == name)
        .map_or(name, |(_, new)| new)
}

/// The old names among `names`, each with its new one, for the caller to
/// say so ([`RENAMED_PARAMETERS`]).
pub fn renamed_in<S: AsRef<str>>(names: &[S]) -> Vec<(&'static str, &'static str)> {
    RENAMED_PARAMETERS
        .iter()
        .filter(|(old, _)| names.iter().any(|n| n.as_ref() == *old))
        .copied()
        .collect()
}

impl Free {
    /// The parameters named in `names` (`mu_a`, `mu_s_reduced`, `t0`,
    /// `irf`; the old `mu_s` for `mu_s_reduced`).
    pub fn from_names<S: AsRef<str>>(names: &[S]) -> Result<Self, CalibrateError> {
        let mut free = Free {
            mu_a: false,
            mu_s_reduced: false,
            t0: false,
            irf_fwhm: false,
        };
        for name in names {
            match current_parameter_name(name.as_ref()) {
                "mu_a" => free.mu_a = true,
                "mu_s_reduced" => free.mu_s_reduced = true,
                "t0" => free.t0 = true,
                "irf" => free.irf_fwhm = true,
                other => {
                    return Err(CalibrateError::Invalid(format!(
                        "unknown parameter `{other}` (use mu_a, mu_s_reduced, t0, irf)"
                    )));
                }
            }
        }
        Ok(free)
    }

    /// The names of the fitted parameters, as [`Free::from_names`] takes
    /// them.
    pub fn names(&self) -> Vec<&'static str> {
        [
            (self.mu_a, "mu_a"),
            (self.mu_s_reduced, "mu_s_reduced"),
            (self.t0, "t0"),
            (self.irf_fwhm, "irf"),
        ]
        .into_iter()
        .filter_map(|(on, name)| on.then_some(name))
        .collect()
    }
}

/// One fitted or fixed parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Parameter {
    /// Name as the output prints it.
    pub name: &'static str,
    /// Unit.
    pub unit: &'static str,
    /// Value at the optimum (or the fixed value).
    pub value: f64,
    /// Standard error, for fitted parameters the data determine.
    pub standard_error: Option<f64>,
    /// Whether it was fitted.
    pub fitted: bool,
}

/// The result of [`calibrate`].
#[derive(Debug, Clone)]
pub struct Calibration {
    /// Every parameter, fitted or fixed, in a fixed order: mu_a, mu_s',
    /// t0 shift, IRF FWHM, signal counts, background counts per bin.
    pub parameters: Vec<Parameter>,
    /// The setup with the fitted medium and IRF (time zero not applied).
    pub setup: Setup,
    /// Pearson chi-square per degree of freedom of the fit.
    pub chi2_per_dof: f64,
    /// Degrees of freedom: bins less fitted parameters.
    pub dof: usize,
    /// Measured counts per bin.
    pub measured: Vec<f64>,
    /// Fitted expected counts per bin.
    pub fitted: Vec<f64>,
    /// Likelihood evaluations the fit took.
    pub evaluations: u64,
    /// Parameters the data do not determine, and why.
    pub undetermined: Vec<String>,
}

impl Calibration {
    /// The fit's parameters, quality and notes, one printable line each.
    pub fn lines(&self) -> Vec<String> {
        let mut lines = vec![format!(
            "fit of {} bins ({} counts), {} likelihood evaluations:",
            self.measured.len(),
            self.measured.iter().sum::<f64>(),
            self.evaluations
        )];
        for p in &self.parameters {
            let value = match (p.fitted, p.standard_error) {
                (true, Some(se)) => format!("{:.6} +- {:.2e}", p.value, se),
                (true, None) => format!("{:.6} (not determined by the data)", p.value),
                (false, _) => format!("{:.6} (fixed)", p.value),
            };
            lines.push(format!("  {:<11} {value} {}", p.name, p.unit));
        }
        lines.push(format!(
            "  chi-square per degree of freedom {:.3} ({} degrees of freedom)",
            self.chi2_per_dof, self.dof
        ));
        lines.extend(self.undetermined.iter().map(|u| format!("  note: {u}")));
        if self.setup.medium.model == scatterscope_physics::MediumModel::MonteCarlo {
            lines.push(format!(
                "  note: the fitted profile is Monte Carlo transport's ({} packets per evaluation, one seed for every medium); the medium's standard errors are taken over {:.0} % steps and leave out that profile's own Monte Carlo error",
                scatterscope_physics::transport::PROFILE_PACKETS,
                100.0 * MONTE_CARLO_STEP
            ));
        }
        lines
    }
}

/// Why a calibration cannot run.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    /// The profile or the setup cannot be fitted.
    #[error("calibration: {0}")]
    Invalid(String),
    /// A histogram file cannot be read.
    #[error("calibration: {0}")]
    Histogram(#[from] histogram::HistogramError),
    /// A reference recording does not give an instrument response.
    #[error(transparent)]
    Response(#[from] measured_irf::IrfError),
    /// A stack file cannot be read.
    #[error(transparent)]
    Stack(#[from] crate::stack::StackError),
}

/// Natural parameters in the order of [`Calibration::parameters`].
const NAMES: [(&str, &str); 6] = [
    ("mu_a", "1/cm"),
    ("mu_s'", "1/cm"),
    ("t0 shift", "ps"),
    ("IRF FWHM", "ps"),
    ("signal", "counts"),
    ("background", "counts per bin"),
];

struct Model<'a> {
    setup: Setup,
    counts: &'a [f64],
    start_ps: f64,
    /// Indices into the natural parameters of the free ones (A and B last).
    free: Vec<usize>,
    base: [f64; 6],
}

impl Model<'_> {
    /// Natural parameters from the optimiser's vector (logs except t0).
    fn natural(&self, x: &[f64]) -> [f64; 6] {
        let mut p = self.base;
        for (&i, &v) in self.free.iter().zip(x) {
            p[i] = if i == 2 { v } else { v.exp() };
        }
        p
    }

    /// The setup with the medium and IRF of `p`, its bins on the model's
    /// time axis (shifted by `p`'s time zero).
    fn setup_at(&self, p: &[f64; 6]) -> Setup {
        let mut s = self.setup.clone();
        s.medium.mu_a_per_cm = p[0];
        s.medium.mu_s_per_cm = p[1] / (1.0 - s.medium.g);
        s.bins.start_ps = self.start_ps - p[2];
        if p[3] > 0.0 {
            let tail_ps = s
                .irf
                .as_ref()
                .and_then(InstrumentResponse::parametric)
                .map_or(0.0, |i| i.tail_ps);
            s.irf = Some(
                Irf {
                    fwhm_ps: p[3],
                    tail_ps,
                }
                .into(),
            );
        }
        s
    }

    fn expected(&self, p: &[f64; 6]) -> Option<Vec<f64>> {
        let profile = bin_profile(&self.setup_at(p)).ok()?;
        Some(profile.iter().map(|q| p[4] * q + p[5]).collect())
    }

    fn nll(&self, p: &[f64; 6]) -> f64 {
        match self.expected(p) {
            Some(mu) => mu
                .iter()
                .zip(self.counts)
                .map(|(&u, &m)| {
                    if u <= 0.0 {
                        if m > 0.0 { f64::INFINITY } else { 0.0 }
                    } else {
                        u - if m > 0.0 { m * u.ln() } else { 0.0 }
                    }
                })
                .sum(),
            None => f64::INFINITY,
        }
    }
}

impl CostFunction for Model<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, x: &Self::Param) -> Result<f64, argmin::core::Error> {
        let v = self.nll(&self.natural(x));
        // Nelder-Mead compares values: an impossible point is just bad.
        Ok(if v.is_finite() { v } else { f64::MAX })
    }
}

/// Fits `counts` (one per bin, bins of the setup's width from `start_ps`)
/// with `setup`'s physics as the starting point.
pub fn calibrate(
    counts: &[f64],
    start_ps: f64,
    setup: &Setup,
    free: Free,
) -> Result<Calibration, CalibrateError> {
    let n = counts.len();
    if counts.iter().any(|c| !c.is_finite() || *c < 0.0) {
        return Err(CalibrateError::Invalid(
            "the time profile holds negative or non-finite counts".into(),
        ));
    }
    let total: f64 = counts.iter().sum();
    if total <= 0.0 {
        return Err(CalibrateError::Invalid(
            "the time profile holds no counts".into(),
        ));
    }
    if setup.medium.g >= 1.0 {
        return Err(CalibrateError::Invalid(format!(
            "g = {} leaves no scattering to fit",
            setup.medium.g
        )));
    }
    let mut setup = setup.clone();
    setup.bins.count = n;
    let lowest = counts.iter().copied().fold(f64::INFINITY, f64::min);
    let background = lowest.max(1e-3);
    let irf_fwhm = match &setup.irf {
        Some(InstrumentResponse::Parametric(irf)) => irf.fwhm_ps,
        Some(InstrumentResponse::Measured(_)) if free.irf_fwhm => {
            return Err(CalibrateError::Invalid(
                "the IRF width cannot be fitted: the instrument response is a measured table (leave `irf` out of the fitted parameters)".into(),
            ));
        }
        Some(InstrumentResponse::Measured(_)) => 0.0,
        // A fitted IRF the setup lacks starts at two bins.
        None if free.irf_fwhm => 2.0 * setup.bins.width_ps,
        None => 0.0,
    };
    let base = [
        setup.medium.mu_a_per_cm.max(1e-4),
        (1.0 - setup.medium.g) * setup.medium.mu_s_per_cm,
        0.0,
        irf_fwhm,
        (total - background * n as f64).max(1.0),
        background,
    ];
    let mut free_idx: Vec<usize> = [
        (free.mu_a, 0),
        (free.mu_s_reduced, 1),
        (free.t0, 2),
        (free.irf_fwhm, 3),
    ]
    .into_iter()
    .filter_map(|(f, i)| f.then_some(i))
    .collect();
    free_idx.extend([4, 5]);
    if n <= free_idx.len() {
        return Err(CalibrateError::Invalid(format!(
            "{n} bins cannot determine {} parameters",
            free_idx.len()
        )));
    }
    let bin_width_ps = setup.bins.width_ps;
    let model = Model {
        setup,
        counts,
        start_ps,
        free: free_idx.clone(),
        base,
    };
    let x0: Vec<f64> = free_idx
        .iter()
        .map(|&i| if i == 2 { base[2] } else { base[i].ln() })
        .collect();
    let steps: Vec<f64> = free_idx
        .iter()
        .map(|&i| if i == 2 { bin_width_ps } else { 0.2 })
        .collect();
    let (x, model, evaluations) = nelder_mead(model, x0, &steps, 3000, "the fit")?;
    let p = model.natural(&x);
    let fitted = model
        .expected(&p)
        .ok_or_else(|| CalibrateError::Invalid("the fitted physics is invalid".into()))?;
    let (se, undetermined) = standard_errors(&model, &p);
    // Signal and background are always fitted; the physics asked for is
    // indices 0 to 3. When the data determine none of it the fit is a
    // guess (a stack of one photon gave mu_a 4e11), not a calibration.
    let asked: Vec<usize> = free_idx.iter().copied().filter(|&i| i < 4).collect();
    if !asked.is_empty()
        && asked
            .iter()
            .all(|i| undetermined.iter().any(|&j| free_idx[j] == *i))
    {
        let names: Vec<&str> = asked.iter().map(|&i| NAMES[i].0).collect();
        return Err(CalibrateError::Invalid(format!(
            "the data ({} counts in {n} bins) determine none of the fitted parameters ({}): the fit would be a guess",
            counts.iter().sum::<f64>(),
            names.join(", ")
        )));
    }
    let chi2 = pearson_chi2(&fitted, counts);
    let dof = n - free_idx.len();
    // A measured table is fixed; its FWHM is reported in the IRF's row.
    let table_fwhm = match &model.setup.irf {
        Some(InstrumentResponse::Measured(t)) => Some(t.fwhm_ps()),
        _ => None,
    };
    let parameters = NAMES
        .iter()
        .enumerate()
        .map(|(i, &(name, unit))| Parameter {
            name: if i == 3 && table_fwhm.is_some() {
                "IRF FWHM (measured table)"
            } else {
                name
            },
            unit,
            value: if i == 3 {
                table_fwhm.unwrap_or(p[i])
            } else {
                p[i]
            },
            standard_error: free_idx.iter().position(|&f| f == i).and_then(|j| se[j]),
            fitted: free_idx.contains(&i),
        })
        .collect();
    let mut out_setup = model.setup_at(&p);
    out_setup.bins.start_ps = start_ps;
    Ok(Calibration {
        parameters,
        setup: out_setup,
        chi2_per_dof: chi2 / dof as f64,
        dof,
        measured: counts.to_vec(),
        fitted,
        evaluations,
        undetermined: undetermined
            .into_iter()
            .map(|j| {
                format!(
                    "{}: the data do not determine it (standard error above its value or a flat likelihood)",
                    NAMES[free_idx[j]].0
                )
            })
            .collect(),
    })
}

/// The relative step over which the medium's standard errors are taken
/// under the Monte Carlo medium (a fixed-seed run's profile moves in small
/// jumps with the medium; over this step the jumps average out).
pub const MONTE_CARLO_STEP: f64 = 0.02;

/// Standard errors of the free parameters from the inverse Hessian of the
/// negative log-likelihood in natural parameters, and the indices (into
/// the free list) of those the data do not determine.
fn standard_errors(model: &Model, p: &[f64; 6]) -> (Vec<Option<f64>>, Vec<usize>) {
    let free = &model.free;
    let f = |v: &[f64]| {
        let mut q = *p;
        for (&i, &x) in free.iter().zip(v) {
            q[i] = x;
        }
        model.nll(&q)
    };
    let x: Vec<f64> = free.iter().map(|&i| p[i]).collect();
    // Transport's profile is a fixed-seed Monte Carlo run: smooth in the
    // signal and background, but its packets' paths change in steps with
    // the medium, so the medium's curvature is taken over steps of
    // [`MONTE_CARLO_STEP`] rather than at a point.
    let monte_carlo = model.setup.medium.model == scatterscope_physics::MediumModel::MonteCarlo;
    let steps: Vec<f64> = free
        .iter()
        .map(|&i| match i {
            2 => 1e-3 * model.setup.bins.width_ps,
            0 | 1 if monte_carlo => MONTE_CARLO_STEP * p[i].abs().max(1e-12),
            _ => 1e-4 * p[i].abs().max(1e-12),
        })
        .collect();
    let inverse = invert(&numerical_hessian(&f, &x, &steps));
    let mut se = vec![None; free.len()];
    let mut undetermined = Vec::new();
    for (a, &i) in free.iter().enumerate() {
        // Time zero may be 0: it counts as determined within ten bins.
        let bound = match i {
            2 => 10.0 * model.setup.bins.width_ps,
            i => p[i].abs(),
        };
        se[a] = standard_error(inverse.as_ref(), a, bound);
        if se[a].is_none() {
            undetermined.push(a);
        }
    }
    (se, undetermined)
}

/// Fits `stack`'s physics to its time profile ([`calibrate`], starting
/// from `setup`) and applies the fit: the returned calibration's setup
/// holds the fitted medium and IRF, and a fitted time-zero shift is
/// applied to both the stack's bin starts and that setup's bins, so the
/// two stay aligned for [`crate::Problem::new`].
pub fn fit_stack_physics(
    stack: &mut crate::stack::Stack,
    setup: &Setup,
    free: Free,
) -> Result<Calibration, CalibrateError> {
    let (start, counts) = time_profile(stack)?;
    let mut cal = calibrate(&counts, start, setup, free)?;
    let shift = cal.parameters[2].value;
    cal.setup.bins.start_ps -= shift;
    stack
        .meta
        .bin_starts_ps
        .iter_mut()
        .for_each(|t| *t -= shift);
    Ok(cal)
}

/// The time profile of `stack`: counts summed over the sensor per bin, and
/// the start of its first bin (ps). Its bins must follow one another.
pub fn time_profile(stack: &crate::stack::Stack) -> Result<(f64, Vec<f64>), CalibrateError> {
    let starts = &stack.meta.bin_starts_ps;
    let width = stack.meta.bin_width_ps;
    let first = *starts
        .first()
        .ok_or_else(|| CalibrateError::Invalid("the stack has no bins".into()))?;
    if let Some((i, t)) = starts
        .iter()
        .enumerate()
        .find(|(i, t)| (**t - (first + *i as f64 * width)).abs() > 1e-6 * width)
    {
        return Err(CalibrateError::Invalid(format!(
            "bin {i} starts at {t} ps, not {} ps: calibration needs consecutive bins",
            first + i as f64 * width
        )));
    }
    let counts = stack
        .data
        .outer_iter()
        .map(|img| img.iter().map(|&v| f64::from(v)).sum())
        .collect();
    Ok((first, counts))
}
