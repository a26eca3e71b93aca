//! Physics of time-resolved imaging through a scattering slab.
//!
//! The diffusion approximation of the radiative transport equation gives a
//! spatio-temporal point spread function (ST-PSF, Eq. 6 of the paper):
//!
//! ```text
//! h(x, y, t; z0) = c / (4 pi D c t)^(3/2) * exp(-(x^2 + y^2 + z0^2) / (4 D c t) - mu_a c t)
//! ```
//!
//! with `D = 1 / (3 (mu_a + (1 - g) mu_s))` (Eq. 2) and `c` the speed of light
//! in the medium. This crate holds the parameters ([`params`]), the pointwise
//! log-domain evaluation ([`diffusion`]), the pixel- and bin-integrated kernel
//! stack ([`kernel`]) and the validity diagnostics ([`validity`]).
//!
//! It depends on nothing else of the workspace so that both the host
//! (`scatterscope`) and the emulated devices (`scatterscope-mocks`) can use it
//! without a dependency cycle.

#![warn(missing_docs)]

pub mod diffusion;
pub mod diffusion_error;
pub mod error;
pub mod irf;
pub mod kernel;
pub mod params;
pub mod quadrature;
pub mod slab;
pub mod transport;
pub mod transport_cache;
pub mod validity;

pub use diffusion::Diffusion;
pub use error::ParamError;
pub use irf::{InstrumentResponse, Irf, IrfTable};
pub use kernel::{KernelStack, Sampling};
pub use params::{Medium, MediumModel, Preset, Sensor, Setup, TimeBins};
pub use validity::Diagnostic;
