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
