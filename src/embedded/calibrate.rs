//! Self-calibration when nothing else was recorded: the time zero (the
//! pulse's entry into the front slab on the cube's clock) and the slabs'
//! reduced scattering and absorption, fitted to the cube's own time
//! profile summed over its used pixels.
//!
//! The model of that profile is the light crossing both slabs, summed over
//! the whole face: the front slab's transmitted flux convolved with the
//! back slab's (and the instrument's response), integrated over each bin,
//! times an amplitude, plus a constant background; amplitude and
//! background are solved for in closed form (weighted least squares, the
//! weights the measured variance) at each trial. The trials scan the
//! fitted media factor (scattering or absorption, not both: one factor on
//! both slabs; the index and thicknesses held as stated) on a log grid,
//! and the time zero on a grid of a fifth of a bin, each refined by a
//! parabola; standard errors from the inverse curvature of the weighted
//! residual sum over the fitted quantities, scaled by its reduced value.
//! The light lost off the camera's face grows with time (the back slab's
//! spread widens): the model keeps the share a field of the camera's size
//! catches from sources spread evenly over it (the object is taken to lie
//! within the field; its shape is not modelled).

use scatterscope_physics::{Diffusion, IrfTable};
use serde::Serialize;

use super::geometry::Geometry;

/// Trials per factor of 2 of a fitted medium factor, and the range
/// scanned (factors of the stated value).
const SCALES_PER_OCTAVE: f64 = 6.0;
const SCALE_RANGE: (f64, f64) = (0.125, 4.0);
/// Why scattering and absorption are not fitted together.
pub const JOINT_REFUSED: &str = "scattering and absorption fitted together trade off with the time zero along a valley the summed time profile does not resolve (on a simulated cube, starts from 0.5x and 2x the truth ended 140 ps apart in time zero at the same chi-square): fit one of them";

/// Which media factors are fitted beside the time zero (each one factor
/// on both slabs' value).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Free {
    /// Reduced scattering.
    pub scattering: bool,
    /// Absorption.
    pub absorption: bool,
}

/// The fitted time zero and media.
#[derive(Debug, Clone, Serialize)]
pub struct Calibration {
    /// Time zero on the cube's clock (ps from bin 0's start) and its
    /// standard error.
    pub time_zero_ps: (f64, f64),
    /// Reduced scattering of the front and back slabs (1/cm) and the
    /// relative standard error of their common factor (0 when held).
    pub mu_s_reduced_per_cm: (f64, f64, f64),
    /// Absorption of the front and back slabs (1/cm) and the relative
    /// standard error of their common factor (0 when held).
    pub mu_a_per_cm: (f64, f64, f64),
    /// Reduced chi-square of the summed profile's fit.
    pub reduced_chi2: f64,
    /// Whether the scattering was fitted (else held as stated).
    pub scattering_fitted: bool,
    /// Whether the absorption was fitted (else held as stated).
    pub absorption_fitted: bool,
    /// The factors on the stated scattering and absorption
    /// ([`scaled`] makes the fitted geometry).
    pub factors: [f64; 2],
}

