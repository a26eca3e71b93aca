//! One decay's fit: Levenberg-Marquardt on the Poisson deviance (maximum
//! likelihood; its curvature the Fisher information, as iteratively
//! reweighted least squares) or on Neyman's weighted squares (weights one
//! over the counts, at least 1), within bounds, some parameters held.
//! Measured hot path: a few parameters per pixel, tens of thousands of
//! pixels, so the small linear algebra is written out here.

use super::model::DecayModel;

/// What a fit minimises.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Objective {
    /// Poisson maximum likelihood: the deviance `2 sum (mu - y + y ln(y /
    /// mu))`.
    Poisson,
    /// Weighted least squares: `sum (y - mu)^2 / max(y, 1)`.
    LeastSquares,
}

/// The most iterations one fit takes.
pub const MAX_ITERATIONS: usize = 200;

/// A decay's fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Fitted {
    /// The parameters (the model's layout).
    pub params: Vec<f64>,
    /// Poisson deviance of the data under the fit.
    pub deviance: f64,
    /// The objective's value.
    pub objective: f64,
    /// Pearson's chi-squared (`sum (y - mu)^2 / mu`, or the least squares'
    /// own weights) over the degrees of freedom.
    pub reduced_chi2: f64,
    /// Standard error of each parameter from the inverse curvature (the
    /// Cramer-Rao bound at the fit for maximum likelihood); 0 for held
    /// ones, NaN where the curvature is singular.
    pub errors: Vec<f64>,
    /// Iterations taken.
    pub iterations: usize,
    /// Whether the objective stopped changing before the cap.
    pub converged: bool,
}

/// Fits `model` to `y` (photons per bin of its window) from `start`,
/// parameters with `free[q]` false held, each kept within `bounds`.
pub fn fit(
    model: &DecayModel,
    y: &[f64],
    start: &[f64],
    free: &[bool],
    bounds: &[(f64, f64)],
    objective: Objective,
) -> Fitted {
    let n = model.bins;
    let np = model.parameters();
    let idx: Vec<usize> = (0..np).filter(|&q| free[q]).collect();
    let nf = idx.len();
    let clamp = |p: &mut [f64]| {
        for (v, (lo, hi)) in p.iter_mut().zip(bounds) {
            *v = v.clamp(*lo, *hi);
        }
    };
    let mut p = start.to_vec();
    clamp(&mut p);
    let mut mu = vec![0.0; n];
    let mut jac = vec![0.0; n * np];
    let mut trial_mu = vec![0.0; n];
    let value = |mu: &[f64]| objective_value(objective, y, mu);
    let mut lambda = 1e-3;
    let mut converged = false;
    let mut iterations = 0;
    let mut grad = vec![0.0; nf];
    let mut curv = vec![0.0; nf * nf];
    model.evaluate(&p, &mut mu, Some(&mut jac));
    let mut f = value(&mu);
    while iterations < MAX_ITERATIONS {
        iterations += 1;
        gradient_and_curvature(objective, y, &mu, &jac, np, &idx, &mut grad, &mut curv);
        // Parameters at a bound that the gradient pushes outward stay
        // there this step (the active set); the rest move.
        let moving: Vec<usize> = (0..nf)
            .filter(|&a| {
                let q = idx[a];
                let (lo, hi) = bounds[q];
                !((p[q] <= lo && grad[a] > 0.0) || (p[q] >= hi && grad[a] < 0.0))
            })
            .collect();
        let nm = moving.len();
        if nm == 0 {
            converged = true;
            break;
        }
        let mut stepped = false;
        while lambda < 1e12 {
            let mut a = vec![0.0; nm * nm];
            for (i, &ai) in moving.iter().enumerate() {
                for (j, &aj) in moving.iter().enumerate() {
                    a[i * nm + j] = curv[ai * nf + aj];
                }
                a[i * nm + i] += lambda * curv[ai * nf + ai].max(1e-300);
            }
            let rhs: Vec<f64> = moving.iter().map(|&ai| -grad[ai]).collect();
            let Some(delta) = solve(&mut a, &rhs, nm) else {
                lambda *= 10.0;
                continue;
            };
            let mut trial = p.clone();
            for (k, &ai) in moving.iter().enumerate() {
                trial[idx[ai]] += delta[k];
            }
            clamp(&mut trial);
            model.evaluate(&trial, &mut trial_mu, None);
            let ft = value(&trial_mu);
            if ft <= f {
                let change = f - ft;
                let moved = trial
                    .iter()
                    .zip(&p)
                    .all(|(a, b)| (a - b).abs() <= 1e-9 * (1.0 + b.abs()));
                p = trial;
                f = ft;
                lambda = (lambda / 10.0).max(1e-12);
                stepped = true;
                if change <= 1e-10 * (1.0 + f.abs()) || moved {
                    converged = true;
                }
                break;
            }
            lambda *= 10.0;
        }
        model.evaluate(&p, &mut mu, Some(&mut jac));
        if !stepped {
            // No step lowers the objective: a minimum within rounding.
            converged = true;
        }
        if converged {
            break;
        }
    }
    gradient_and_curvature(objective, y, &mu, &jac, np, &idx, &mut grad, &mut curv);
    let errors = standard_errors(&curv, nf, &idx, np);
    let dof = (n as f64 - nf as f64).max(1.0);
    let chi2: f64 = y
        .iter()
        .zip(&mu)
        .map(|(&y, &m)| {
            let w = match objective {
                Objective::Poisson => m.max(1e-12),
                Objective::LeastSquares => y.max(1.0),
            };
            (y - m) * (y - m) / w
        })
        .sum();
    Fitted {
        deviance: objective_value(Objective::Poisson, y, &mu),
        objective: f,
        reduced_chi2: chi2 / dof,
        params: p,
        errors,
        iterations,
        converged,
    }
}

