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
//! default a rule that needs no truth ([`PnpStop::Auto`]). As sigma
//! keeps shrinking, ADMM eventually fits noise and the image degrades, so
//! some iterate must be chosen from the data alone. Two facts shape the rule
//! (measured on 150-iteration traces, BENCHMARKS.md):
//! - The Poisson deviance `D(v)` of the output ([`super::discrepancy`])
//!   separates the early, over-smoothed iterates from the rest, but after
//!   about 20 iterations all iterates lie within one standard deviation of
//!   the noise's own deviance of each other (differences of a few hundred
//!   against a standard deviation of about 1650 on the paper preset): the
//!   data cannot tell them apart, and the smallest `D` is an arbitrary pick
//!   among them (on the disks it returned 27.7 dB of a possible 31.2 dB).
//! - Among those iterates, the one where the data step and the prior step
//!   agree best, the smallest primal residual `||o - v||`, lies within
//!   0.25 dB of the best iteration by truth with the learned prior on every
//!   scene measured (nine traces, five of them held out).
//!
//! So the agreement rule keeps the iterate with the smallest primal residual
//! among those whose deviance is within one noise standard deviation of the
//! smallest deviance seen and at most two above what the noise alone gives
//! (the discrepancy test), and stops when that pick has not changed for
//! `patience` (10) iterations. It needs a prior that stays a prior at small
//! sigma: TV's weight is proportional to sigma, so with TV `||o - v||`
//! falls steadily to zero and the rule would run to the cap (0.5-1 dB past
//! the best iterate). The default [`PnpStop::Auto`] therefore uses it for
//! the learned prior and the smallest-deviance rule (patience 30) for priors
//! that fade to the identity. How close each comes to the best iteration
//! chosen with the truth is measured in BENCHMARKS.md.

use std::sync::Mutex;

use argmin::core::{CostFunction, Executor, Gradient, State};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::LBFGS;
use ndarray::Array2;

use super::data::{Data, flat_level};
use super::discrepancy::ExpectedDeviance;
use super::error::ReconstructError;
use super::likelihood::PoissonLikelihood;
use super::run::{Estimate, Reconstructor, Run, WorkShape, grid_note};
use super::split::pnp_working_bytes;
use super::trace::TraceRow;
use crate::denoise::{Denoiser, denoise_scaled};
use crate::named::named;

/// When ADMM stops, besides the iteration cap and residual tolerances.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PnpStop {
    /// `agreement` for priors that do not fade to the identity at small
    /// sigma (the learned one), `deviance` for those that do (TV, identity).
    Auto,
    /// Smallest primal residual among the iterates the data cannot reject
    /// (deviance within one noise standard deviation of the smallest), with
    /// patience (needs no truth).
    Agreement,
    /// Smallest Poisson deviance of the output, with patience (needs no truth).
    Deviance,
    /// Only the iteration cap and the residual tolerances.
    Iterations,
}

named!(PnpStop {
    Auto => "auto",
    Agreement => "agreement",
    Deviance => "deviance",
    Iterations => "iterations",
});

/// Parameters of Algorithm 1 and of its o-update. The command line's
/// admm-lbfgs flags are these fields (their docs are the flags' help; one
/// `--max-iters` caps both solvers, one `--residual-tol` sets both
/// tolerances).
#[derive(Debug, Clone, Copy)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[cfg_attr(
    feature = "cli",
    command(next_help_heading = "admm-lbfgs solver (--solver admm-lbfgs)")
)]
pub struct AdmmLbfgsOptions {
    /// Initial ADMM penalty lambda_0.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = AdmmLbfgsOptions::default().lambda0))]
    pub lambda0: f64,
    /// Growth factor of lambda per iteration.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = AdmmLbfgsOptions::default().lambda_step))]
    pub lambda_step: f64,
    /// Regularisation weight beta (sigma^2 = beta / lambda).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = AdmmLbfgsOptions::default().beta))]
    pub beta: f64,
    /// ADMM iteration cap.
    #[cfg_attr(feature = "cli", arg(skip = AdmmLbfgsOptions::default().max_iters))]
    pub max_iters: usize,
    /// Stop when the primal residual ||o - v|| / sqrt(N) falls below this ...
    #[cfg_attr(feature = "cli", arg(skip = AdmmLbfgsOptions::default().primal_tol))]
    pub primal_tol: f64,
    /// ... and the dual residual lambda ||v - v_prev|| / sqrt(N) below this.
    #[cfg_attr(feature = "cli", arg(skip = AdmmLbfgsOptions::default().dual_tol))]
    pub dual_tol: f64,
    /// Stopping rule: agreement (smallest primal residual the noise
    /// allows), deviance, iterations, or auto (agreement for FFDNet).
    #[cfg_attr(feature = "cli", arg(long, value_parser = crate::named::choice::<PnpStop>(), default_value = crate::Named::name(AdmmLbfgsOptions::default().stop)))]
    pub stop: PnpStop,
    /// Iterations without a new pick before the stopping rule stops
    /// [default: the rule's own, agreement 10, deviance 30].
    #[cfg_attr(feature = "cli", arg(long))]
    pub patience: Option<usize>,
    /// L-BFGS iteration cap per o-update.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = AdmmLbfgsOptions::default().lbfgs_iters))]
    pub lbfgs_iters: u64,
    /// L-BFGS memory (stored correction pairs).
    #[cfg_attr(feature = "cli", arg(skip = AdmmLbfgsOptions::default().lbfgs_memory))]
    pub lbfgs_memory: usize,
    /// L-BFGS gradient-norm tolerance.
    #[cfg_attr(feature = "cli", arg(long = "lbfgs-tol", value_name = "LBFGS_TOL", default_value_t = AdmmLbfgsOptions::default().lbfgs_grad_tol))]
    pub lbfgs_grad_tol: f64,
    /// Switch point of the surrogate logarithm (Eq. 16).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = AdmmLbfgsOptions::default().eps))]
    pub eps: f64,
}

