//! Reconstruction settings shared by `reconstruct` and `report`.

use crate::shared_args::choice;
use std::path::PathBuf;

use scatterscope::denoise::Denoiser;
use scatterscope::denoise::prior::{PriorKind, PriorSpec};
use scatterscope::reconstruct::admm_lbfgs::{AdmmLbfgsOptions, StopRule};
use scatterscope::reconstruct::method::{MethodOptions, RlStop, Solver};
use scatterscope::reconstruct::split::SplitOptions;

/// The denoiser and its settings (`reconstruct`, `report`, `denoise`).
#[derive(Debug, Clone, clap::Args)]
pub struct PriorArgs {
    /// Prior for PnP-ADMM (the denoiser): ffdnet (the learned prior;
    /// weights: --weights, else $SCATTERSCOPE_FFDNET_WEIGHTS, else
    /// imported, else embedded), tv (total variation, weight = gain x
    /// sigma) or identity (no prior).
    #[arg(long, value_parser = choice::<PriorKind>(), default_value = "ffdnet")]
    pub denoiser: PriorKind,
    /// FFDNet weight file (the project's safetensors format), or
    /// `embedded` for the built-in weights even when imported ones exist.
    #[arg(long, value_name = "PATH")]
    pub weights: Option<PathBuf>,
    /// TV weight per unit of the denoiser's noise sigma.
    #[arg(long, default_value_t = 0.5)]
    pub tv_gain: f64,
}

impl PriorArgs {
    /// The prior as the library specifies it.
    pub fn spec(&self) -> PriorSpec {
        PriorSpec {
            kind: self.denoiser,
            weights: self.weights.clone(),
            tv_gain: self.tv_gain,
        }
    }

    /// The chosen denoiser, its settings checked.
    pub fn denoiser(&self) -> anyhow::Result<Box<dyn Denoiser>> {
        Ok(self.spec().build()?)
    }

    /// For `report`: TV (at `--tv-gain`) as a second prior when the chosen
    /// one is not TV, so the learned prior is always shown beside it.
    pub fn tv_comparison(&self) -> anyhow::Result<Option<(String, Box<dyn Denoiser>)>> {
        if self.denoiser == PriorKind::Tv {
            return Ok(None);
        }
        let tv = PriorSpec {
            kind: PriorKind::Tv,
            weights: None,
            tv_gain: self.tv_gain,
        };
        Ok(Some(("tv".to_string(), tv.build()?)))
    }
}

