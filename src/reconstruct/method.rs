//! The reconstruction methods by name, as the CLI and the report run them.

use ndarray::{ArrayView2, Axis};

use super::ReconstructError;
use super::admm_lbfgs::{AdmmLbfgs, AdmmLbfgsOptions};
use super::auto::Auto;
use super::data::Data;
pub use super::em::{Acceleration, RlStop};
use super::guard::CarriedSearch;
use super::learned::net::LearnedNet;
use super::learned::{Learned, RL_SUM_CV};
use super::problem::Problem;
use super::rl_stack::RlStack;
use super::rl_sum::RlSum;
use super::run::{Reconstruction, Reconstructor, WorkShape};
use super::scaled_counts::ScaledCounts;
use super::split::{Split, SplitOptions};
use super::trace::TraceRow;
use crate::denoise::Denoiser;
use crate::named::{Named, named};

/// A reconstruction method.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// The default: the learned reconstruction inside its trained ranges,
    /// whole-stack Richardson-Lucy outside them ([`super::auto`]).
    Auto,
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
    /// Richardson-Lucy's iterates on the time-summed stack corrected by
    /// the embedded network trained here ([`super::learned`]).
    Learned,
}

named!(Method {
    Auto => "auto",
    Pnp => "pnp",
    PnpSlice => "pnp-slice",
    PnpSum => "pnp-sum",
    Rl => "rl",
    RlSum => "rl-sum",
    RlStack => "rl-stack",
    ScaledCounts => "scaled-counts",
    Learned => "learned",
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
    /// likelihood ([`super::admm_lbfgs`]).
    AdmmLbfgs,
}

named!(Solver {
    Split => "split",
    AdmmLbfgs => "admm-lbfgs",
});

named!(Acceleration {
    None => "none",
    Extrapolated => "extrapolated",
});

/// Settings of every method.
#[derive(Debug, Clone, Copy)]
pub struct MethodOptions {
    /// Which PnP solver runs.
    pub solver: Solver,
    /// Settings of the exact-splitting solver.
    pub split: SplitOptions,
    /// Settings of Algorithm 1 (L-BFGS solver).
    pub admm_lbfgs: AdmmLbfgsOptions,
    /// When Richardson-Lucy stops.
    pub rl_stop: RlStop,
    /// The network of `learned` and `auto`: weights a user trained
    /// ([`super::learned::from_file`]), or `None` for the embedded ones.
    pub learned: Option<&'static LearnedNet>,
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
            admm_lbfgs: AdmmLbfgsOptions::default(),
            rl_stop: RlStop::CROSS_VALIDATED,
            learned: None,
        }
    }
}

/// The most Richardson-Lucy iterations the split solver's start may take
/// (its benefit ends within a few hundred).
pub const MAX_WARM_START: usize = 100_000;

impl MethodOptions {
    /// Caps both PnP solvers at `cap` iterations: the one iteration cap a
    /// front end offers for either solver (the command line's
    /// `--max-iters`, Python's `max_iters`).
    pub fn cap_pnp_iters(&mut self, cap: usize) {
        self.split.max_iters = cap;
        self.admm_lbfgs.max_iters = cap;
    }