/// Fits the time zero (and the `free` media factors) to `profile` (summed
/// counts per bin, bins of `bin_ps` from 0) with per-bin `variance`, for
/// a camera whose field is `field_cm` (x, y).
pub fn fit(
    geometry: &Geometry,
    field_cm: (f64, f64),
    profile: &[f64],
    variance: &[f64],
    bin_ps: f64,
    free: Free,
) -> Result<Calibration, String> {
    let weights: Vec<f64> = variance.iter().map(|v| 1.0 / v.max(1.0)).collect();
    let chi2_at = |factors: [f64; 2]| -> Result<(f64, f64), String> {
        let table = arrival(geometry, field_cm, factors, bin_ps)?;
        Ok(scan_time_zero(&table, profile, &weights, bin_ps))
    };
    let fitted = [free.scattering, free.absorption];
    let k = std::f64::consts::LN_2 / SCALES_PER_OCTAVE;
    let n = ((SCALE_RANGE.1 / SCALE_RANGE.0).log2() * SCALES_PER_OCTAVE).round() as usize;
    let grid: Vec<f64> = (0..=n)
        .map(|i| SCALE_RANGE.0 * 2f64.powf(i as f64 / SCALES_PER_OCTAVE))
        .collect();
    if fitted.iter().all(|&f| f) {
        return Err(JOINT_REFUSED.into());
    }
    let mut factors = [1.0f64, 1.0];
    for d in (0..2).filter(|&d| fitted[d]) {
        let mut trials = Vec::with_capacity(grid.len());
        for &g in &grid {
            let mut x = factors;
            x[d] = g;
            trials.push(chi2_at(x)?.0);
        }
        let i = (0..trials.len())
            .min_by(|&a, &b| trials[a].total_cmp(&trials[b]))
            .expect("trials");
        // A parabola through the best and its neighbours, in log scale.
        let shift = if i > 0 && i + 1 < trials.len() {
            let (l, c, r) = (trials[i - 1], trials[i], trials[i + 1]);
            let den = l - 2.0 * c + r;
            if den > 0.0 {
                0.5 * k * (l - r) / den
            } else {
                0.0
            }
        } else {
            0.0
        };
        factors[d] = grid[i] * shift.exp();
    }
    let centre = arrival(geometry, field_cm, factors, bin_ps)?;
    let (chi2, t0) = scan_time_zero(&centre, profile, &weights, bin_ps);
    let free_count = fitted.iter().filter(|&&f| f).count() as f64;
    let dof = (profile.len() as f64 - 3.0 - free_count).max(1.0);
    let reduced = chi2 / dof;
    // The curvature of the residual sum over the time zero (ps) and the
    // fitted factors' logarithms; the errors from its inverse (they trade
    // off: the time zero's is the marginal one).
    let h = bin_ps / 5.0;
    let dims: Vec<usize> = (0..2).filter(|&d| fitted[d]).collect();
    // The residual sum over (time zero, the fitted factors' logarithms).
    let residual = |q: &[f64]| {
        let mut x = factors;
        for (&d, l) in dims.iter().zip(&q[1..]) {
            x[d] *= l.exp();
        }
        match arrival(geometry, field_cm, x, bin_ps) {
            Ok(table) => weighted_fit(&table, profile, &weights, bin_ps, t0 + q[0]).0,
            Err(_) => f64::NAN,
        }
    };
    let origin = vec![0.0; 1 + dims.len()];
    let mut steps = vec![k; 1 + dims.len()];
    steps[0] = h;
    let hess = crate::calibrate::hessian::numerical_hessian(&residual, &origin, &steps);
    let inverse = crate::calibrate::hessian::invert(&hess);
    let variances: Vec<f64> = (0..origin.len())
        .map(|i| inverse.as_ref().map_or(f64::INFINITY, |m| m[i][i]))
        .collect();
    let se = |v: f64| {
        if v > 0.0 && v.is_finite() {
            (2.0 * v * reduced.max(1.0)).sqrt()
        } else {
            f64::INFINITY
        }
    };
    let factor_se = |d: usize| {
        dims.iter()
            .position(|&x| x == d)
            .map_or(0.0, |i| se(variances[i + 1]))
    };
    let g = scaled(geometry, factors);
    Ok(Calibration {
        time_zero_ps: (t0, se(variances[0])),
        mu_s_reduced_per_cm: (
            g.front.mu_s_per_cm * (1.0 - g.front.g),
            g.back.mu_s_per_cm * (1.0 - g.back.g),
            factor_se(0),
        ),
        mu_a_per_cm: (g.front.mu_a_per_cm, g.back.mu_a_per_cm, factor_se(1)),
        reduced_chi2: reduced,
        scattering_fitted: free.scattering,
        absorption_fitted: free.absorption,
        factors,
    })
}

/// The geometry with both slabs' scattering and absorption times
/// `factors`.
pub fn scaled(geometry: &Geometry, factors: [f64; 2]) -> Geometry {
    let mut g = geometry.clone();
    g.front.mu_s_per_cm *= factors[0];
    g.back.mu_s_per_cm *= factors[0];
    g.front.mu_a_per_cm *= factors[1];
    g.back.mu_a_per_cm *= factors[1];
    g
}

/// The arrival density on the camera, summed over it: the front profile
/// (with the instrument) convolved with the back slab's flux times the
/// share of that flux the camera's `field_cm` (x, y) catches after each
/// time in the back slab, on the profile's grid.
fn arrival(
    geometry: &Geometry,
    field_cm: (f64, f64),
    factors: [f64; 2],
    bin_ps: f64,
) -> Result<IrfTable, String> {
    let g = scaled(geometry, factors);
    let front = g.arrival_profile(bin_ps).map_err(|e| e.to_string())?;
    let step = front.bin_ps();
    let d = Diffusion::new(&g.back).map_err(|e| e.to_string())?;
    let back: Vec<f64> = super::geometry::flux_on(&d, step)
        .map_err(|e| e.to_string())?
        .into_iter()
        .enumerate()
        .map(|(j, f)| {
            let sigma = d.lateral_sigma_cm((j as f64 + 0.5) * step);
            f * caught(field_cm.0, sigma) * caught(field_cm.1, sigma)
        })
        .collect();
    let out = super::geometry::convolve(front.weights(), &back);
    IrfTable::new(step, front.start_ps(), out).map_err(|e| e.to_string())
}

