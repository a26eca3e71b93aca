//! The Poisson toolkit shared by the 2-D methods ([`crate::reconstruct`])
//! and the hidden-volume methods ([`crate::confocal`]): photon counts
//! thinned into independent halves ([`thinning`]), for stops and choices
//! made without the truth, the Poisson deviance that scores a
//! prediction against counts ([`deviance`]), and what counts can be
//! ([`counts`]: the limits every reader of counts shares).

pub mod counts;
pub mod deviance;
pub mod thinning;