/// Flags of the reconstruction algorithms.
#[derive(Debug, Clone, clap::Args)]
pub struct ReconArgs {
    #[command(flatten)]
    pub prior: PriorArgs,
    /// PnP solver: split (exact splitting, P4IP: closed-form Poisson prox
    /// and Fourier-domain o-update) or admm-lbfgs (the paper's Algorithm 1).
    #[arg(long, value_parser = choice::<Solver>(), default_value = "split")]
    pub solver: Solver,
    /// Split solver: data-split penalty rho, relative to the Poisson
    /// curvature at the flat object's counts.
    #[arg(long, default_value_t = SplitOptions::default().rho)]
    pub rho: f64,
    /// Split solver: prior-split penalty gamma, relative to the data's
    /// weight at zero frequency.
    #[arg(long, default_value_t = SplitOptions::default().gamma)]
    pub gamma: f64,
    /// Split solver: the denoiser's first sigma, relative to the level of
    /// the flat object that explains the total count.
    #[arg(long, default_value_t = SplitOptions::default().sigma0)]
    pub sigma0: f64,
    /// Split solver: sigma shrinks by this factor per iteration down to its floor.
    #[arg(long, default_value_t = SplitOptions::default().sigma_decay)]
    pub sigma_decay: f64,
    /// Split solver: the last sigma is sigma_floor x o_flat x n^-sigma_power,
    /// n the photons per pixel of the flat object that explains the total.
    #[arg(long, default_value_t = SplitOptions::default().sigma_floor)]
    pub sigma_floor: f64,
    /// Split solver: see --sigma-floor.
    #[arg(long, default_value_t = SplitOptions::default().sigma_power)]
    pub sigma_power: f64,
    /// Split solver: the deviance target, in noise standard deviations
    /// above the deviance Poisson noise alone gives.
    #[arg(long, default_value_t = SplitOptions::default().target_z)]
    pub target_z: f64,
    /// Split solver: iterations at the target before stopping.
    #[arg(long, default_value_t = SplitOptions::default().patience)]
    pub split_patience: usize,
    /// Split solver: start from this many Richardson-Lucy iterations on the
    /// time-summed stack (0: from the flat object that explains the total).
    #[arg(long, default_value_t = SplitOptions::default().warm_start)]
    pub warm_start: usize,
    /// Split solver: the learned prior on its fixed 2x2 pixel-unshuffle
    /// grid, or averaged over the grid's four positions (about 3x the
    /// time; removes a 2x2 pattern the blur cannot see: +0.3 dB on average
    /// on the tuning images at the paper's light, up to +3 dB on smooth
    /// scenes; BENCHMARKS.md)
    #[arg(long, default_value = "fixed", value_parser = ["fixed", "average"])]
    pub prior_grid: String,
    /// admm-lbfgs: initial penalty lambda_0.
    #[arg(long, default_value_t = 1.0)]
    pub lambda0: f64,
    /// admm-lbfgs: lambda grows by this factor per iteration.
    #[arg(long, default_value_t = 1.1)]
    pub lambda_step: f64,
    /// admm-lbfgs: regularisation weight beta; the denoiser gets
    /// sigma^2 = beta / lambda.
    #[arg(long, default_value_t = AdmmLbfgsOptions::default().beta)]
    pub beta: f64,
    /// ADMM iteration cap [default: split 80, admm-lbfgs 100].
    #[arg(long)]
    pub max_iters: Option<usize>,
    /// ADMM stopping rule besides the cap and residual tolerances, none of
    /// which needs the truth: agreement (the smallest primal residual among
    /// iterates whose Poisson deviance the noise can explain), deviance (the
    /// smallest deviance), iterations (cap only), or auto (agreement for the
    /// learned prior, deviance for TV and identity).
    #[arg(long, value_parser = choice::<StopRule>(), default_value = "auto")]
    pub stop: StopRule,
    /// Iterations without a new pick before the agreement or deviance rule
    /// stops (default: 10 for agreement, 30 for deviance).
    #[arg(long)]
    pub patience: Option<usize>,
    /// ADMM primal and dual residual tolerance (RMS per pixel).
    #[arg(long, default_value_t = 1e-4)]
    pub residual_tol: f64,
    /// L-BFGS iterations per o-update.
    #[arg(long, default_value_t = 20)]
    pub lbfgs_iters: u64,
    /// L-BFGS gradient-norm tolerance.
    #[arg(long, default_value_t = 1e-8)]
    pub lbfgs_tol: f64,
    /// Switch point of the surrogate logarithm (Eq. 16).
    #[arg(long, default_value_t = 1e-10)]
    pub eps: f64,
    /// Richardson-Lucy iterations (with --rl-stop fixed).
    #[arg(long, default_value_t = MethodOptions::default().rl_iters)]
    pub rl_iters: usize,
    /// When Richardson-Lucy stops: fixed (after --rl-iters) or cv (at the
    /// iteration whose estimate best predicts photons it was not fitted to:
    /// two-fold cross-validation on thinned halves of the counts; the
    /// output is the sum of the halves' estimates).
    #[arg(long, value_parser = choice::<RlStop>(), default_value = "cv")]
    pub rl_stop: RlStop,
    /// The most iterations --rl-stop cv searches.
    #[arg(long, default_value_t = MethodOptions::default().rl_max_iters)]
    pub rl_max_iters: usize,
}

impl ReconArgs {
    /// The method settings (checked where they are used).
    pub fn options(&self) -> anyhow::Result<MethodOptions> {
        let split = SplitOptions::default();
        let lbfgs = AdmmLbfgsOptions::default();
        let opts = MethodOptions {
            solver: self.solver,
            split: SplitOptions {
                rho: self.rho,
                gamma: self.gamma,
                sigma0: self.sigma0,
                sigma_decay: self.sigma_decay,
                sigma_floor: self.sigma_floor,
                sigma_power: self.sigma_power,
                target_z: self.target_z,
                patience: self.split_patience,
                max_iters: self.max_iters.unwrap_or(split.max_iters),
                warm_start: self.warm_start,
                average_prior_grid: self.prior_grid == "average",
            },
            admm_lbfgs: AdmmLbfgsOptions {
                lambda0: self.lambda0,
                lambda_step: self.lambda_step,
                beta: self.beta,
                max_iters: self.max_iters.unwrap_or(lbfgs.max_iters),
                primal_tol: self.residual_tol,
                dual_tol: self.residual_tol,
                stop: self.stop,
                patience: self.patience,
                lbfgs_iters: self.lbfgs_iters,
                lbfgs_memory: 7,
                lbfgs_grad_tol: self.lbfgs_tol,
                eps: self.eps,
            },
            rl_iters: self.rl_iters,
            rl_stop: self.rl_stop,
            rl_max_iters: self.rl_max_iters,
        };
        opts.validate()?;
        Ok(opts)
    }
}
