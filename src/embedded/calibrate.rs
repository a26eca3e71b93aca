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
//! What the sensor's edges and the object do to the summed profile is not
//! modelled (the light lost off a 32-pixel face grows with time).

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
        let arrival = arrival(geometry, s, bin_ps)?;
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
    let arrival = arrival(geometry, scale, bin_ps)?;
    let (chi2, t0) = scan_time_zero(&arrival, profile, &weights, bin_ps);
    let h = bin_ps / 5.0;
    let at = |t: f64| weighted_fit(&arrival, profile, &weights, bin_ps, t).0;
    let curv = (at(t0 - h) - 2.0 * chi2 + at(t0 + h)) / (h * h);
    let dof = (profile.len() as f64 - 4.0).max(1.0);
    let reduced = chi2 / dof;
    let t0_se = if curv > 0.0 {
        (2.0 * reduced.max(1.0) / curv).sqrt()
    } else {
        f64::INFINITY
    };
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

/// The arrival density at the face, summed over it: the front profile
/// (with the instrument) convolved with the back slab's flux, on the
/// profile's grid.
fn arrival(geometry: &Geometry, scale: f64, bin_ps: f64) -> Result<IrfTable, String> {
    let g = scaled(geometry, scale);
    let front = g.arrival_profile(bin_ps).map_err(|e| e.to_string())?;
    let step = front.bin_ps();
    let d = Diffusion::new(&g.back).map_err(|e| e.to_string())?;
    let back = super::geometry::flux_on(&d, step).map_err(|e| e.to_string())?;
    let out = super::geometry::convolve(front.weights(), &back);
    IrfTable::new(step, front.start_ps(), out).map_err(|e| e.to_string())
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
