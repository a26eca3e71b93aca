//! A scene behind the medium, seen by the sensor: the expected stack and a
//! Poisson draw of it, each with its metadata. What `scatterscope
//! simulate` writes and the report starts from.

use std::time::Instant;

use ndarray::Array2;
use scatterscope_physics::{KernelStack, ParamError, Sampling, Setup};

use crate::forward::{Boundary, ForwardModel, poisson_counts};
use crate::scene::{ImageError, Scene};
use crate::stack::{Stack, StackMeta, ValueKind};

/// A simulated measurement.
pub struct Simulation {
    /// The scene on the sensor grid (values in [0, 1]).
    pub truth: Array2<f64>,
    /// The kept ST-PSF kernels.
    pub kernels: KernelStack,
    /// The forward model the stacks came from.
    pub model: ForwardModel,
    /// Noise-free expected counts.
    pub expected: Stack,
    /// One Poisson draw of `expected`.
    pub counts: Stack,
    /// Expected-count values FFT round-off made negative and were set to 0.
    pub clamped: usize,
    /// The most negative of those before clamping (0 when none).
    pub most_negative: f64,
    /// Wall time of each step.
    pub timings: SimulationTimings,
}

/// Seconds spent in each step of [`simulate`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SimulationTimings {
    /// Building the ST-PSF kernels.
    pub psf_s: f64,
    /// Transforming the kernels.
    pub spectra_s: f64,
    /// The forward model (expected counts).
    pub forward_s: f64,
    /// The Poisson draw.
    pub poisson_s: f64,
}

/// Why a simulation cannot run.
#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    /// The physics is invalid.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// The scene cannot be rendered.
    #[error(transparent)]
    Scene(#[from] ImageError),
    /// Every bin falls below the light threshold.
    #[error("no bin carries at least {min_bin_photons} expected photons")]
    NoBins {
        /// The threshold of the set-up.
        min_bin_photons: f64,
    },
}

/// Simulates `scene` through `setup`'s medium onto its sensor with edges
/// modelled by `boundary`, and draws Poisson counts with `seed`.
pub fn simulate(
    setup: &Setup,
    scene: &Scene,
    sampling: Sampling,
    boundary: Boundary,
    seed: u64,
) -> Result<Simulation, SimulateError> {
    let t = Instant::now();
    let kernels = KernelStack::build(setup, sampling)?;
    let psf_s = t.elapsed().as_secs_f64();
    if kernels.is_empty() {
        return Err(SimulateError::NoBins {
            min_bin_photons: setup.min_bin_photons,
        });
    }
    let truth = scene.render(setup.sensor.height_px, setup.sensor.width_px)?;
    let t = Instant::now();
    let model = ForwardModel::new(&kernels, boundary);
    let spectra_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let expected = model.expected_scene(truth.view());
    let forward_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let counts = poisson_counts(&expected.counts, seed);
    let poisson_s = t.elapsed().as_secs_f64();
    let source = format!("simulated scene {}", scene.name());
    let mut meta = StackMeta::simulated(&kernels, ValueKind::ExpectedCounts, source);
    meta.clamped_negative = expected.clamped as u64;
    meta.boundary = Some(boundary);
    let expected_stack = Stack {
        data: expected.counts.mapv(|v| v as f32),
        meta: meta.clone(),
    };
    meta.kind = ValueKind::Counts;
    meta.seed = Some(seed);
    Ok(Simulation {
        truth,
        kernels,
        model,
        expected: expected_stack,
        counts: Stack {
            data: counts.mapv(|v| v as f32),
            meta,
        },
        clamped: expected.clamped,
        most_negative: expected.most_negative,
        timings: SimulationTimings {
            psf_s,
            spectra_s,
            forward_s,
            poisson_s,
        },
    })
}
