//! The instrument response (IRF): the spread of the recorded time of a
//! photon around its arrival time, from detector and TCSPC jitter and the
//! laser pulse's width.
//!
//! The parametric form is an exponentially modified Gaussian: a Gaussian of
//! the given FWHM centred on the time zero, plus an exponential delay of
//! time constant `tail_ps` (the diffusion tail of a SPAD; 0 for none). Time
//! zero is the Gaussian's centre, which is where a reference measurement's
//! peak sits when the tail is short against the FWHM.
//!
//! A bin `[ta, tb)` then collects a photon that arrived at `s` with
//! probability `W(s) = F(tb - s) - F(ta - s)`, `F` the IRF's cumulative
//! distribution, and the bin's kernel is `int h(x, y, s) W(s) ds`: the
//! ST-PSF convolved in time with the IRF and integrated over the bin, with no
//! fine time grid needed (the kernel builder integrates `W` exactly inside
//! its adaptive quadrature).
//!
//! A measured response is an [`IrfTable`]: the share of photons in each
//! delay bin of a reference recording, a piecewise-constant density whose
//! `F` is piecewise linear. [`InstrumentResponse`] is either.

use serde::{Deserialize, Serialize};

use crate::error::{ParamError, non_negative, positive};

/// `FWHM = FWHM_PER_SIGMA sigma` for a Gaussian.
pub const FWHM_PER_SIGMA: f64 = 2.354_820_045_030_949_3;

/// Standard deviations of the Gaussian part beyond which the IRF is taken
/// as zero (a share under 1e-16).
pub const GAUSS_SIGMAS: f64 = 8.5;

/// Time constants of the tail beyond which it is taken as zero (e^-37 <
/// 1e-16).
pub const TAIL_CONSTANTS: f64 = 37.0;

/// Longest IRF width or tail accepted (ps).
pub const MAX_IRF_PS: f64 = 1e6;

/// Parametric instrument response.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Irf {
    /// Full width at half maximum of the Gaussian part (ps).
    pub fwhm_ps: f64,
    /// Time constant of the exponential tail (ps); 0 for a plain Gaussian.
    pub tail_ps: f64,
}

