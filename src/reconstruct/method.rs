//! The reconstruction methods by name, as the CLI and the report run them.

use ndarray::{Array3, ArrayView2, Axis};

use super::pnp::{PnpOptions, pnp_admm};
use super::problem::Problem;
use super::richardson_lucy::{richardson_lucy, richardson_lucy_cv};
use super::rl_stack::{richardson_lucy_stack, richardson_lucy_stack_cv};
use super::scaled_counts::scaled_counts;
use super::split::{SplitOptions, pnp_split};
use super::trace::TraceRow;
use super::{ReconstructError, Reconstruction};
use crate::denoise::Denoiser;
use crate::forward::ForwardModel;
use crate::named::{Named, named};

/// A reconstruction method.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Poisson PnP-ADMM on the whole stack (the paper's method).
    Pnp,
    /// PnP-ADMM on one bin (K = 1).
    PnpSlice,
    /// PnP-ADMM on the time-summed stack with the time-summed kernel (does
    /// the time axis help?).
    PnpSum,
    /// Richardson-Lucy on one bin.
    Rl,
    /// Richardson-Lucy on the time-summed stack with the time-summed kernel.
    RlSum,
    /// Richardson-Lucy on the whole stack, every bin with its own kernel.
    RlStack,
    /// Counts divided by kernel mass, no deblurring (one bin, or the sum
    /// of all bins when none is chosen).
    ScaledCounts,
}

named!(Method {
    Pnp => "pnp",
    PnpSlice => "pnp-slice",
    PnpSum => "pnp-sum",
    Rl => "rl",
    RlSum => "rl-sum",
    RlStack => "rl-stack",
    ScaledCounts => "scaled-counts",
});

impl Method {
    /// Whether the method works on a single bin.
    pub fn needs_bin(self) -> bool {
        matches!(self, Method::PnpSlice | Method::Rl)
    }
}

/// How PnP-ADMM solves its data step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Solver {
    /// Exact splitting (P4IP): closed-form Poisson prox per pixel and bin,
    /// exact Fourier-domain o-update ([`super::split`]).
    Split,
    /// The paper's Algorithm 1: L-BFGS o-update on the surrogate
    /// likelihood ([`super::pnp`]).
    AdmmLbfgs,
}

named!(Solver {
    Split => "split",
    AdmmLbfgs => "admm-lbfgs",
});

/// When Richardson-Lucy stops (RL's only regularisation is its iteration
/// count).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RlStop {
    /// After `rl_iters` iterations.
    Fixed,
    /// At the iteration chosen by two-fold cross-validation on thinned
    /// halves of the counts, searched up to `rl_max_iters`
    /// ([`super::richardson_lucy::richardson_lucy_cv`]).
    CrossValidated,
}

named!(RlStop {
    Fixed => "fixed",
    CrossValidated => "cv",
});

/// Settings of every method.
#[derive(Debug, Clone, Copy)]
pub struct MethodOptions {
    /// Which PnP solver runs.
    pub solver: Solver,
    /// Settings of the exact-splitting solver.
    pub split: SplitOptions,
    /// Settings of Algorithm 1 (L-BFGS solver).
    pub pnp: PnpOptions,
    /// Richardson-Lucy iterations (with [`RlStop::Fixed`]).
    pub rl_iters: usize,
    /// When Richardson-Lucy stops.
    pub rl_stop: RlStop,
    /// The most Richardson-Lucy iterations the cross-validated stop
    /// searches.
    pub rl_max_iters: usize,
}

impl Default for MethodOptions {
    /// The command line's defaults: the split solver with its defaults,
    /// Algorithm 1's defaults, Richardson-Lucy stopped by cross-validation
    /// (searched up to 1000 iterations; 200 with a fixed stop). On the
    /// benchmark's tuning images the cross-validated stop came within 0.3 dB
    /// of RL's best iteration chosen with the truth on average at each light
    /// level, where 200 fixed iterations were 1.4-5.8 dB below it
    /// (BENCHMARKS.md).
    fn default() -> Self {
        Self {
            solver: Solver::Split,
            split: SplitOptions::default(),
            pnp: PnpOptions::default(),
            rl_iters: 200,
            rl_stop: RlStop::CrossValidated,
            rl_max_iters: 1000,
        }
    }
}

/// Runs `method` on `problem`; `bin` selects the bin of single-bin methods
/// (and of `scaled-counts`, which otherwise sums all bins).
pub fn run_method(
    problem: &Problem,
    method: Method,
    bin: Option<usize>,
    denoiser: &dyn Denoiser,
    opts: &MethodOptions,
    truth: Option<ArrayView2<f64>>,
    mut on_iter: impl FnMut(&TraceRow),
) -> Result<Reconstruction, ReconstructError> {
    let k = problem.counts.shape()[0];
    if let Some(b) = bin.filter(|&b| b >= k) {
        return Err(ReconstructError::Shape(format!(
            "bin {b} does not exist: the stack has bins 0 to {}",
            k - 1
        )));
    }
    let single = |method: Method| {
        bin.ok_or_else(|| {
            ReconstructError::Shape(format!(
                "method {} works on one bin; none was chosen",
                method.name()
            ))
        })
    };
    let all = problem.all_bins();
    let model = &problem.model;
    let pnp = |model: &ForwardModel,
               counts: &Array3<f64>,
               bins: &[usize],
               on_iter: &mut dyn FnMut(&TraceRow)| match opts.solver {
        Solver::Split => pnp_split(model, counts, bins, denoiser, &opts.split, truth, on_iter),
        Solver::AdmmLbfgs => pnp_admm(model, counts, bins, denoiser, &opts.pnp, truth, on_iter),
    };
    let rl = |counts: &Array3<f64>, bins: &[usize], on_iter: &mut dyn FnMut(&TraceRow)| match opts
        .rl_stop
    {
        RlStop::Fixed => richardson_lucy(model, counts, bins, opts.rl_iters, truth, on_iter),
        RlStop::CrossValidated => {
            richardson_lucy_cv(model, counts, bins, opts.rl_max_iters, truth, on_iter)
        }
    };
    match method {
        Method::Pnp => pnp(model, &problem.counts, &all, &mut on_iter),
        Method::PnpSlice => {
            let b = single(method)?;
            pnp(model, &problem.single_bin(b), &[b], &mut on_iter)
        }
        Method::PnpSum => {
            let summed = model.summed(&all);
            let counts = problem.counts.sum_axis(Axis(0)).insert_axis(Axis(0));
            let mut r = pnp(&summed, &counts, &[0], &mut on_iter)?;
            r.trace.method = method.name().into();
            Ok(r)
        }
        Method::Rl => {
            let b = single(method)?;
            rl(&problem.single_bin(b), &[b], &mut on_iter)
        }
        Method::RlSum => rl(&problem.counts, &all, &mut on_iter),
        Method::RlStack => match opts.rl_stop {
            RlStop::Fixed => {
                richardson_lucy_stack(model, &problem.counts, &all, opts.rl_iters, truth, on_iter)
            }
            RlStop::CrossValidated => richardson_lucy_stack_cv(
                model,
                &problem.counts,
                &all,
                opts.rl_max_iters,
                truth,
                on_iter,
            ),
        },
        Method::ScaledCounts => match bin {
            Some(b) => scaled_counts(model, &problem.single_bin(b), &[b], truth),
            None => scaled_counts(model, &problem.counts, &all, truth),
        },
    }
}
