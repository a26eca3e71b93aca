//! Which prior a reconstruction plugs in, by name and settings, as every
//! front end chooses it.

use std::path::PathBuf;

use super::ffdnet::source;
use super::tv::TotalVariation;
use super::{Denoiser, NoPrior};
use crate::named::named;

/// The kinds of prior.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PriorKind {
    /// FFDNet, the learned prior (weights: given, else the weights
    /// variable, else imported, else embedded; see [`source::load`]).
    Ffdnet,
    /// Total variation (Chambolle), weight = gain x sigma.
    Tv,
    /// No prior.
    Identity,
}

named!(PriorKind {
    Ffdnet => "ffdnet",
    Tv => "tv",
    Identity => "identity",
});

/// A prior and its settings. The command line's prior flags are these
/// fields (their docs are the flags' help).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct PriorSpec {
    /// Prior for PnP: ffdnet (learned; weights: --weights, else
    /// $SCATTERSCOPE_FFDNET_WEIGHTS, else imported, else embedded), tv or
    /// identity.
    #[cfg_attr(feature = "cli", arg(long = "denoiser", value_name = "DENOISER", value_parser = crate::named::choice::<PriorKind>(), default_value = crate::Named::name(PriorSpec::default().kind)))]
    pub kind: PriorKind,
    /// FFDNet weights (the project's safetensors), or `embedded`.
    #[cfg_attr(feature = "cli", arg(long, value_name = "PATH"))]
    pub weights: Option<PathBuf>,
    /// TV weight per unit of the denoiser's noise sigma.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = PriorSpec::default().tv_gain))]
    pub tv_gain: f64,
}

impl Default for PriorSpec {
    /// The learned prior with the default weights; TV's gain 0.5.
    fn default() -> Self {
        Self {
            kind: PriorKind::Ffdnet,
            weights: None,
            tv_gain: TotalVariation::default().gain,
        }
    }
}

/// Why a prior cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum PriorError {
    /// A setting is out of range.
    #[error("{0}")]
    Setting(String),
    /// The FFDNet weights cannot be loaded.
    #[error(transparent)]
    Weights(#[from] super::ffdnet::weights::WeightsError),
}

impl PriorSpec {
    /// The prior, its settings checked and its weights loaded.
    pub fn build(&self) -> Result<Box<dyn Denoiser>, PriorError> {
        if !(self.tv_gain > 0.0 && self.tv_gain.is_finite()) {
            return Err(PriorError::Setting(format!(
                "tv_gain = {} must be a positive number",
                self.tv_gain
            )));
        }
        if self.weights.is_some() && self.kind != PriorKind::Ffdnet {
            return Err(PriorError::Setting(
                "weights apply to the ffdnet prior only".into(),
            ));
        }
        Ok(match self.kind {
            PriorKind::Ffdnet => Box::new(source::load(self.weights.as_deref())?),
            PriorKind::Tv => Box::new(TotalVariation {
                gain: self.tv_gain,
                ..Default::default()
            }),
            PriorKind::Identity => Box::new(NoPrior),
        })
    }

    /// TV at this gain, to be shown beside this prior when it is not TV
    /// itself (so the learned prior is always compared with it).
    pub fn tv_beside(&self) -> Result<Option<Box<dyn Denoiser>>, PriorError> {
        if self.kind == PriorKind::Tv {
            return Ok(None);
        }
        let tv = Self {
            kind: PriorKind::Tv,
            weights: None,
            tv_gain: self.tv_gain,
        };
        Ok(Some(tv.build()?))
    }
}
