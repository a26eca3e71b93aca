//! Pointwise diffusion-approximation ST-PSF, evaluated in the log domain.
//!
//! All evaluations return natural logarithms so that `t -> 0`, huge
//! `z0^2 / (4 D c t)` and huge `mu_a c t` give `-inf` or very negative
//! numbers instead of overflow, underflow to a wrong zero, or NaN.

use crate::error::ParamError;
use crate::params::{Medium, MediumModel};
use crate::slab::{SlabTransmittance, effective_reflection};

/// Speed of light in vacuum (m/s, exact by the SI's definition of the
/// metre).
pub const SPEED_OF_LIGHT_M_PER_S: f64 = 299_792_458.0;

/// Speed of light in vacuum (cm/ns): [`SPEED_OF_LIGHT_M_PER_S`] in the
/// physics' units (the quotient is 29.9792458 to the last bit).
pub const SPEED_OF_LIGHT_CM_PER_NS: f64 = SPEED_OF_LIGHT_M_PER_S * 100.0 / 1e9;

/// Speed of light in a medium of refractive index `n`, `c / n` (cm/ps).
pub fn light_speed_cm_per_ps(refractive_index: f64) -> f64 {
    SPEED_OF_LIGHT_CM_PER_NS / 1000.0 / refractive_index
}

/// Diffusion coefficient `D = 1 / (3 (mu_a + mu_s'))` (cm), Eq. 2, from
/// the absorption and reduced scattering coefficients (1/cm).
pub fn diffusion_coefficient_cm(mu_a_per_cm: f64, mu_s_reduced_per_cm: f64) -> f64 {
    1.0 / (3.0 * (mu_a_per_cm + mu_s_reduced_per_cm))
}

/// Derived constants of the diffusion model for one medium.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Diffusion {
    /// Diffusion coefficient D = 1 / (3 (mu_a + (1 - g) mu_s)) (cm), Eq. 2.
    pub d_cm: f64,
    /// Speed of light in the medium, c / n (cm/ps).
    pub c_cm_per_ps: f64,
    /// Absorption coefficient (1/cm).
    pub mu_a_per_cm: f64,
    /// Reduced scattering coefficient (1 - g) mu_s (1/cm).
    pub mu_s_reduced_per_cm: f64,
    /// Slab thickness z0 (cm).
    pub z0_cm: f64,
    /// The finite slab's transmittance (`--medium slab`); `None` for the
    /// paper's infinite medium.
    pub slab: Option<SlabTransmittance>,
}

impl Diffusion {
    /// Derives the model constants; fails on invalid parameters.
    pub fn new(medium: &Medium) -> Result<Self, ParamError> {
        medium.validate()?;
        let mu_s_reduced = (1.0 - medium.g) * medium.mu_s_per_cm;
        let d_cm = diffusion_coefficient_cm(medium.mu_a_per_cm, mu_s_reduced);
        let c_cm_per_ps = light_speed_cm_per_ps(medium.refractive_index);
        let slab = match medium.model {
            // The Monte Carlo medium keeps the infinite medium's
            // constants for its diagnostics (spreads, peak time).
            MediumModel::Infinite | MediumModel::MonteCarlo => None,
            MediumModel::Slab => {
                // validate() has checked that the slab is thicker than this.
                let source_depth_cm = 3.0 * d_cm;
                let r = effective_reflection(medium.refractive_index);
                Some(SlabTransmittance {
                    thickness_cm: medium.thickness_cm,
                    source_depth_cm,
                    extrapolation_cm: 2.0 * (1.0 + r) / (1.0 - r) * d_cm,
                    dc_cm2_per_ps: d_cm * c_cm_per_ps,
                    absorption_per_ps: medium.mu_a_per_cm * c_cm_per_ps,
                })
            }
        };
        Ok(Self {
            d_cm,
            c_cm_per_ps,
            mu_a_per_cm: medium.mu_a_per_cm,
            mu_s_reduced_per_cm: mu_s_reduced,
            z0_cm: medium.thickness_cm,
            slab,
        })
    }

    /// `D c` (cm^2/ps): the lateral variance per axis grows as `2 D c t`.
    pub fn dc_cm2_per_ps(&self) -> f64 {
        self.d_cm * self.c_cm_per_ps
    }

    /// Lateral standard deviation per axis, `sqrt(2 D c t)` (cm).
    pub fn lateral_sigma_cm(&self, t_ps: f64) -> f64 {
        (2.0 * self.dc_cm2_per_ps() * t_ps.max(0.0)).sqrt()
    }

    /// ln of the ST-PSF integrated over the whole sensor plane,
    /// `T(t) = c (4 pi D c t)^(-1/2) exp(-z0^2/(4 D c t) - mu_a c t)` (1/ps)
    /// for the infinite medium, the transmitted flux of
    /// [`SlabTransmittance`] for the slab.
    ///
    /// Returns `-inf` for `t <= 0` (causality) and for non-finite `t`.
    pub fn log_temporal_density(&self, t_ps: f64) -> f64 {
        if let Some(slab) = &self.slab {
            return slab.log_density(t_ps);
        }
        if t_ps.is_nan() || t_ps <= 0.0 || t_ps.is_infinite() {
            return f64::NEG_INFINITY;
        }
        let four_dct = 4.0 * self.dc_cm2_per_ps() * t_ps;
        self.c_cm_per_ps.ln()
            - 0.5 * (std::f64::consts::PI * four_dct).ln()
            - self.z0_cm * self.z0_cm / four_dct
            - self.mu_a_per_cm * self.c_cm_per_ps * t_ps
    }