impl Irf {
    /// Checks both fields; the error names the first invalid one.
    pub fn validate(&self) -> Result<(), ParamError> {
        positive("irf_fwhm_ps", self.fwhm_ps)?;
        non_negative("irf_tail_ps", self.tail_ps)?;
        for (field, v) in [("irf_fwhm_ps", self.fwhm_ps), ("irf_tail_ps", self.tail_ps)] {
            if v > MAX_IRF_PS {
                return Err(ParamError::new(
                    field,
                    v,
                    format!(
                        "at most {MAX_IRF_PS:e} ps (a microsecond: longer than any time window)"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Standard deviation of the Gaussian part (ps).
    pub fn sigma_ps(&self) -> f64 {
        self.fwhm_ps / FWHM_PER_SIGMA
    }

    /// Earliest and latest delay with a share of the IRF above 1e-16 (ps).
    pub fn support_ps(&self) -> (f64, f64) {
        let s = GAUSS_SIGMAS * self.sigma_ps();
        (-s, s + TAIL_CONSTANTS * self.tail_ps)
    }

    /// Mean delay (ps): the tail's time constant.
    pub fn mean_ps(&self) -> f64 {
        self.tail_ps
    }

    /// Probability density of the delay `x` (1/ps).
    pub fn density(&self, x: f64) -> f64 {
        let s = self.sigma_ps();
        if self.tail_ps == 0.0 {
            return (-0.5 * (x / s).powi(2)).exp() / (s * (2.0 * std::f64::consts::PI).sqrt());
        }
        // (1/l) exp(s^2/(2 l^2) - x/l) Phi(x/s - s/l), in the stable form.
        let l = self.tail_ps;
        scaled_normal_tail(x, s, l) / l
    }

    /// Probability that the delay is below `x`.
    pub fn cdf(&self, x: f64) -> f64 {
        let s = self.sigma_ps();
        let g = normal_cdf(x / s);
        if self.tail_ps == 0.0 {
            return g;
        }
        (g - scaled_normal_tail(x, s, self.tail_ps)).clamp(0.0, 1.0)
    }

    /// Probability that the delay is at least `x`, `1 - cdf(x)` computed
    /// without cancellation where it is small.
    pub fn survival(&self, x: f64) -> f64 {
        let s = self.sigma_ps();
        let g = normal_cdf(-x / s);
        if self.tail_ps == 0.0 {
            return g;
        }
        (g + scaled_normal_tail(x, s, self.tail_ps)).clamp(0.0, 1.0)
    }

    /// Probability that a photon arriving at `s` is recorded in `[ta, tb)`,
    /// without cancellation on either side of the bin.
    pub fn bin_weight(&self, ta: f64, tb: f64, s: f64) -> f64 {
        if ta - s > 0.0 {
            (self.survival(ta - s) - self.survival(tb - s)).max(0.0)
        } else {
            (self.cdf(tb - s) - self.cdf(ta - s)).max(0.0)
        }
    }
}

/// Standard normal cumulative distribution.
pub fn normal_cdf(z: f64) -> f64 {
    0.5 * libm::erfc(-z / std::f64::consts::SQRT_2)
}

/// `exp(s^2/(2 l^2) - x/l) Phi(x/s - s/l)`, the exponential part of the
/// exponentially modified Gaussian, without overflow: where the exponent is
/// large it is rewritten as `exp(-x^2/(2 s^2)) erfcx(-b/sqrt 2) / 2`.
fn scaled_normal_tail(x: f64, s: f64, l: f64) -> f64 {
    let b = x / s - s / l;
    if b < 0.0 {
        (-0.5 * (x / s).powi(2)).exp() * 0.5 * erfcx(-b / std::f64::consts::SQRT_2)
    } else {
        (0.5 * (s / l).powi(2) - x / l).exp() * normal_cdf(b)
    }
}

/// Scaled complementary error function `exp(y^2) erfc(y)` for `y >= 0`:
/// directly while `exp(y^2)` is finite, by its asymptotic series beyond
/// (six terms: relative error below 1e-14 there).
pub fn erfcx(y: f64) -> f64 {
    if y < 25.0 {
        (y * y).exp() * libm::erfc(y)
    } else {
        // sum_n (-1)^n (2n - 1)!! / (2 y^2)^n, Horner in r = 1 / (2 y^2).
        let r = 0.5 / (y * y);
        let series =
            1.0 - r * (1.0 - 3.0 * r * (1.0 - 5.0 * r * (1.0 - 7.0 * r * (1.0 - 9.0 * r))));
        series / (y * std::f64::consts::PI.sqrt())
    }
}

/// Most entries a measured table may hold.
pub const MAX_TABLE_BINS: usize = 1 << 16;

/// An instrument response measured from a reference recording: the share
/// of photons recorded with each delay, as a piecewise-constant density on
/// equal delay bins. Entry `j` covers delays `[start_ps + j bin_ps,
/// start_ps + (j + 1) bin_ps)`; time zero is wherever the reference put it
/// (the centre of its fullest bin, for a table measured by the main
/// crate's `MeasuredIrf::table`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "TableFields", into = "TableFields")]
pub struct IrfTable {
    bin_ps: f64,
    start_ps: f64,
    weights: Vec<f64>,
    /// `cumulative[j]`: sum of the weights before entry `j` (n + 1 values).
    cumulative: Vec<f64>,
    /// `remaining[j]`: sum of the weights from entry `j` on, summed from
    /// the end so that the far tail keeps its digits.
    remaining: Vec<f64>,
}

/// The stored fields of an [`IrfTable`].
#[derive(Serialize, Deserialize)]
struct TableFields {
    /// Width of the table's delay bins (ps).
    bin_ps: f64,
    /// Delay of the first bin's start (ps).
    start_ps: f64,
    /// Share of the photons in each bin.
    weights: Vec<f64>,
}

impl TryFrom<TableFields> for IrfTable {
    type Error = ParamError;
    fn try_from(f: TableFields) -> Result<Self, ParamError> {
        IrfTable::new(f.bin_ps, f.start_ps, f.weights)
    }
}

impl From<IrfTable> for TableFields {
    fn from(t: IrfTable) -> Self {
        TableFields {
            bin_ps: t.bin_ps,
            start_ps: t.start_ps,
            weights: t.weights,
        }
    }
}

impl IrfTable {
    /// A table of `weights` (any non-negative scale; stored scaled to unit
    /// sum, unless within 1e-12 of it already) on delay bins of `bin_ps` from `start_ps`. The error names the
    /// field and value that are not usable.
    pub fn new(bin_ps: f64, start_ps: f64, weights: Vec<f64>) -> Result<Self, ParamError> {
        positive("irf_table_bin_ps", bin_ps)?;
        if !start_ps.is_finite() || start_ps.abs() > MAX_IRF_PS {
            return Err(ParamError::new(
                "irf_table_start_ps",
                start_ps,
                format!("a finite delay of at most {MAX_IRF_PS:e} ps"),
            ));
        }
        if weights.is_empty() || weights.len() > MAX_TABLE_BINS {
            return Err(ParamError::new(
                "irf_table_weights",
                weights.len() as f64,
                format!("between 1 and {MAX_TABLE_BINS} entries"),
            ));
        }
        if weights.len() as f64 * bin_ps > MAX_IRF_PS {
            return Err(ParamError::new(
                "irf_table_bin_ps",
                bin_ps,
                format!(
                    "{} entries of {bin_ps} ps span more than {MAX_IRF_PS:e} ps",
                    weights.len()
                ),
            ));
        }
        if let Some((j, &w)) = weights
            .iter()
            .enumerate()
            .find(|(_, w)| !(w.is_finite() && **w >= 0.0))
        {
            return Err(ParamError::new(
                "irf_table_weights",
                w,
                format!("entry {j}: weights must be finite and non-negative"),
            ));
        }
        let total: f64 = weights.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return Err(ParamError::new(
                "irf_table_weights",
                total,
                "the weights must have a positive finite sum (a response with photons)",
            ));
        }
        // Scaled to unit sum, unless already there to round-off (so that a
        // stored table reads back bit for bit).
        let weights: Vec<f64> = if (total - 1.0).abs() > 1e-12 {
            weights.iter().map(|w| w / total).collect()
        } else {
            weights
        };
        let mut cumulative = Vec::with_capacity(weights.len() + 1);
        let mut acc = 0.0;
        cumulative.push(0.0);
        for w in &weights {
            acc += w;
            cumulative.push(acc);
        }
        let mut remaining = vec![0.0; weights.len() + 1];
        for j in (0..weights.len()).rev() {
            remaining[j] = remaining[j + 1] + weights[j];
        }
        Ok(Self {
            bin_ps,
            start_ps,
            weights,
            cumulative,
            remaining,
        })
    }

    /// Width of the delay bins (ps).
    pub fn bin_ps(&self) -> f64 {
        self.bin_ps
    }

    /// Delay of the first bin's start (ps).
    pub fn start_ps(&self) -> f64 {
        self.start_ps
    }

    /// Share of the photons in each delay bin (sums to 1).
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Earliest and latest delay the table holds (ps).
    pub fn support_ps(&self) -> (f64, f64) {
        (
            self.start_ps,
            self.start_ps + self.weights.len() as f64 * self.bin_ps,
        )
    }

    /// Mean delay (ps).
    pub fn mean_ps(&self) -> f64 {
        self.weights
            .iter()
            .enumerate()
            .map(|(j, w)| w * (self.start_ps + (j as f64 + 0.5) * self.bin_ps))
            .sum()
    }

    /// Full width at half maximum (ps): between the half-maximum crossings
    /// on either side of the fullest bin, interpolated linearly between
    /// bin centres (a crossing beyond the table is put at its edge).
    pub fn fwhm_ps(&self) -> f64 {
        let w = &self.weights;
        let peak = (0..w.len())
            .max_by(|&a, &b| w[a].total_cmp(&w[b]))
            .unwrap_or(0);
        let half = 0.5 * w[peak];
        let right = (peak + 1..w.len())
            .find(|&k| w[k] < half)
            .map_or(w.len() as f64 - 0.5, |k| {
                (k - 1) as f64 + (w[k - 1] - half) / (w[k - 1] - w[k])
            });
        let left = (0..peak).rev().find(|&k| w[k] < half).map_or(-0.5, |k| {
            (k + 1) as f64 - (w[k + 1] - half) / (w[k + 1] - w[k])
        });
        (right - left) * self.bin_ps
    }

    /// Position of delay `x` in bins from the table's start, and the bin.
    fn locate(&self, x: f64) -> (usize, f64) {
        let u = (x - self.start_ps) / self.bin_ps;
        let j = (u.floor().max(0.0) as usize).min(self.weights.len() - 1);
        (j, (u - j as f64).clamp(0.0, 1.0))
    }

    /// Probability that the delay is below `x`.
    pub fn cdf(&self, x: f64) -> f64 {
        let (lo, hi) = self.support_ps();
        if x <= lo {
            return 0.0;
        }
        if x >= hi {
            return 1.0;
        }
        let (j, f) = self.locate(x);
        self.cumulative[j] + f * self.weights[j]
    }

    /// Probability that the delay is at least `x`, summed from the far end.
    pub fn survival(&self, x: f64) -> f64 {
        let (lo, hi) = self.support_ps();
        if x <= lo {
            return 1.0;
        }
        if x >= hi {
            return 0.0;
        }
        let (j, f) = self.locate(x);
        self.remaining[j + 1] + (1.0 - f) * self.weights[j]
    }

    /// Probability that a photon arriving at `s` is recorded in `[ta, tb)`:
    /// `F(tb - s) - F(ta - s)`, each side from the end where it keeps its
    /// digits.
    pub fn bin_weight(&self, ta: f64, tb: f64, s: f64) -> f64 {
        if self.cdf(ta - s) > 0.5 {
            (self.survival(ta - s) - self.survival(tb - s)).max(0.0)
        } else {
            (self.cdf(tb - s) - self.cdf(ta - s)).max(0.0)
        }
    }

    /// Delay of a photon for a uniform draw `u` in [0, 1): the inverse of
    /// [`Self::cdf`] (uniform within each bin).
    pub fn delay_for(&self, u: f64) -> f64 {
        let j = self
            .cumulative
            .partition_point(|&c| c <= u)
            .saturating_sub(1)
            .min(self.weights.len() - 1);
        let w = self.weights[j];
        let f = if w > 0.0 {
            ((u - self.cumulative[j]) / w).clamp(0.0, 1.0)
        } else {
            0.5
        };
        self.start_ps + (j as f64 + f) * self.bin_ps
    }
}

/// The instrument response a model assumes: the parametric form or a
/// measured table. Stored as the one's or the other's fields; a stored
/// table is checked when read, and the error names the bad field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "StoredResponse", into = "StoredResponse")]
pub enum InstrumentResponse {
    /// Gaussian plus exponential tail.
    Parametric(Irf),
    /// Tabulated from a reference recording.
    Measured(IrfTable),
}

/// The stored fields of an [`InstrumentResponse`], unchecked.
#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum StoredResponse {
    Parametric(Irf),
    Measured(TableFields),
}

impl TryFrom<StoredResponse> for InstrumentResponse {
    type Error = ParamError;
    fn try_from(s: StoredResponse) -> Result<Self, ParamError> {
        Ok(match s {
            StoredResponse::Parametric(irf) => irf.into(),
            StoredResponse::Measured(f) => IrfTable::try_from(f)?.into(),
        })
    }
}

impl From<InstrumentResponse> for StoredResponse {
    fn from(r: InstrumentResponse) -> Self {
        match r {
            InstrumentResponse::Parametric(irf) => StoredResponse::Parametric(irf),
            InstrumentResponse::Measured(t) => StoredResponse::Measured(t.into()),
        }
    }
}

impl From<Irf> for InstrumentResponse {
    fn from(irf: Irf) -> Self {
        InstrumentResponse::Parametric(irf)
    }
}

impl From<IrfTable> for InstrumentResponse {
    fn from(t: IrfTable) -> Self {
        InstrumentResponse::Measured(t)
    }
}

impl InstrumentResponse {
    /// Checks the response's fields.
    pub fn validate(&self) -> Result<(), ParamError> {
        match self {
            InstrumentResponse::Parametric(irf) => irf.validate(),
            // Checked when made (and when read back).
            InstrumentResponse::Measured(_) => Ok(()),
        }
    }

    /// The parametric form, if that is what this is.
    pub fn parametric(&self) -> Option<&Irf> {
        match self {
            InstrumentResponse::Parametric(irf) => Some(irf),
            InstrumentResponse::Measured(_) => None,
        }
    }

    /// Earliest and latest delay with any share (ps).
    pub fn support_ps(&self) -> (f64, f64) {
        match self {
            InstrumentResponse::Parametric(irf) => irf.support_ps(),
            InstrumentResponse::Measured(t) => t.support_ps(),
        }
    }

    /// Mean delay (ps).
    pub fn mean_ps(&self) -> f64 {
        match self {
            InstrumentResponse::Parametric(irf) => irf.mean_ps(),
            InstrumentResponse::Measured(t) => t.mean_ps(),
        }
    }

    /// Probability that a photon arriving at `s` is recorded in `[ta, tb)`.
    pub fn bin_weight(&self, ta: f64, tb: f64, s: f64) -> f64 {
        match self {
            InstrumentResponse::Parametric(irf) => irf.bin_weight(ta, tb, s),
            InstrumentResponse::Measured(t) => t.bin_weight(ta, tb, s),
        }
    }

    /// One line for outputs: what the response is.
    pub fn describe(&self) -> String {
        match self {
            InstrumentResponse::Parametric(irf) => format!(
                "instrument response: Gaussian FWHM {} ps, exponential tail {} ps",
                irf.fwhm_ps, irf.tail_ps
            ),
            InstrumentResponse::Measured(t) => format!(
                "instrument response: measured table of {} bins of {} ps (delays {:.1} to {:.1} ps, FWHM {:.1} ps, mean delay {:.1} ps)",
                t.weights.len(),
                t.bin_ps,
                t.support_ps().0,
                t.support_ps().1,
                t.fwhm_ps(),
                t.mean_ps()
            ),
        }
    }
}