/// The objective's value for data `y` and model `mu`.
pub fn objective_value(objective: Objective, y: &[f64], mu: &[f64]) -> f64 {
    match objective {
        Objective::Poisson => y
            .iter()
            .zip(mu)
            .map(|(&y, &m)| {
                if m <= 0.0 {
                    if y > 0.0 { f64::INFINITY } else { 0.0 }
                } else if y > 0.0 {
                    2.0 * (m - y + y * (y / m).ln())
                } else {
                    2.0 * m
                }
            })
            .sum(),
        Objective::LeastSquares => y
            .iter()
            .zip(mu)
            .map(|(&y, &m)| (y - m) * (y - m) / y.max(1.0))
            .sum(),
    }
}

/// The objective's gradient over the free parameters `idx` and its
/// Gauss-Newton curvature (twice the Fisher information for the deviance).
#[allow(clippy::too_many_arguments)]
fn gradient_and_curvature(
    objective: Objective,
    y: &[f64],
    mu: &[f64],
    jac: &[f64],
    np: usize,
    idx: &[usize],
    grad: &mut [f64],
    curv: &mut [f64],
) {
    let nf = idx.len();
    grad.iter_mut().for_each(|g| *g = 0.0);
    curv.iter_mut().for_each(|c| *c = 0.0);
    for (i, (&yi, &mi)) in y.iter().zip(mu).enumerate() {
        let (resid_w, w) = match objective {
            Objective::Poisson => {
                let m = mi.max(1e-12);
                (2.0 * (1.0 - yi / m), 2.0 / m)
            }
            Objective::LeastSquares => {
                let v = yi.max(1.0);
                (-2.0 * (yi - mi) / v, 2.0 / v)
            }
        };
        let row = &jac[i * np..(i + 1) * np];
        for (a, &qa) in idx.iter().enumerate() {
            let ja = row[qa];
            if ja == 0.0 {
                continue;
            }
            grad[a] += resid_w * ja;
            let wa = w * ja;
            for (b, &qb) in idx.iter().enumerate().skip(a) {
                curv[a * nf + b] += wa * row[qb];
            }
        }
    }
    for a in 0..nf {
        for b in 0..a {
            curv[a * nf + b] = curv[b * nf + a];
        }
    }
}

/// Standard errors from the curvature `curv` of the free parameters:
/// `sqrt(2 (curv^-1)_qq)` (the curvature is twice the information).
fn standard_errors(curv: &[f64], nf: usize, idx: &[usize], np: usize) -> Vec<f64> {
    let mut errors = vec![0.0; np];
    let Some(inv) = inverse(curv, nf) else {
        for &q in idx {
            errors[q] = f64::NAN;
        }
        return errors;
    };
    for (k, &q) in idx.iter().enumerate() {
        let v = 2.0 * inv[k * nf + k];
        errors[q] = if v >= 0.0 { v.sqrt() } else { f64::NAN };
    }
    errors
}

/// Solves `a x = b` (`a` symmetric, `n` x `n`, overwritten) by Cholesky;
/// `None` when `a` is not positive definite.
pub(crate) fn solve(a: &mut [f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    cholesky(a, n)?;
    let mut x = b.to_vec();
    for i in 0..n {
        let mut s = x[i];
        for k in 0..i {
            s -= a[i * n + k] * x[k];
        }
        x[i] = s / a[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = x[i];
        for k in i + 1..n {
            s -= a[k * n + i] * x[k];
        }
        x[i] = s / a[i * n + i];
    }
    Some(x)
}

/// The lower Cholesky factor of `a`, in place; `None` unless positive
/// definite.
fn cholesky(a: &mut [f64], n: usize) -> Option<()> {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / d;
        }
    }
    Some(())
}

/// The inverse of the symmetric positive definite `a` (`n` x `n`).
pub fn inverse(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut inverse = vec![0.0; n * n];
    for c in 0..n {
        let mut e = vec![0.0; n];
        e[c] = 1.0;
        let x = solve(&mut a.to_vec(), &e, n)?;
        for r in 0..n {
            inverse[r * n + c] = x[r];
        }
    }
    Some(inverse)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_and_inverts() {
        let a = [4.0, 2.0, 0.6, 2.0, 5.0, 1.0, 0.6, 1.0, 3.0];
        let x = solve(&mut a.to_vec(), &[1.0, 2.0, 3.0], 3).unwrap();
        for r in 0..3 {
            let s: f64 = (0..3).map(|c| a[r * 3 + c] * x[c]).sum();
            assert!((s - [1.0, 2.0, 3.0][r]).abs() < 1e-12);
        }
        let inv = inverse(&a, 3).unwrap();
        for r in 0..3 {
            for c in 0..3 {
                let s: f64 = (0..3).map(|k| a[r * 3 + k] * inv[k * 3 + c]).sum();
                assert!((s - f64::from(u8::from(r == c))).abs() < 1e-12);
            }
        }
        assert!(solve(&mut [1.0, 2.0, 2.0, 1.0], &[1.0, 1.0], 2).is_none());
    }
}