    /// Checks every setting: penalties, noise levels and tolerances are
    /// finite and in range; the error names the setting and its value.
    pub fn validate(&self) -> Result<(), ReconstructError> {
        let bad = |name: &'static str, value: f64, want: &'static str| {
            Err(ReconstructError::Setting { name, value, want })
        };
        let positive = |name, v: f64| {
            if v > 0.0 && v.is_finite() {
                Ok(())
            } else {
                bad(name, v, "a positive number")
            }
        };
        let finite = |name, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                bad(name, v, "a finite number")
            }
        };
        let (s, a) = (&self.split, &self.admm_lbfgs);
        positive("lambda0", a.lambda0)?;
        positive("rho", s.rho)?;
        positive("gamma", s.gamma)?;
        if !(s.sigma0 >= 0.0 && s.sigma0.is_finite()) {
            bad("sigma0", s.sigma0, "a finite number >= 0")?;
        }
        positive("sigma_floor", s.sigma_floor)?;
        finite("sigma_power", s.sigma_power)?;
        finite("target_z", s.target_z)?;
        positive("beta", a.beta)?;
        positive("eps", a.eps)?;
        if !(a.lambda_step >= 1.0 && a.lambda_step.is_finite()) {
            bad("lambda_step", a.lambda_step, "at least 1")?;
        }
        if s.warm_start > MAX_WARM_START {
            bad(
                "warm_start",
                s.warm_start as f64,
                "at most 100000 iterations",
            )?;
        }
        if !(s.sigma_decay > 0.0 && s.sigma_decay <= 1.0) {
            bad("sigma_decay", s.sigma_decay, "in (0, 1]")?;
        }
        if !(a.primal_tol >= 0.0 && a.dual_tol >= 0.0) {
            bad(
                "residual_tol",
                a.primal_tol.min(a.dual_tol),
                "a number >= 0",
            )?;
        }
        if a.lbfgs_grad_tol.is_nan() || a.lbfgs_grad_tol < 0.0 {
            bad("lbfgs_grad_tol", a.lbfgs_grad_tol, "a number >= 0")?;
        }
        Ok(())
    }

    /// The network these options choose: a user's, else the embedded.
    pub fn learned_net(&self) -> &'static LearnedNet {
        self.learned.unwrap_or_else(super::learned::embedded)
    }

    /// The PnP-ADMM solver these options choose, with `denoiser` as its
    /// prior.
    pub fn pnp<'a>(&self, denoiser: &'a dyn Denoiser) -> Box<dyn Reconstructor + 'a> {
        match self.solver {
            Solver::Split => Box::new(Split {
                denoiser,
                opts: self.split,
            }),
            Solver::AdmmLbfgs => Box::new(AdmmLbfgs {
                denoiser,
                opts: self.admm_lbfgs,
            }),
        }
    }
}

/// The part of the stack a planned method sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum View {
    /// One bin with its kernel.
    Bin(usize),
    /// The sum of every bin with the time-summed kernel.
    Summed,
    /// Every bin with its own kernel.
    Whole,
}

/// A method planned on a stack: the algorithm apart from the view of the
/// data it sees, and the memory both need.
pub struct MethodPlan<'a> {
    /// The algorithm.
    pub algorithm: Box<dyn Reconstructor + 'a>,
    /// What it sees.
    pub view: View,
    /// The method planned (a summed view's trace carries its name).
    pub method: Method,
}

impl<'a> MethodPlan<'a> {
    /// Plans `method` on a stack of `bins` bins; `bin` selects the bin of
    /// single-bin methods (and of `scaled-counts`, which otherwise sums
    /// every bin).
    pub fn new(
        method: Method,
        bin: Option<usize>,
        bins: usize,
        denoiser: &'a dyn Denoiser,
        opts: &MethodOptions,
    ) -> Result<Self, ReconstructError> {
        opts.validate()?;
        if let Some(b) = bin.filter(|&b| b >= bins) {
            return Err(ReconstructError::Shape(format!(
                "bin {b} does not exist: the stack has bins 0 to {}",
                bins.saturating_sub(1)
            )));
        }
        let one_bin = || {
            bin.map(View::Bin).ok_or_else(|| {
                ReconstructError::Shape(format!(
                    "method {} works on one bin; none was chosen",
                    method.name()
                ))
            })
        };
        let rl = RlSum { stop: opts.rl_stop };
        let rl_stack = RlStack { stop: opts.rl_stop };
        let (algorithm, view): (Box<dyn Reconstructor + 'a>, View) = match method {
            Method::Auto => (
                Box::new(Auto::new(opts.rl_stop, opts.learned_net(), None)),
                View::Whole,
            ),
            Method::Pnp => (opts.pnp(denoiser), View::Whole),
            Method::PnpSlice => (opts.pnp(denoiser), one_bin()?),
            Method::PnpSum => (opts.pnp(denoiser), View::Summed),
            Method::Rl => (Box::new(rl), one_bin()?),
            Method::RlSum => (Box::new(rl), View::Whole),
            Method::RlStack => (Box::new(rl_stack), View::Whole),
            Method::ScaledCounts => (Box::new(ScaledCounts), bin.map_or(View::Whole, View::Bin)),
            Method::Learned => (
                Box::new(Learned {
                    net: opts.learned_net(),
                    outside: Box::new(RL_SUM_CV),
                }),
                View::Whole,
            ),
        };
        Ok(Self {
            algorithm,
            view,
            method,
        })
    }

