//! scatterscope: time-resolved imaging through scattering media.
//!
//! Data flows one way: a source (simulation, device or recorded file)
//! produces photon tags, tags are binned into a transient stack, the stack
//! is reconstructed, and the result is reported.
//!
//! - [`scene`]: test objects (built-in patterns or image files).
//! - [`forward`]: ST-PSF convolution and Poisson sampling.
//! - [`events`]: photon time tags as every source produces them;
//!   [`formats`] reads and writes the files that hold them and stacks;
//!   [`tags`] bins them into stacks.
//! - [`stack`]: the K x H x W transient stack with its metadata, and its
//!   OpenEXR / .npy files and PNG previews.
//! - [`reconstruct`]: Poisson PnP-ADMM, Richardson-Lucy and raw baselines.
//! - [`poisson`]: what both share: thinning into halves, the Poisson
//!   deviance.
//! - [`confocal`]: confocal scans of hidden objects behind a slab,
//!   reconstructed into volumes.
//! - [`denoise`]: Gaussian denoisers plugged in as priors.
//! - [`metrics`]: PSNR and SSIM against a known truth.
//! - [`config`]: physics parameters from presets, TOML files and flags.
//! - [`batch`]: many commands from a manifest, locally or as a Slurm array.
//!
//! The physics itself lives in the `scatterscope-physics` crate, re-exported
//! as [`physics`]; the main types are re-exported here.
//!
//! # Simulate a measurement, then reconstruct it
//!
//! ```
//! use scatterscope::denoise::tv::TotalVariation;
//! use scatterscope::forward::poisson_counts;
//! use scatterscope::{
//!     Boundary, ForwardModel, KernelStack, Method, MethodOptions, Preset, Problem, Sampling,
//!     Scene, Stack, StackMeta, ValueKind, run_method,
//! };
//!
//! // The paper's slab and bins on a small 32 x 32 sensor.
//! let mut setup = Preset::Paper.setup();
//! (setup.sensor.width_px, setup.sensor.height_px) = (32, 32);
//! setup.sensor.fov_cm = 50.0 / 8.0;
//! let kernels = KernelStack::build(&setup, Sampling::Integrated)?;
//! let model = ForwardModel::new(&kernels, Boundary::Sensor);
//! let truth = Scene::parse("disks").render(32, 32)?;
//! let counts = poisson_counts(&model.expected_scene(truth.view()).counts, 7);
//! let stack = Stack::new(
//!     counts.mapv(|c| c as f32),
//!     StackMeta::simulated(&kernels, ValueKind::Counts, "example".into()),
//! );
//! let problem = Problem::new(&stack, &setup, Sampling::Integrated, Boundary::Sensor)?;
//! let mut opts = MethodOptions::default();
//! opts.split.max_iters = 10;
//! let prior = TotalVariation::default();
//! let result = run_method(&problem, Method::Pnp, None, &prior, &opts, None, |_| {})?;
//! assert_eq!(result.image.dim(), (32, 32));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Bin a recorded PicoQuant file
//!
//! ```
//! use scatterscope::formats::picoquant::writer::write_synthetic_t3;
//! use scatterscope::{BinSpec, bin_file};
//!
//! let path = std::env::temp_dir().join(format!("scatterscope-doc-{}.ptu", std::process::id()));
//! write_synthetic_t3(&path, 10_000)?;
//! // One time histogram over one sync period, at the file's resolution.
//! let binned = bin_file(&path, &BinSpec::default())?;
//! assert!(binned.counts.balances());
//! assert_eq!(binned.stacks[0].total() as u64, binned.counts.binned);
//! std::fs::remove_file(&path)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

pub mod acquire;
pub mod batch;
pub mod cache;
pub mod calibrate;
pub mod cnn;
pub mod config;
pub mod confocal;
pub mod decay;
pub mod denoise;
pub mod embedded;
pub mod error_text;
pub mod events;
pub mod fft2;
pub mod files;
pub mod font;
pub mod formats;
pub mod forward;
pub mod live;
pub mod memory;
pub mod metrics;
pub mod named;
pub mod plot;
pub mod poisson;
pub mod psf;
pub mod reconstruct;
pub mod report;
pub mod scene;
pub mod simulate;
pub mod stack;
pub mod tags;
pub mod time_basis;
pub mod units;

pub use scatterscope_physics as physics;

pub use error_text::error_text;
pub use forward::{Boundary, ForwardModel};
pub use named::Named;
pub use reconstruct::method::{Method, MethodOptions, run_method};
pub use reconstruct::problem::Problem;
pub use scatterscope_physics::{KernelStack, Preset, Sampling, Setup};
pub use scene::Scene;
pub use stack::{Stack, StackMeta, ValueKind};
pub use tags::bin_file::{BinSpec, BinnedFile, bin_file, bin_file_counts};
pub use tags::binning::{Binner, TimeWindow};
pub use tags::counts::Counts;