    /// ln of the pointwise ST-PSF h(x, y, t; z0) of Eq. 6 at lateral squared
    /// distance `r2_cm2` (1/(cm^2 ps)).
    pub fn log_psf(&self, r2_cm2: f64, t_ps: f64) -> f64 {
        let log_t = self.log_temporal_density(t_ps);
        if log_t == f64::NEG_INFINITY {
            return log_t;
        }
        let four_dct = 4.0 * self.dc_cm2_per_ps() * t_ps;
        log_t - (std::f64::consts::PI * four_dct).ln() - r2_cm2 / four_dct
    }

    /// Time of maximal photon arrival, the maximum of `T(t)` (ps); 0 when
    /// `z0 = 0` (the density then decreases from `t = 0`).
    pub fn peak_time_ps(&self) -> f64 {
        if let Some(slab) = &self.slab {
            return slab.peak_time_ps();
        }
        // d/dt ln T = -1/(2t) + a/t^2 - b = 0  <=>  b t^2 + t/2 - a = 0.
        let a = self.z0_cm * self.z0_cm / (4.0 * self.dc_cm2_per_ps());
        let b = self.mu_a_per_cm * self.c_cm_per_ps;
        if a == 0.0 {
            0.0
        } else if b == 0.0 {
            2.0 * a
        } else {
            // Stable root of b t^2 + t/2 - a: t = 2a / (1/2 + sqrt(1/4 + 4ab)).
            2.0 * a / (0.5 + (0.25 + 4.0 * a * b).sqrt())
        }
    }

    /// Transport mean free path 1 / (mu_a + (1 - g) mu_s) (cm).
    pub fn transport_mean_free_path_cm(&self) -> f64 {
        3.0 * self.d_cm
    }

    /// Time light needs to cross one transport mean free path (ps).
    pub fn transport_mean_free_time_ps(&self) -> f64 {
        self.transport_mean_free_path_cm() / self.c_cm_per_ps
    }
}

/// Fraction of a unit-mass 1-D Gaussian `exp(-x^2/s^2) / (sqrt(pi) s)` that
/// falls in `[x0, x1]`, computed without cancellation in the tails.
pub fn gaussian_interval_fraction(x0: f64, x1: f64, s: f64) -> f64 {
    if s.is_nan() || s <= 0.0 {
        // A delta at 0: all of it when 0 is inside the half-open cell.
        return if x0 <= 0.0 && 0.0 < x1 { 1.0 } else { 0.0 };
    }
    let (u0, u1) = (x0 / s, x1 / s);
    let f = if u0 >= 0.0 {
        libm::erfc(u0) - libm::erfc(u1)
    } else if u1 <= 0.0 {
        libm::erfc(-u1) - libm::erfc(-u0)
    } else {
        libm::erf(u1) - libm::erf(u0)
    };
    (0.5 * f).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::Preset;

    /// The speed in the physics' units is the decimal value to the last
    /// bit, so deriving it from the metre's speed changed no result.
    #[test]
    fn light_speed_in_cm_per_ns_is_the_decimal_value() {
        assert_eq!(SPEED_OF_LIGHT_CM_PER_NS, 29.979_245_8);
    }

    #[test]
    fn paper_constants() {
        let d = Diffusion::new(&Preset::Paper.setup().medium).unwrap();
        assert!((d.d_cm - 1.0 / 3.15).abs() < 1e-15);
        assert!((d.c_cm_per_ps - 0.029_979_245_8 / 1.4).abs() < 1e-15);
        // Peak from the quadratic, checked against a dense scan of ln T.
        let scan = (1..100_000)
            .map(|i| i as f64 * 0.01)
            .max_by(|a, b| {
                d.log_temporal_density(*a)
                    .total_cmp(&d.log_temporal_density(*b))
            })
            .unwrap();
        assert!(
            (d.peak_time_ps() - scan).abs() < 0.011,
            "{} {scan}",
            d.peak_time_ps()
        );
    }

    #[test]
    fn interval_fraction_sums_to_one_and_is_symmetric() {
        let s = 0.7;
        let total: f64 = (-40..40)
            .map(|i| gaussian_interval_fraction(i as f64 * 0.25, (i + 1) as f64 * 0.25, s))
            .sum();
        assert!((total - 1.0).abs() < 1e-14);
        let a = gaussian_interval_fraction(2.0, 3.0, s);
        let b = gaussian_interval_fraction(-3.0, -2.0, s);
        assert_eq!(a, b);
        // Deep tail keeps relative precision instead of cancelling to 0.
        let tail = gaussian_interval_fraction(10.0, 11.0, 1.0);
        let expected = 0.5 * (libm::erfc(10.0) - libm::erfc(11.0));
        assert!(tail > 0.0 && ((tail - expected) / expected).abs() < 1e-12);
    }
}