impl Default for AdmmLbfgsOptions {
    fn default() -> Self {
        Self {
            lambda0: 1.0,
            lambda_step: 1.1,
            beta: 0.25,
            max_iters: 100,
            primal_tol: 1e-4,
            dual_tol: 1e-4,
            stop: PnpStop::Auto,
            patience: None,
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
    likelihood: &'a PoissonLikelihood<'a>,
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
fn evaluation_budget(opts: &AdmmLbfgsOptions) -> u64 {
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

/// How many noise standard deviations above its expectation an iterate's
/// deviance may lie for the agreement rule to consider it (a one-sided test
/// at about 2.3 %). Without it, a run that sits far from the data for tens of
/// iterations (a natural image, BENCHMARKS.md) stopped there, 2.5 dB below
/// the iterates that later fit the data.
const DISCREPANCY_Z: f64 = 2.0;

/// The stopping rule's current choice of output iterate.
struct Pick {
    /// What the rule minimises: primal residual or deviance.
    score: f64,
    deviance: f64,
    iteration: usize,
    image: Array2<f64>,
}

/// The paper's Algorithm 1 with `denoiser` as its prior.
pub struct AdmmLbfgs<'a> {
    /// The prior.
    pub denoiser: &'a dyn Denoiser,
    /// Its settings.
    pub opts: AdmmLbfgsOptions,
}

impl Reconstructor for AdmmLbfgs<'_> {
    fn name(&self, bins: usize) -> &'static str {
        if bins == 1 { "pnp-slice" } else { "pnp" }
    }

    fn reconstruct(
        &self,
        data: &Data<'_>,
        run: &mut Run<'_>,
    ) -> Result<Estimate, ReconstructError> {
        admm_lbfgs(data, self.denoiser, &self.opts, run)
    }

    /// As the split solver's (the likelihood's per-bin state on the sensor
    /// and in the spectrum) plus L-BFGS's stored correction pairs.
    fn working_bytes(&self, shape: &WorkShape) -> u64 {
        let pairs = 16 * self.opts.lbfgs_memory as u64;
        pnp_working_bytes(shape, self.denoiser, pairs)
    }
}

/// Runs Algorithm 1 on `data`.
fn admm_lbfgs(
    data: &Data<'_>,
    denoiser: &dyn Denoiser,
    opts: &AdmmLbfgsOptions,
    run: &mut Run<'_>,
) -> Result<Estimate, ReconstructError> {
    let (model, counts, bins) = (data.model, data.counts, data.bins);
    let (h, w) = model.sensor_shape();
    let (gh, gw) = model.grid_shape();
    let n = gh * gw;
    let likelihood = PoissonLikelihood::new(model, counts, bins, opts.eps);
    run.set_prior(denoiser.name());
    run.note(format!(
        "{} FFTs per likelihood gradient ({} of {} bins have counts; bins without counts only add the constant term)",
        likelihood.ffts_per_gradient(),
        bins.len() - likelihood.skipped_bins(),
        bins.len()
    ));
    let total: f64 = counts.sum();
    run.note(grid_note(model));
    run.note_background(model);
    let flat = flat_level(
        total,
        model.background(),
        bins.len(),
        likelihood.total_mass(),
        h * w,
    );
    if total == 0.0 {
        return Ok(run.no_photons((h, w)));
    }
    let deviance = ExpectedDeviance::shared();
    let stop = match opts.stop {
        PnpStop::Auto if denoiser.fades_to_identity() => PnpStop::Deviance,
        PnpStop::Auto => PnpStop::Agreement,
        rule => rule,
    };
    let patience = opts.patience.unwrap_or(match stop {
        PnpStop::Deviance => 30,
        _ => 10,
    });
    if stop != PnpStop::Iterations {
        run.note(format!(
            "stopping rule: {} with patience {patience}",
            match stop {
                PnpStop::Agreement =>
                    "agreement (smallest primal residual among iterates the data cannot reject)",
                _ => "deviance (smallest Poisson deviance)",
            }
        ));
    }
    let mut o = vec![flat; n];
    let mut v = Array2::from_elem((gh, gw), flat);
    let mut u = Array2::<f64>::zeros((gh, gw));
    let mut lambda = opts.lambda0;
    let mut row0 = run.row(0);
    run.score(&mut row0, model.crop(v.view()).view());
    run.push(row0);
    let mut stopped = format!("iteration cap {}", opts.max_iters);
    let mut budget_hits = 0usize;
    // Iterations whose sigma exceeded the denoiser's trained range.
    let mut clamped: Vec<usize> = Vec::new();
    // The stopping rule's current choice and the smallest deviance seen.
    let mut pick: Option<Pick> = None;
    let mut smallest_deviance = f64::INFINITY;
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
        let o_img = Array2::from_shape_vec((gh, gw), o.clone()).expect("shape");
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
            return Err(run.non_finite(it));
        }
        let check = deviance.check(model, counts, bins, v.view());
        let mut row = TraceRow {
            objective: Some(objective),
            primal_residual: Some(primal),
            dual_residual: Some(dual),
            sigma: Some(sigma),
            lambda: Some(lambda),
            deviance: Some(check.deviance),
            expected_deviance: Some(check.expected),
            deviance_sd: Some(check.sd),
            inner_iterations: Some(inner),
            ..run.row(it)
        };
        if run.scores() {
            run.score(&mut row, model.crop(v.view()).view());
        }
        run.push(row);
        lambda *= opts.lambda_step;
        if stop != PnpStop::Iterations {
            smallest_deviance = smallest_deviance.min(check.deviance);
            // Eligible: within one noise standard deviation of the smallest
            // deviance seen (a later iterate can void an earlier pick) and,
            // for the agreement rule, passing the discrepancy test: at most
            // DISCREPANCY_Z standard deviations above what the noise gives.
            let relative = smallest_deviance + check.sd;
            let tolerance = match stop {
                PnpStop::Agreement => relative.min(check.expected + DISCREPANCY_Z * check.sd),
                _ => relative,
            };
            if pick.as_ref().is_some_and(|p| p.deviance > tolerance) {
                pick = None;
            }
            let score = match stop {
                PnpStop::Agreement => primal,
                _ => check.deviance,
            };
            if check.deviance <= tolerance && pick.as_ref().is_none_or(|p| score < p.score) {
                pick = Some(Pick {
                    score,
                    deviance: check.deviance,
                    iteration: it,
                    image: v.clone(),
                });
            }
            if let Some(p) = &pick
                && it - p.iteration >= patience
            {
                stopped = format!(
                    "{} for {} iterations; returning iteration {} (deviance {:.1}, {:.1} +- {:.1} expected from Poisson noise, smallest seen {smallest_deviance:.1})",
                    match stop {
                        PnpStop::Agreement =>
                            "no smaller primal residual among the iterates the data cannot reject",
                        _ => "deviance has not decreased",
                    },
                    patience,
                    p.iteration,
                    p.deviance,
                    check.expected,
                    check.sd
                );
                break;
            }
        }
        if primal < opts.primal_tol && dual < opts.dual_tol {
            stopped = format!("residuals below tolerance at iteration {it}");
            break;
        }
    }
    run.note(format!("stopped: {stopped}"));
    if let (Some(first), Some(last)) = (clamped.first(), clamped.last()) {
        run.note(format!(
            "sigma clamped to the prior's trained maximum {:.4} (on its [0, 1] scale) in {} iteration(s), {first} to {last}",
            denoiser.sigma_max(),
            clamped.len()
        ));
    }
    if budget_hits > 0 {
        run.note(format!(
            "{budget_hits} o-update(s) ended on the evaluation budget ({} calls per update; the line search did not converge) with their best point",
            evaluation_budget(opts)
        ));
    }
    let (output, iteration) = match pick {
        Some(p) => (p.image, p.iteration),
        None => {
            if stop == PnpStop::Agreement {
                run.note(format!(
                    "no iterate passed the discrepancy test (deviance at most {DISCREPANCY_Z} noise standard deviations above its expectation); returning the last"
                ));
            }
            (v, run.rows().len() - 1)
        }
    };
    run.note(format!("output: iteration {iteration}"));
    Ok(Estimate {
        image: model.crop(output.view()),
        iteration,
    })
}
