//! Reconstruction settings shared by `reconstruct` and `report`.

use crate::shared_args::choice;

use scatterscope::denoise::prior::PriorSpec;
use scatterscope::named::Named;
use scatterscope::reconstruct::admm_lbfgs::AdmmLbfgsOptions;
use scatterscope::reconstruct::method::{Acceleration, MethodOptions, RlStop, Solver};
use scatterscope::reconstruct::split::SplitOptions;

/// Flags of the reconstruction algorithms: the library's settings types,
/// and the flags that set several of their fields at once.
#[derive(Debug, Clone, clap::Args)]
pub struct ReconArgs {
    #[command(flatten)]
    pub prior: PriorSpec,
    /// PnP solver: split (exact splitting, P4IP) or admm-lbfgs (Algorithm 1).
    #[arg(long, value_parser = choice::<Solver>(), default_value = MethodOptions::default().solver.name())]
    pub solver: Solver,
    /// PnP iteration cap [default: split 80, admm-lbfgs 100].
    #[arg(long)]
    pub max_iters: Option<usize>,
    /// admm-lbfgs: primal and dual residual tolerance (RMS per pixel).
    #[arg(long, default_value_t = AdmmLbfgsOptions::default().primal_tol)]
    pub residual_tol: f64,
    /// Richardson-Lucy iterations (with --rl-stop fixed).
    #[arg(long, default_value_t = RlStop::DEFAULT_ITERS)]
    pub rl_iters: usize,
    /// When Richardson-Lucy stops: fixed (--rl-iters) or cv (two-fold
    /// cross-validation on thinned halves of the counts).
    #[arg(long, value_parser = choice::<RlStop>(), default_value = MethodOptions::default().rl_stop.name())]
    pub rl_stop: RlStop,
    /// The most iterations --rl-stop cv searches.
    #[arg(long, default_value_t = RlStop::DEFAULT_MAX_ITERS)]
    pub rl_max_iters: usize,
    /// How --rl-stop cv steps: none (plain EM steps) or extrapolated
    /// (vector extrapolation, the likelihood never going up).
    #[arg(long, value_parser = choice::<Acceleration>(), default_value = Acceleration::default().name())]
    pub rl_acceleration: Acceleration,
    /// Weights of the learned network (`learned`, and `auto`'s network)
    /// that `training/train_unrolled.py` wrote, instead of the embedded
    /// ones (`scatterscope weights show FILE` says what they were trained
    /// on).
    #[arg(long, value_name = "FILE")]
    pub learned_weights: Option<std::path::PathBuf>,
    #[command(flatten)]
    pub split: SplitOptions,
    #[command(flatten)]
    pub admm_lbfgs: AdmmLbfgsOptions,
}

impl ReconArgs {
    /// The method settings, checked.
    pub fn options(&self) -> anyhow::Result<MethodOptions> {
        let mut opts = MethodOptions {
            solver: self.solver,
            split: self.split,
            admm_lbfgs: AdmmLbfgsOptions {
                primal_tol: self.residual_tol,
                dual_tol: self.residual_tol,
                ..self.admm_lbfgs
            },
            rl_stop: self.rl_stop.with_counts(
                self.rl_iters,
                self.rl_max_iters,
                self.rl_acceleration,
            ),
            learned: match &self.learned_weights {
                Some(path) => Some(scatterscope::reconstruct::learned::from_file(path)?),
                None => None,
            },
        };
        if let Some(cap) = self.max_iters {
            opts.cap_pnp_iters(cap);
        }
        opts.validate()?;
        Ok(opts)
    }
}
