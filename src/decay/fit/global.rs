//! The global fit (FLIMfit's global analysis): lifetimes shared by every
//! fitted pixel, amplitudes and background per pixel, the IRF's
//! parameters held at the summed decay's fit. Variable projection: for
//! given lifetimes each pixel's linear parameters are fitted on their
//! own; the lifetimes then take a Levenberg-Marquardt step on the summed
//! objective, whose gradient is the sum of the pixels' (the pixels'
//! parameters at their optimum) and whose curvature is the pixels'
//! lifetime curvature less what their amplitudes explain (the Schur
//! complement).

use rayon::prelude::*;

use super::model::DecayModel;
use super::optimise::{Fitted, Objective, fit, inverse, solve};

/// The global fit's pixels and what it did, in words.
pub struct GlobalFit {
    /// Each pixel's fit (`None` below the threshold), lifetimes shared.
    pub fits: Vec<Option<Fitted>>,
    /// The shared lifetimes, iterations and convergence.
    pub note: String,
}

/// The most steps of the shared lifetimes.
const MAX_OUTER: usize = 60;

/// Fits the decays (pixels x the model's bins, in `decays`) with the
/// lifetimes shared by every pixel of at least `min_photons`, starting
/// from `start` (the summed decay's parameters).
pub fn fit_global(
    model: &DecayModel,
    decays: &[f64],
    photons: &[f64],
    min_photons: f64,
    start: &[f64],
    bounds: &[(f64, f64)],
    objective: Objective,
) -> GlobalFit {
    let n = model.bins;
    let np = model.parameters();
    let k = model.components;
    let bg = model.background();
    let fitted: Vec<usize> = (0..photons.len())
        .filter(|&p| photons[p] >= min_photons)
        .collect();
    let mut free = vec![false; np];
    for c in 0..k {
        free[2 * c] = true;
    }
    free[bg] = true;
    let summed_photons: f64 = (0..k).map(|c| start[2 * c]).sum::<f64>() + start[bg] * n as f64;
    let params: Vec<Vec<f64>> = fitted
        .iter()
        .map(|&p| {
            let scale = photons[p] / summed_photons.max(1.0);
            let mut s = start.to_vec();
            for c in 0..k {
                s[2 * c] *= scale;
            }
            s[bg] *= scale;
            s
        })
        .collect();
    let taus_of = |p: &[f64]| -> Vec<f64> { (0..k).map(|c| p[2 * c + 1]).collect() };
    let mut taus = taus_of(start);
    // Every pixel's linear fit at `taus`, with the summed objective, its
    // gradient by the lifetimes and their reduced curvature.
    let inner = |taus: &[f64], params: &[Vec<f64>]| {
        let results: Vec<(Fitted, Vec<f64>, Vec<f64>)> = fitted
            .par_iter()
            .zip(params.par_iter())
            .map(|(&p, s)| {
                let y = &decays[p * n..(p + 1) * n];
                let mut s = s.clone();
                for c in 0..k {
                    s[2 * c + 1] = taus[c];
                }
                let f = fit(model, y, &s, &free, bounds, objective);
                let (g, r) = reduced(model, y, &f.params, objective);
                (f, g, r)
            })
            .collect();
        let total: f64 = results.iter().map(|(f, _, _)| f.objective).sum();
        let mut grad = vec![0.0; k];
        let mut curv = vec![0.0; k * k];
        for (_, g, r) in &results {
            grad.iter_mut().zip(g).for_each(|(a, b)| *a += b);
            curv.iter_mut().zip(r).for_each(|(a, b)| *a += b);
        }
        (results, total, grad, curv)
    };
    let (mut results, mut total, mut grad, mut curv) = inner(&taus, &params);
    let mut lambda = 1e-3;
    let (mut iterations, mut converged) = (0, false);
    while iterations < MAX_OUTER && !fitted.is_empty() {
        iterations += 1;
        let mut stepped = false;
        while lambda < 1e12 {
            let mut a = curv.clone();
            for q in 0..k {
                a[q * k + q] += lambda * curv[q * k + q].max(1e-300);
            }
            let Some(delta) = solve(&mut a, &grad.iter().map(|g| -g).collect::<Vec<_>>(), k) else {
                lambda *= 10.0;
                continue;
            };
            let trial: Vec<f64> = (0..k)
                .map(|c| {
                    let (lo, hi) = bounds[2 * c + 1];
                    (taus[c] + delta[c]).clamp(lo, hi)
                })
                .collect();
            let kept: Vec<Vec<f64>> = results.iter().map(|(f, _, _)| f.params.clone()).collect();
            let (r2, t2, g2, c2) = inner(&trial, &kept);
            if t2 <= total {
                let change = total - t2;
                (results, total, grad, curv) = (r2, t2, g2, c2);
                taus = trial;
                lambda = (lambda / 10.0).max(1e-12);
                stepped = true;
                converged = change <= 1e-10 * (1.0 + total.abs());
                break;
            }
            lambda *= 10.0;
        }
        if !stepped {
            converged = true;
        }
        if converged {
            break;
        }
    }
    // The shared lifetimes' standard errors from the reduced curvature.
    let errors: Vec<f64> = match inverse(&curv, k) {
        Some(inv) => (0..k)
            .map(|c| (2.0 * inv[c * k + c]).max(0.0).sqrt())
            .collect(),
        None => vec![f64::NAN; k],
    };
    let mut fits: Vec<Option<Fitted>> = vec![None; photons.len()];
    for (&p, (mut f, _, _)) in fitted.iter().zip(results) {
        for (c, e) in errors.iter().enumerate() {
            f.errors[2 * c + 1] = *e;
        }
        f.converged &= converged;
        fits[p] = Some(f);
    }
    let shared: Vec<String> = taus
        .iter()
        .zip(&errors)
        .enumerate()
        .map(|(c, (t, e))| format!("tau{} {t:.1} +- {e:.1} ps", c + 1))
        .collect();
    GlobalFit {
        fits,
        note: format!(
            "global fit: lifetimes shared by {} pixels ({}), amplitudes and background per pixel, the IRF held at the summed decay's; {iterations} steps, {}",
            fitted.len(),
            shared.join(", "),
            if converged {
                "converged"
            } else {
                "not converged (every pixel masked)"
            }
        ),
    }
}

