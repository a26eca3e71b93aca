//! Reconstruction settings shared by `reconstruct` and `report`.

use std::path::PathBuf;

use scatterscope::denoise::ffdnet::source;
use scatterscope::denoise::tv::TotalVariation;
use scatterscope::denoise::{Denoiser, Identity};
use scatterscope::reconstruct::method::MethodOptions;
use scatterscope::reconstruct::pnp::{PnpOptions, StopRule};

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
    /// FFDNet weight file (the project's safetensors format).
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
            DenoiserChoice::Identity => Box::new(Identity),
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
    /// ADMM: initial penalty lambda_0.
    #[arg(long, default_value_t = 1.0)]
    pub lambda0: f64,
    /// ADMM: lambda grows by this factor per iteration.
    #[arg(long, default_value_t = 1.1)]
    pub lambda_step: f64,
    /// ADMM: regularisation weight beta; the denoiser gets sigma^2 = beta / lambda.
    #[arg(long, default_value_t = 0.25)]
    pub beta: f64,
    /// ADMM iteration cap.
    #[arg(long, default_value_t = 100)]
    pub max_iters: usize,
    /// ADMM stopping rule besides the cap and residual tolerances, none of
    /// which needs the truth: agreement (the smallest primal residual among
    /// iterates whose Poisson deviance the noise can explain), deviance (the
    /// smallest deviance), iterations (cap only), or auto (agreement for the
    /// learned prior, deviance for TV and identity).
    #[arg(long, value_enum, default_value = "auto")]
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
    /// Richardson-Lucy iterations.
    #[arg(long, default_value_t = 200)]
    pub rl_iters: usize,
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
        positive("lambda0", self.lambda0)?;
        positive("beta", self.beta)?;
        positive("eps", self.eps)?;
        anyhow::ensure!(
            self.lambda_step >= 1.0 && self.lambda_step.is_finite(),
            "--lambda-step = {} must be at least 1",
            self.lambda_step
        );
        Ok(MethodOptions {
            pnp: PnpOptions {
                lambda0: self.lambda0,
                lambda_step: self.lambda_step,
                beta: self.beta,
                max_iters: self.max_iters,
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
        })
    }
}
