//! Reconstruction settings shared by `reconstruct` and `report`.

use crate::shared_args::{choice, same_fields};

use scatterscope::denoise::prior::PriorSpec;
use scatterscope::named::Named;
use scatterscope::reconstruct::admm_lbfgs::{AdmmLbfgsOptions, PnpStop};
use scatterscope::reconstruct::method::{Acceleration, MethodOptions, RlStop, Solver};
use scatterscope::reconstruct::split::SplitOptions;

/// Flags of the reconstruction algorithms.
#[derive(Debug, Clone, clap::Args)]
pub struct ReconArgs {
    #[command(flatten)]
    pub prior: PriorSpec,
    /// PnP solver: split (exact splitting, P4IP) or admm-lbfgs (Algorithm 1).
    #[arg(long, value_parser = choice::<Solver>(), default_value = MethodOptions::default().solver.name())]
    pub solver: Solver,
    /// Split: data penalty rho, relative to the flat object's Poisson curvature.
    #[arg(long, default_value_t = SplitOptions::default().rho)]
    pub rho: f64,
    /// Split: prior penalty gamma, relative to the data's weight at frequency 0.
    #[arg(long, default_value_t = SplitOptions::default().gamma)]
    pub gamma: f64,
    /// Split: the prior's first sigma, relative to the flat object's level.
    #[arg(long, default_value_t = SplitOptions::default().sigma0)]
    pub sigma0: f64,
    /// Split: sigma shrinks by this factor per iteration down to its floor.
    #[arg(long, default_value_t = SplitOptions::default().sigma_decay)]
    pub sigma_decay: f64,
    /// Split: last sigma = sigma_floor o_flat n^-sigma_power (n photons per pixel).
    #[arg(long, default_value_t = SplitOptions::default().sigma_floor)]
    pub sigma_floor: f64,
    /// Split: see --sigma-floor.
    #[arg(long, default_value_t = SplitOptions::default().sigma_power)]
    pub sigma_power: f64,
    /// Split: deviance target, in noise SDs above Poisson noise's own.
    #[arg(long, default_value_t = SplitOptions::default().target_z)]
    pub target_z: f64,
    /// Split: iterations at the target before stopping.
    #[arg(long, default_value_t = SplitOptions::default().patience)]
    pub split_patience: usize,
    /// Split: start from this many RL iterations on the summed stack (0: flat).
    #[arg(long, default_value_t = SplitOptions::default().warm_start)]
    pub warm_start: usize,
    /// Split: the learned prior on its fixed 2x2 grid, or averaged over its
    /// four positions (3x the time; +0.3 dB on average, BENCHMARKS.md).
    #[arg(long, default_value = "fixed", value_parser = ["fixed", "average"])]
    pub prior_grid: String,
    /// admm-lbfgs: initial penalty lambda_0.
    #[arg(long, default_value_t = AdmmLbfgsOptions::default().lambda0)]
    pub lambda0: f64,
    /// admm-lbfgs: lambda grows by this factor per iteration.
    #[arg(long, default_value_t = AdmmLbfgsOptions::default().lambda_step)]
    pub lambda_step: f64,
    /// admm-lbfgs: prior weight beta (sigma^2 = beta / lambda).
    #[arg(long, default_value_t = AdmmLbfgsOptions::default().beta)]
    pub beta: f64,
    /// ADMM iteration cap [default: split 80, admm-lbfgs 100].
    #[arg(long)]
    pub max_iters: Option<usize>,
    /// admm-lbfgs stopping rule: agreement (smallest primal residual the
    /// noise allows), deviance, iterations, or auto (agreement for FFDNet).
    #[arg(long, value_parser = choice::<PnpStop>(), default_value = AdmmLbfgsOptions::default().stop.name())]
    pub stop: PnpStop,
    /// admm-lbfgs: iterations without a new pick [default: 10, deviance 30].
    #[arg(long)]
    pub patience: Option<usize>,
    /// ADMM primal and dual residual tolerance (RMS per pixel).
    #[arg(long, default_value_t = AdmmLbfgsOptions::default().primal_tol)]
    pub residual_tol: f64,
    /// L-BFGS iterations per o-update.
    #[arg(long, default_value_t = AdmmLbfgsOptions::default().lbfgs_iters)]
    pub lbfgs_iters: u64,
    /// L-BFGS gradient-norm tolerance.
    #[arg(long, default_value_t = AdmmLbfgsOptions::default().lbfgs_grad_tol)]
    pub lbfgs_tol: f64,
    /// Switch point of the surrogate logarithm (Eq. 16).
    #[arg(long, default_value_t = AdmmLbfgsOptions::default().eps)]
    pub eps: f64,
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
}

impl ReconArgs {
    /// The method settings, checked.
    pub fn options(&self) -> anyhow::Result<MethodOptions> {
        let split = same_fields!(self => SplitOptions { rho, gamma, sigma0, sigma_decay,
            sigma_floor, sigma_power, target_z, warm_start }
            patience: self.split_patience,
            max_iters: self.max_iters.unwrap_or(SplitOptions::default().max_iters),
            average_prior_grid: self.prior_grid == "average");
        let admm_lbfgs = same_fields!(self => AdmmLbfgsOptions { lambda0, lambda_step, beta,
            stop, patience, lbfgs_iters, eps }
            max_iters: self.max_iters.unwrap_or(AdmmLbfgsOptions::default().max_iters),
            primal_tol: self.residual_tol,
            dual_tol: self.residual_tol,
            lbfgs_memory: AdmmLbfgsOptions::default().lbfgs_memory,
            lbfgs_grad_tol: self.lbfgs_tol);
        let opts = same_fields!(self => MethodOptions { solver }
            split, admm_lbfgs,
            rl_stop: self.rl_stop.with_counts(self.rl_iters, self.rl_max_iters, self.rl_acceleration));
        opts.validate()?;
        Ok(opts)
    }
}
