//! Pieces every calibration fit shares: the Nelder-Mead search (argmin)
//! from a starting point with one step per coordinate, and the Pearson
//! chi-square of a fit.

use argmin::core::{CostFunction, Executor, State};
use argmin::solver::neldermead::NelderMead;

use super::CalibrateError;

/// The likelihood's spread across the simplex below which a search stops
/// (a change of 0.5 in the negative log-likelihood is one standard
/// error's worth).
pub const NLL_TOLERANCE: f64 = 1e-3;

/// Minimises `problem` by Nelder-Mead from `x0`, the first simplex being
/// `x0` and `x0` moved by `steps[j]` along each coordinate `j`, for at most
/// `max_iters` iterations; returns the best point, the problem back and
/// the cost evaluations it took. `what` names the fit in errors.
pub fn nelder_mead<P>(
    problem: P,
    x0: Vec<f64>,
    steps: &[f64],
    max_iters: u64,
    what: &str,
) -> Result<(Vec<f64>, P, u64), CalibrateError>
where
    P: CostFunction<Param = Vec<f64>, Output = f64>,
{
    let mut simplex = vec![x0.clone()];
    for (j, step) in steps.iter().enumerate() {
        let mut v = x0.clone();
        v[j] += step;
        simplex.push(v);
    }
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(NLL_TOLERANCE)
        .map_err(|e| CalibrateError::Invalid(e.to_string()))?;
    let res = Executor::new(problem, solver)
        .configure(|c| c.max_iters(max_iters))
        .run()
        .map_err(|e| CalibrateError::Invalid(e.to_string()))?;
    let evaluations = res.problem.counts.get("cost_count").copied().unwrap_or(0);
    let x = res
        .state()
        .get_best_param()
        .cloned()
        .ok_or_else(|| CalibrateError::Invalid(format!("{what} found no point")))?;
    let problem = res
        .problem
        .problem
        .expect("the executor returns its problem");
    Ok((x, problem, evaluations))
}

/// Pearson chi-square of `measured` counts against `fitted` means, over
/// the bins with a positive mean.
pub fn pearson_chi2(fitted: &[f64], measured: &[f64]) -> f64 {
    fitted
        .iter()
        .zip(measured)
        .filter(|(u, _)| **u > 0.0)
        .map(|(u, m)| (m - u) * (m - u) / u)
        .sum()
}
