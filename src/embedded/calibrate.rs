//! Self-calibration when nothing else was recorded: the time zero (the
//! pulse's entry into the front slab on the cube's clock) and the slabs'
//! reduced scattering, fitted to the cube's own time profile summed over
//! its used pixels.
//!
//! The model of that profile is the light crossing both slabs, summed over
//! the whole face: the front slab's transmitted flux convolved with the
//! back slab's (and the instrument's response), integrated over each bin,
//! times an amplitude, plus a constant background; amplitude and
//! background are solved for in closed form (weighted least squares, the
//! weights the measured variance) at each trial. The trials scan the
//! scattering on a log grid (both slabs scaled alike; absorption, index
//! and thicknesses held as stated) and the time zero on a grid of a fifth
//! of a bin, then refine both by parabolas; standard errors from the
//! curvature of the weighted residual sum, scaled by its reduced value.
//! The light lost off the camera's face grows with time (the back slab's
//! spread widens): the model keeps the share a field of the camera's size
//! catches from sources spread evenly over it (the object is taken to lie
//! within the field; its shape is not modelled).

use scatterscope_physics::{Diffusion, IrfTable};
use serde::Serialize;

use super::geometry::Geometry;

/// Scattering trials per factor of 2, and the range scanned (factors of
/// the stated value).
const SCALES_PER_OCTAVE: f64 = 6.0;
const SCALE_RANGE: (f64, f64) = (0.125, 4.0);

/// The fitted time zero and scattering.
#[derive(Debug, Clone, Serialize)]
pub struct Calibration {
    /// Time zero on the cube's clock (ps from bin 0's start) and its
    /// standard error.
    pub time_zero_ps: (f64, f64),
    /// Reduced scattering of the front and back slabs (1/cm) and the
    /// relative standard error of their common factor.
    pub mu_s_reduced_per_cm: (f64, f64, f64),
    /// Reduced chi-square of the summed profile's fit.
    pub reduced_chi2: f64,
    /// Whether the scattering was fitted (else held as stated).
    pub scattering_fitted: bool,
}

/// Fits the time zero (and, when `fit_scattering`, a common factor on both
/// slabs' reduced scattering) to `profile` (summed counts per bin, bins of
/// `bin_ps` from 0) with per-bin `variance`.
pub fn fit(
    geometry: &Geometry,
    field_cm: (f64, f64),
    profile: &[f64],
    variance: &[f64],
    bin_ps: f64,
    fit_scattering: bool,
) -> Result<Calibration, String> {
    let weights: Vec<f64> = variance.iter().map(|v| 1.0 / v.max(1.0)).collect();
    let scales: Vec<f64> = if fit_scattering {
        let n = ((SCALE_RANGE.1 / SCALE_RANGE.0).log2() * SCALES_PER_OCTAVE).round() as usize;
        (0..=n)
            .map(|i| SCALE_RANGE.0 * 2f64.powf(i as f64 / SCALES_PER_OCTAVE))
            .collect()
    } else {
        vec![1.0]
    };
    let mut best: Option<(f64, f64, f64)> = None; // (chi2, scale, t0)
    let mut per_scale = Vec::new();
    for &s in &scales {
        let arrival = arrival(geometry, field_cm, s, bin_ps)?;
        let (chi2, t0) = scan_time_zero(&arrival, profile, &weights, bin_ps);
        per_scale.push((s, chi2, t0));
        if best.is_none_or(|b| chi2 < b.0) {
            best = Some((chi2, s, t0));
        }
    }
    let (_, mut scale, _) = best.expect("at least one scale");
    let mut scale_se = 0.0;
    if fit_scattering {
        // Parabola through the best and its neighbours in log scale.
        let i = per_scale
            .iter()
            .position(|p| p.0 == scale)
            .expect("present");
        if i > 0 && i + 1 < per_scale.len() {
            let (l, c, r) = (per_scale[i - 1].1, per_scale[i].1, per_scale[i + 1].1);
            let h = 1.0 / SCALES_PER_OCTAVE * std::f64::consts::LN_2;
            let curv = (l - 2.0 * c + r) / (h * h);
            let shift = if curv > 0.0 {
                0.5 * h * (l - r) / (l - 2.0 * c + r)
            } else {
                0.0
            };
            scale *= shift.exp();
            scale_se = if curv > 0.0 {
                (2.0 / curv).sqrt()
            } else {
                f64::INFINITY
            };
        } else {
            scale_se = f64::INFINITY;
        }
    }
    let best = arrival(geometry, field_cm, scale, bin_ps)?;
    let (chi2, t0) = scan_time_zero(&best, profile, &weights, bin_ps);
    let h = bin_ps / 5.0;
    let at = |t: f64| weighted_fit(&best, profile, &weights, bin_ps, t).0;
    let curv = (at(t0 - h) - 2.0 * chi2 + at(t0 + h)) / (h * h);
    let dof = (profile.len() as f64 - 4.0).max(1.0);
    let reduced = chi2 / dof;
    let mut t0_se = if curv > 0.0 {
        (2.0 * reduced.max(1.0) / curv).sqrt()
    } else {
        f64::INFINITY
    };
    if fit_scattering {
        // Time zero and scattering trade off: both errors from the 2 x 2
        // curvature (time, log scattering) of the residual sum.
        let k = std::f64::consts::LN_2 / SCALES_PER_OCTAVE;
        let below = arrival(geometry, field_cm, scale * (-k).exp(), bin_ps)?;
        let above = arrival(geometry, field_cm, scale * k.exp(), bin_ps)?;
        let f = |table: &IrfTable, dt: f64| {
            weighted_fit(table, profile, &weights, bin_ps, t0 + dt * h).0
        };
        let h_tt = curv;
        let h_ss = (f(&above, 0.0) - 2.0 * chi2 + f(&below, 0.0)) / (k * k);
        let h_ts =
            (f(&above, 1.0) - f(&below, 1.0) - f(&above, -1.0) + f(&below, -1.0)) / (4.0 * h * k);
        let det = h_tt * h_ss - h_ts * h_ts;
        let (var_t, var_s) = if det > 0.0 && h_tt > 0.0 {
            (2.0 * h_ss / det, 2.0 * h_tt / det)
        } else {
            (f64::INFINITY, f64::INFINITY)
        };
        t0_se = (var_t * reduced.max(1.0)).sqrt();
        scale_se = var_s.sqrt();
    }
    Ok(Calibration {
        time_zero_ps: (t0, t0_se),
        mu_s_reduced_per_cm: (
            geometry.front.mu_s_per_cm * (1.0 - geometry.front.g) * scale,
            geometry.back.mu_s_per_cm * (1.0 - geometry.back.g) * scale,
            scale_se * reduced.max(1.0).sqrt(),
        ),
        reduced_chi2: reduced,
        scattering_fitted: fit_scattering,
    })
}

/// The geometry with both slabs' scattering times `scale`.
pub fn scaled(geometry: &Geometry, scale: f64) -> Geometry {
    let mut g = geometry.clone();
    g.front.mu_s_per_cm *= scale;
    g.back.mu_s_per_cm *= scale;
    g
}

/// The arrival density on the camera, summed over it: the front profile
/// (with the instrument) convolved with the back slab's flux times the
/// share of that flux the camera's `field_cm` (x, y) catches after each
/// time in the back slab, on the profile's grid.
fn arrival(
    geometry: &Geometry,
    field_cm: (f64, f64),
    scale: f64,
    bin_ps: f64,
) -> Result<IrfTable, String> {
    let g = scaled(geometry, scale);
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
