//! Poisson Plug-and-Play ADMM (the paper's Algorithm 1).
//!
//! ```text
//! o_{i+1} = argmin_o L(o) + lambda_i/2 ||o - v_i + u_i||^2     (L-BFGS, warm start)
//! v_{i+1} = Denoiser_sigma(o_{i+1} + u_i),  sigma^2 = beta / lambda_i
//! u_{i+1} = u_i + o_{i+1} - v_{i+1}
//! lambda_{i+1} = lambda_i * lambda_step
//! ```
//!
//! Start: the paper starts from o = v = u = 0, where every `H o` sits in the
//! surrogate region of the logarithm and the first o-update is extremely
//! stiff (curvature 1/eps^2 = 1e20). We start from the flat object that
//! explains the total photon count, `o = v = sum(m) / (M N)`, `u = 0`.
//!
//! Prior step: the denoiser's output projected onto `v >= 0` (an object's
//! transmittance is never negative), so the prior is the denoiser plus the
//! physical constraint.
//!
//! Output: `v`, the iterate the prior has seen; at convergence `o = v`.
//!
//! Stopping: an iteration cap, primal and dual residual tolerances, and by
//! default a rule that needs no truth, built on the Poisson deviance `D(v)`
//! of the output iterate ([`super::discrepancy`]). As sigma keeps shrinking,
//! ADMM eventually fits noise and the image degrades; `D(v)` first falls
//! while the iterate gains detail the data supports, then levels off or
//! rises. The rule stops once `D(v)` has not decreased for `patience`
//! iterations and returns the iterate with the smallest `D(v)`. The
//! patience is long (30) because `D(v)` hovers within a few hundredths of a
//! percent for tens of iterations while the image still improves: with the
//! learned prior on the text scene, patience 3 returned iteration 11
//! (16.15 dB) and 30 returned iteration 60 (17.94 dB, the best by truth
//! 17.94 dB); on no built-in scene did a longer patience return a worse
//! iterate (BENCHMARKS.md). The trace
//! also records the deviance `E` that Poisson noise alone would produce;
//! stopping where `D` first reaches `E` (the classical discrepancy
//! principle) was measured too and stops too early on some scenes (0.7 dB
//! lost on the Siemens star). How close the rule comes to the best
//! iteration chosen with the truth is measured in BENCHMARKS.md.

use std::sync::Mutex;
use std::time::Instant;

use argmin::core::{CostFunction, Executor, Gradient, State};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::LBFGS;
use ndarray::{Array2, Array3, ArrayView2};

use super::discrepancy::ExpectedDeviance;
use super::likelihood::PoissonLikelihood;
use super::trace::{Trace, TraceRow};
use super::{
    ReconstructError, Reconstruction, finish, flat_level, no_photons, score, validate_counts,
};
use crate::denoise::{Denoiser, denoise_scaled};
use crate::forward::ForwardModel;

/// When ADMM stops, besides the iteration cap and residual tolerances.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum StopRule {
    /// Smallest Poisson deviance of the output, with patience (needs no truth).
    Deviance,
    /// Only the iteration cap and the residual tolerances.
    Iterations,
}

/// Parameters of Algorithm 1 and of its o-update.
#[derive(Debug, Clone, Copy)]
pub struct PnpOptions {
    /// Initial ADMM penalty lambda_0.
    pub lambda0: f64,
    /// Growth factor of lambda per iteration.
    pub lambda_step: f64,
    /// Regularisation weight beta (sigma^2 = beta / lambda).
    pub beta: f64,
    /// ADMM iteration cap.
    pub max_iters: usize,
    /// Stop when the primal residual ||o - v|| / sqrt(N) falls below this ...
    pub primal_tol: f64,
    /// ... and the dual residual lambda ||v - v_prev|| / sqrt(N) below this.
    pub dual_tol: f64,
    /// Data-driven stopping rule.
    pub stop: StopRule,
    /// Iterations without a deviance decrease before the rule stops.
    pub patience: usize,
    /// L-BFGS iteration cap per o-update.
    pub lbfgs_iters: u64,
    /// L-BFGS memory (stored correction pairs).
    pub lbfgs_memory: usize,
    /// L-BFGS gradient-norm tolerance.
    pub lbfgs_grad_tol: f64,
    /// Switch point of the surrogate logarithm (Eq. 16).
    pub eps: f64,
}

impl Default for PnpOptions {
    fn default() -> Self {
        Self {
            lambda0: 1.0,
            lambda_step: 1.1,
            beta: 0.25,
            max_iters: 100,
            primal_tol: 1e-4,
            dual_tol: 1e-4,
            stop: StopRule::Deviance,
            patience: 30,
            lbfgs_iters: 20,
            lbfgs_memory: 7,
            lbfgs_grad_tol: 1e-8,
            eps: 1e-10,
        }
    }
}

/// A point with its objective value and gradient.
type Evaluated = (Vec<f64>, f64, Vec<f64>);