    /// The default method (`auto`) with its check's search carried
    /// between the snapshots of one growing acquisition by `carried` (the
    /// live view's).
    pub fn auto_carrying(opts: &MethodOptions, carried: &'a CarriedSearch) -> Self {
        Self {
            algorithm: Box::new(Auto::new(opts.rl_stop, opts.learned_net(), Some(carried))),
            view: View::Whole,
            method: Method::Auto,
        }
    }

    /// Checks the plan's working memory against the budget and runs it
    /// ([`MethodPlan::run`]).
    pub fn run_within_budget(
        &self,
        problem: &Problem,
        truth: Option<ArrayView2<f64>>,
        on_iter: &mut dyn FnMut(&TraceRow),
    ) -> Result<Reconstruction, ReconstructError> {
        let k = problem.counts.shape()[0];
        let (gh, gw) = problem.model.grid_shape();
        crate::memory::check(self.working_bytes(problem), || {
            format!("{} on {k} bins of a {gw} x {gh} grid", self.method.name())
        })?;
        self.run(problem, truth, on_iter)
    }

    /// The bytes the run holds beyond the problem: the view's own copies
    /// (one bin's counts; the summed counts and kernel) and the
    /// algorithm's working memory on them.
    pub fn working_bytes(&self, problem: &Problem) -> u64 {
        let k = problem.counts.shape()[0];
        let one = WorkShape::new(&problem.model, 1);
        let (shape, copies) = match self.view {
            View::Whole => (WorkShape::new(&problem.model, k), 0),
            View::Bin(_) => (one, one.bytes([8, 0, 0], [0; 3])),
            View::Summed => (one, one.bytes([8, 0, 16], [0; 3])),
        };
        copies.saturating_add(self.algorithm.working_bytes(&shape))
    }

    /// Runs the plan on `problem`, scored against `truth` when given; each
    /// trace row goes to `on_iter` as it is produced.
    pub fn run(
        &self,
        problem: &Problem,
        truth: Option<ArrayView2<f64>>,
        on_iter: &mut dyn FnMut(&TraceRow),
    ) -> Result<Reconstruction, ReconstructError> {
        let model = &problem.model;
        let mut r = match self.view {
            View::Whole => {
                let all = problem.all_bins();
                self.algorithm
                    .run(&Data::new(model, &problem.counts, &all)?, truth, on_iter)?
            }
            View::Bin(b) => {
                let counts = problem.single_bin(b);
                self.algorithm
                    .run(&Data::new(model, &counts, &[b])?, truth, on_iter)?
            }
            View::Summed => {
                let summed = model.summed(&problem.all_bins());
                let counts = problem.counts.sum_axis(Axis(0)).insert_axis(Axis(0));
                self.algorithm
                    .run(&Data::new(&summed, &counts, &[0])?, truth, on_iter)?
            }
        };
        if self.view == View::Summed {
            r.trace.method = self.method.name().into();
        }
        Ok(r)
    }
}

/// Runs `method` on `problem`: plans it ([`MethodPlan::new`]), checks the
/// plan's working memory against the budget, and runs it.
pub fn run_method(
    problem: &Problem,
    method: Method,
    bin: Option<usize>,
    denoiser: &dyn Denoiser,
    opts: &MethodOptions,
    truth: Option<ArrayView2<f64>>,
    mut on_iter: impl FnMut(&TraceRow),
) -> Result<Reconstruction, ReconstructError> {
    let plan = MethodPlan::new(method, bin, problem.counts.shape()[0], denoiser, opts)?;
    plan.run_within_budget(problem, truth, &mut on_iter)
}
