//! scatterscope: time-resolved imaging through scattering media.
//!
//! Data flows one way: a source (simulation, device or recorded file)
//! produces photon tags, tags are binned into a transient stack, the stack
//! is reconstructed, and the result is reported.
//!
//! - [`scene`]: test objects (built-in patterns or image files).
//! - [`forward`]: ST-PSF convolution and Poisson sampling.
//! - [`stack`]: the K x H x W transient stack with its metadata, and its
//!   OpenEXR / .npy files and PNG previews.
//! - [`reconstruct`]: Poisson PnP-ADMM, Richardson-Lucy and raw baselines.
//! - [`denoise`]: Gaussian denoisers plugged in as priors.
//! - [`metrics`]: PSNR and SSIM against a known truth.
//! - [`config`]: physics parameters from presets, TOML files and flags.
//!
//! The physics itself lives in the `scatterscope-physics` crate, re-exported
//! as [`physics`].

pub mod acquire;
pub mod config;
pub mod denoise;
pub mod fft2;
pub mod forward;
pub mod metrics;
pub mod reconstruct;
pub mod report;
pub mod scene;
pub mod stack;
pub mod tags;

pub use scatterscope_physics as physics;