/// The o-update objective `L(o) + lambda/2 ||o - z||^2`, evaluating value and
/// gradient together (argmin asks for them separately; the last point is
/// cached so each point costs one likelihood evaluation).
///
/// argmin runs its line search without an iteration cap, and More-Thuente
/// can cycle when the objective is very stiff (huge lambda): every
/// evaluation counts against `budget`, past which the o-update ends with the
/// best point it has evaluated.
struct OUpdate<'a> {
    likelihood: &'a PoissonLikelihood,
    z: Vec<f64>,
    lambda: f64,
    cache: Mutex<Option<Evaluated>>,
    /// Lowest objective evaluated and its point; outlives the solver run.
    best: &'a Mutex<Option<(f64, Vec<f64>)>>,
    evaluations: Mutex<u64>,
    budget: u64,
}

/// Calls of value or gradient allowed per o-update: L-BFGS asks for both
/// at 1-3 line-search points per iteration.
fn evaluation_budget(opts: &PnpOptions) -> u64 {
    20 * opts.lbfgs_iters + 20
}

/// Marker text of the error that ends an o-update whose budget is spent.
const BUDGET_SPENT: &str = "evaluation budget spent";

impl OUpdate<'_> {
    fn evaluate(&self, o: &[f64]) -> Result<(f64, Vec<f64>), argmin::core::Error> {
        {
            // Every call counts, cached or not: a line search that keeps
            // asking for the same point must end too.
            let mut n = self.evaluations.lock().expect("counter lock");
            if *n >= self.budget {
                return Err(argmin::core::Error::msg(BUDGET_SPENT));
            }
            *n += 1;
        }
        let mut cache = self.cache.lock().expect("cache lock");
        if let Some((p, v, g)) = cache.as_ref()
            && p.as_slice() == o
        {
            return Ok((*v, g.clone()));
        }
        let e = self.likelihood.evaluate(o);
        let mut value = e.value;
        let mut grad = e.gradient;
        for ((g, &oj), &zj) in grad.iter_mut().zip(o).zip(&self.z) {
            let d = oj - zj;
            value += 0.5 * self.lambda * d * d;
            *g += self.lambda * d;
        }
        *cache = Some((o.to_vec(), value, grad.clone()));
        let mut best = self.best.lock().expect("best lock");
        if value.is_finite() && best.as_ref().is_none_or(|(b, _)| value < *b) {
            *best = Some((value, o.to_vec()));
        }
        Ok((value, grad))
    }
}

impl CostFunction for OUpdate<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, p: &Self::Param) -> Result<f64, argmin::core::Error> {
        Ok(self.evaluate(p)?.0)
    }
}

impl Gradient for OUpdate<'_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    fn gradient(&self, p: &Self::Param) -> Result<Vec<f64>, argmin::core::Error> {
        Ok(self.evaluate(p)?.1)
    }
}

