//! The Poisson toolkit shared by the 2-D methods ([`crate::reconstruct`])
//! and the hidden-volume methods ([`crate::confocal`]): photon counts
//! thinned into independent halves ([`thinning`]), for stops and choices
//! made without the truth, and the Poisson deviance that scores a
//! prediction against counts ([`deviance`]).

pub mod deviance;
pub mod thinning;