/// The share of light from sources spread evenly over a field `width`
/// wide (one axis) that lands inside it after a Gaussian spread `sigma`:
/// `erf(L / (sqrt 2 s)) - sqrt(2 / pi) (s / L) (1 - exp(-L^2 / (2 s^2)))`.
/// The object is taken to lie within the camera's field.
fn caught(width: f64, sigma: f64) -> f64 {
    if sigma <= 0.0 {
        return 1.0;
    }
    let u = width / sigma;
    libm::erf(u / std::f64::consts::SQRT_2)
        - (2.0 / std::f64::consts::PI).sqrt() / u * (1.0 - (-0.5 * u * u).exp())
}

/// The best time zero on a grid of a fifth of a bin over every shift that
/// puts the light's peak inside the profile, refined by a parabola; and its
/// weighted residual sum.
fn scan_time_zero(arrival: &IrfTable, profile: &[f64], weights: &[f64], bin_ps: f64) -> (f64, f64) {
    let peak_at = super::peak(profile).0;
    let model_peak =
        arrival.start_ps() + arrival.bin_ps() * (super::peak(arrival.weights()).0 as f64 + 0.5);
    // The data's peak time less the model's, +- the whole window.
    let centre = (peak_at as f64 + 0.5) * bin_ps - model_peak;
    let span = profile.len() as f64 * bin_ps;
    let h = bin_ps / 5.0;
    let n = (span / h).ceil() as i64;
    let trials: Vec<(f64, f64)> = (-n..=n)
        .map(|i| {
            let t = centre + i as f64 * h;
            (t, weighted_fit(arrival, profile, weights, bin_ps, t).0)
        })
        .collect();
    let (i, &(t, c)) = trials
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.1.total_cmp(&b.1.1))
        .expect("trials");
    if i == 0 || i + 1 == trials.len() {
        return (c, t);
    }
    let (l, r) = (trials[i - 1].1, trials[i + 1].1);
    let den = l - 2.0 * c + r;
    let t = if den > 0.0 {
        t + 0.5 * h * (l - r) / den
    } else {
        t
    };
    (
        weighted_fit(arrival, profile, weights, bin_ps, t).0.min(c),
        t,
    )
}

/// Weighted residual sum, amplitude and background of the best
/// `amplitude * model + background` for time zero `t0`.
pub fn weighted_fit(
    arrival: &IrfTable,
    profile: &[f64],
    weights: &[f64],
    bin_ps: f64,
    t0: f64,
) -> (f64, f64, f64) {
    let model: Vec<f64> = (0..profile.len())
        .map(|k| {
            let a = k as f64 * bin_ps - t0;
            arrival.cdf(a + bin_ps) - arrival.cdf(a)
        })
        .collect();
    // Normal equations of two unknowns.
    let (mut s11, mut s12, mut s22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for ((m, y), w) in model.iter().zip(profile).zip(weights) {
        s11 += w * m * m;
        s12 += w * m;
        s22 += w;
        b1 += w * m * y;
        b2 += w * y;
    }
    let det = s11 * s22 - s12 * s12;
    let (a, c) = if det.abs() > 1e-300 {
        ((b1 * s22 - b2 * s12) / det, (s11 * b2 - s12 * b1) / det)
    } else {
        (0.0, b2 / s22.max(1e-300))
    };
    let chi2 = model
        .iter()
        .zip(profile)
        .zip(weights)
        .map(|((m, y), w)| w * (y - a * m - c).powi(2))
        .sum();
    (chi2, a, c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_caught_share_agrees_with_a_direct_integral() {
        // Midpoint rule over source positions and the normal cdf.
        let (width, sigma) = (4.48, 1.3);
        let n = 4000;
        let direct: f64 = (0..n)
            .map(|i| {
                let x = -width / 2.0 + (i as f64 + 0.5) * width / n as f64;
                let cdf = |z: f64| 0.5 * libm::erfc(-z / std::f64::consts::SQRT_2);
                cdf((width / 2.0 - x) / sigma) - cdf((-width / 2.0 - x) / sigma)
            })
            .sum::<f64>()
            / n as f64;
        assert!(
            (caught(width, sigma) - direct).abs() < 1e-6,
            "{} {direct}",
            caught(width, sigma)
        );
        assert_eq!(caught(width, 0.0), 1.0);
        assert!(caught(width, 100.0) < 0.05);
    }
}
