//! Reconstruction settings shared by `reconstruct` and `report`.

use crate::shared_args::choice;
use std::path::PathBuf;

use scatterscope::denoise::ffdnet::source;
use scatterscope::denoise::tv::TotalVariation;
use scatterscope::denoise::{Denoiser, NoPrior};
use scatterscope::reconstruct::admm_lbfgs::{AdmmLbfgsOptions, StopRule};
use scatterscope::reconstruct::method::{MethodOptions, RlStop, Solver};
use scatterscope::reconstruct::split::SplitOptions;

/// The prior plugged into PnP-ADMM.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DenoiserChoice {
    /// FFDNet, the learned prior (weights: --weights, else
    /// $SCATTERSCOPE_FFDNET_WEIGHTS, else imported, else embedded).
    Ffdnet,
    /// Total variation (Chambolle), weight = gain * sigma.
    Tv,
    /// No prior.
    Identity,
}

/// The denoiser and its settings (`reconstruct`, `report`, `denoise`).
#[derive(Debug, Clone, clap::Args)]
pub struct PriorArgs {
    /// Prior for PnP-ADMM (the denoiser).
    #[arg(long, value_enum, default_value = "ffdnet")]
    pub denoiser: DenoiserChoice,
    /// FFDNet weight file (the project's safetensors format), or
    /// `embedded` for the built-in weights even when imported ones exist.
    #[arg(long, value_name = "PATH")]
    pub weights: Option<PathBuf>,
    /// TV weight per unit of the denoiser's noise sigma.
    #[arg(long, default_value_t = 0.5)]
    pub tv_gain: f64,
}

impl PriorArgs {
    /// The chosen denoiser, its settings checked.
    pub fn denoiser(&self) -> anyhow::Result<Box<dyn Denoiser>> {
        anyhow::ensure!(
            self.tv_gain > 0.0 && self.tv_gain.is_finite(),
            "--tv-gain = {} must be a positive number",
            self.tv_gain
        );
        anyhow::ensure!(
            self.weights.is_none() || self.denoiser == DenoiserChoice::Ffdnet,
            "--weights applies to --denoiser ffdnet only"
        );
        Ok(match self.denoiser {
            DenoiserChoice::Ffdnet => Box::new(source::load(self.weights.as_deref())?),
            DenoiserChoice::Tv => Box::new(TotalVariation {
                gain: self.tv_gain,
                ..Default::default()
            }),
            DenoiserChoice::Identity => Box::new(NoPrior),
        })
    }
}

impl PriorArgs {
    /// For `report`: TV (at `--tv-gain`) as a second prior when the chosen
    /// one is not TV, so the learned prior is always shown beside it.
    pub fn tv_comparison(&self) -> anyhow::Result<Option<(String, Box<dyn Denoiser>)>> {
        if self.denoiser == DenoiserChoice::Tv {
            return Ok(None);
        }
        let tv = PriorArgs {
            denoiser: DenoiserChoice::Tv,
            weights: None,
            tv_gain: self.tv_gain,
        };
        Ok(Some(("tv".to_string(), tv.denoiser()?)))
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
    /// The method settings, checked.
    pub fn options(&self) -> anyhow::Result<MethodOptions> {
        let positive = |name: &str, v: f64| {
            anyhow::ensure!(
                v > 0.0 && v.is_finite(),
                "--{name} = {v} must be a positive number"
            );
            Ok(())
        };
        let finite = |name: &str, v: f64| {
            anyhow::ensure!(v.is_finite(), "--{name} = {v} must be a finite number");
            Ok(())
        };
        positive("lambda0", self.lambda0)?;
        positive("rho", self.rho)?;
        positive("gamma", self.gamma)?;
        anyhow::ensure!(
            self.sigma0 >= 0.0 && self.sigma0.is_finite(),
            "--sigma0 = {} must be a finite number >= 0",
            self.sigma0
        );
        positive("sigma-floor", self.sigma_floor)?;
        finite("sigma-power", self.sigma_power)?;
        finite("target-z", self.target_z)?;
        positive("beta", self.beta)?;
        positive("eps", self.eps)?;
        anyhow::ensure!(
            self.lambda_step >= 1.0 && self.lambda_step.is_finite(),
            "--lambda-step = {} must be at least 1",
            self.lambda_step
        );
        anyhow::ensure!(
            self.sigma_decay > 0.0 && self.sigma_decay <= 1.0,
            "--sigma-decay = {} must lie in (0, 1]",
            self.sigma_decay
        );
        let split = SplitOptions::default();
        let lbfgs = AdmmLbfgsOptions::default();
        Ok(MethodOptions {
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
        })
    }
}