/// Runs Algorithm 1 on bins `bins` of `model` with `counts` (one image per
/// listed bin). `on_iter` sees every trace row as it is produced.
pub fn pnp_admm(
    model: &ForwardModel,
    counts: &Array3<f64>,
    bins: &[usize],
    denoiser: &dyn Denoiser,
    opts: &PnpOptions,
    truth: Option<ArrayView2<f64>>,
    mut on_iter: impl FnMut(&TraceRow),
) -> Result<Reconstruction, ReconstructError> {
    validate_counts(counts)?;
    if counts.shape()[0] != bins.len() {
        return Err(ReconstructError::Shape(format!(
            "{} count images for {} kernels",
            counts.shape()[0],
            bins.len()
        )));
    }
    let method = if bins.len() == 1 { "pnp-slice" } else { "pnp" };
    let start = Instant::now();
    let (h, w) = model.shape();
    let n = h * w;
    let likelihood = PoissonLikelihood::new(model, counts, bins, opts.eps);
    let mut trace = Trace::new(method);
    trace.prior = Some(denoiser.name());
    trace.notes.push(format!(
        "{} FFTs per likelihood gradient ({} of {} bins have counts; bins without counts only add the constant term)",
        likelihood.ffts_per_gradient(),
        bins.len() - likelihood.skipped_bins(),
        bins.len()
    ));
    let total: f64 = counts.sum();
    let flat = flat_level(total, likelihood.total_mass(), n);
    if total == 0.0 {
        return Ok(no_photons(trace, (h, w), truth));
    }
    let deviance = ExpectedDeviance::shared();
    let mut o = vec![flat; n];
    let mut v = Array2::from_elem((h, w), flat);
    let mut u = Array2::<f64>::zeros((h, w));
    let mut lambda = opts.lambda0;
    let mut row0 = TraceRow {
        wall_s: start.elapsed().as_secs_f64(),
        ..Default::default()
    };
    score(&mut row0, v.view(), truth);
    trace.rows.push(row0);
    let mut stopped = format!("iteration cap {}", opts.max_iters);
    let mut budget_hits = 0usize;
    // Iterations whose sigma exceeded the denoiser's trained range.
    let mut clamped: Vec<usize> = Vec::new();
    // Smallest deviance seen, with its iteration and iterate.
    let mut smallest: Option<(f64, usize, Array2<f64>)> = None;
    for it in 1..=opts.max_iters {
        let z: Vec<f64> = v.iter().zip(&u).map(|(vj, uj)| vj - uj).collect();
        let best = Mutex::new(None);
        let problem = OUpdate {
            likelihood: &likelihood,
            z,
            lambda,
            cache: Mutex::new(None),
            best: &best,
            evaluations: Mutex::new(0),
            budget: evaluation_budget(opts),
        };
        let solver = LBFGS::new(MoreThuenteLineSearch::new(), opts.lbfgs_memory)
            .with_tolerance_grad(opts.lbfgs_grad_tol)
            .and_then(|s| s.with_tolerance_cost(0.0))
            .map_err(|e| ReconstructError::Optimiser(e.to_string()))?;
        let inner = match Executor::new(problem, solver)
            .configure(|s| s.param(o.clone()).max_iters(opts.lbfgs_iters))
            .run()
        {
            Ok(result) => result.state().get_iter(),
            Err(e) if e.to_string().contains(BUDGET_SPENT) => {
                budget_hits += 1;
                opts.lbfgs_iters
            }
            Err(e) => return Err(ReconstructError::Optimiser(e.to_string())),
        };
        let (objective, best) = best
            .into_inner()
            .expect("best lock")
            .ok_or_else(|| ReconstructError::Optimiser("no finite objective value".into()))?;
        o = best;
        let o_img = Array2::from_shape_vec((h, w), o.clone()).expect("shape");
        let sigma = (opts.beta / lambda).sqrt();
        // The prior includes what the physics knows: a transmittance is never
        // negative. Projecting the denoised iterate onto v >= 0 measured
        // +0.9 dB at the best iteration on the text scene (BENCHMARKS.md).
        let scaled = denoise_scaled(denoiser, (&o_img + &u).view(), sigma);
        if scaled.unit_sigma.is_some_and(|s| s > denoiser.sigma_max()) {
            clamped.push(it);
        }
        let v_new = scaled.image.mapv(|x| x.max(0.0));
        u = u + &o_img - &v_new;
        let rms = |a: &Array2<f64>| (a.mapv(|x| x * x).sum() / n as f64).sqrt();
        let primal = rms(&(&o_img - &v_new));
        let dual = lambda * rms(&(&v_new - &v));
        v = v_new;
        if v.iter().any(|x| !x.is_finite()) {
            return Err(ReconstructError::NonFinite {
                method: method.into(),
                iteration: it,
            });
        }
        let (dev, expected) = deviance.check(model, counts, bins, v.view());
        let mut row = TraceRow {
            iteration: it,
            wall_s: start.elapsed().as_secs_f64(),
            objective: Some(objective),
            primal_residual: Some(primal),
            dual_residual: Some(dual),
            sigma: Some(sigma),
            lambda: Some(lambda),
            deviance: Some(dev),
            expected_deviance: Some(expected),
            inner_iterations: Some(inner),
            ..Default::default()
        };
        score(&mut row, v.view(), truth);
        on_iter(&row);
        trace.rows.push(row);
        lambda *= opts.lambda_step;
        if opts.stop == StopRule::Deviance {
            if smallest.as_ref().is_none_or(|(d, _, _)| dev < *d) {
                smallest = Some((dev, it, v.clone()));
            }
            let (best_dev, best_it, _) = smallest.as_ref().expect("set above");
            if it - best_it >= opts.patience {
                stopped = format!(
                    "deviance has not decreased for {} iterations; returning iteration {best_it} (deviance {best_dev:.1}, {expected:.1} expected from Poisson noise)",
                    opts.patience
                );
                break;
            }
        }
        if primal < opts.primal_tol && dual < opts.dual_tol {
            stopped = format!("residuals below tolerance at iteration {it}");
            break;
        }
    }
    trace.notes.push(format!("stopped: {stopped}"));
    if let (Some(first), Some(last)) = (clamped.first(), clamped.last()) {
        trace.notes.push(format!(
            "sigma clamped to the prior's trained maximum {:.4} (on its [0, 1] scale) in {} iteration(s), {first} to {last}",
            denoiser.sigma_max(),
            clamped.len()
        ));
    }
    if budget_hits > 0 {
        trace.notes.push(format!(
            "{budget_hits} o-update(s) ended on the evaluation budget ({} calls per update; the line search did not converge) with their best point",
            evaluation_budget(opts)
        ));
    }
    let (output, iteration) = match smallest {
        Some((_, it, img)) => (img, it),
        None => (v, trace.rows.len() - 1),
    };
    trace.notes.push(format!("output: iteration {iteration}"));
    let image = finish(output, method, iteration)?;
    Ok(Reconstruction { image, trace })
}