/// One pixel's gradient of the objective by the lifetimes and their
/// curvature less what the linear parameters explain, at parameters `p`
/// (the linear ones at their optimum).
fn reduced(model: &DecayModel, y: &[f64], p: &[f64], objective: Objective) -> (Vec<f64>, Vec<f64>) {
    let n = model.bins;
    let np = model.parameters();
    let k = model.components;
    let mut mu = vec![0.0; n];
    let mut jac = vec![0.0; n * np];
    model.evaluate(p, &mut mu, Some(&mut jac));
    let lin: Vec<usize> = (0..k).map(|c| 2 * c).chain([model.background()]).collect();
    let tau: Vec<usize> = (0..k).map(|c| 2 * c + 1).collect();
    let (nl, nt) = (lin.len(), tau.len());
    let mut g = vec![0.0; nt];
    let mut ctt = vec![0.0; nt * nt];
    let mut cta = vec![0.0; nt * nl];
    let mut caa = vec![0.0; nl * nl];
    for i in 0..n {
        let (rw, w) = match objective {
            Objective::Poisson => {
                let m = mu[i].max(1e-12);
                (2.0 * (1.0 - y[i] / m), 2.0 / m)
            }
            Objective::LeastSquares => {
                let v = y[i].max(1.0);
                (-2.0 * (y[i] - mu[i]) / v, 2.0 / v)
            }
        };
        let row = &jac[i * np..(i + 1) * np];
        for (a, &qa) in tau.iter().enumerate() {
            g[a] += rw * row[qa];
            for (b, &qb) in tau.iter().enumerate() {
                ctt[a * nt + b] += w * row[qa] * row[qb];
            }
            for (b, &qb) in lin.iter().enumerate() {
                cta[a * nl + b] += w * row[qa] * row[qb];
            }
        }
        for (a, &qa) in lin.iter().enumerate() {
            for (b, &qb) in lin.iter().enumerate() {
                caa[a * nl + b] += w * row[qa] * row[qb];
            }
        }
    }
    // A linear parameter held at its bound (0 photons) is not free: a
    // small ridge keeps the block invertible without moving the rest.
    for a in 0..nl {
        caa[a * nl + a] += 1e-9 * (1.0 + caa[a * nl + a]);
    }
    if let Some(inv) = inverse(&caa, nl) {
        for a in 0..nt {
            for b in 0..nt {
                let mut s = 0.0;
                for i in 0..nl {
                    for j in 0..nl {
                        s += cta[a * nl + i] * inv[i * nl + j] * cta[b * nl + j];
                    }
                }
                ctt[a * nt + b] -= s;
            }
        }
    }
    (g, ctt)
}
