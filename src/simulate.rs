//! A scene behind the medium, seen by the sensor: the expected stack and a
//! Poisson draw of it, each with its metadata. What `scatterscope
//! simulate` writes and the report starts from.

use std::path::{Path, PathBuf};
use std::time::Instant;

use ndarray::Array2;
use scatterscope_physics::{KernelStack, ParamError, Sampling, Setup};

use crate::formats::png::SheetScale;
use crate::forward::{Boundary, ForwardModel, poisson_counts};
use crate::scene::{ImageError, Scene};
use crate::stack::{Stack, StackError, StackMeta, ValueKind};

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
    /// More memory than the budget.
    #[error(transparent)]
    Memory(#[from] crate::memory::MemoryError),
    /// The physics is invalid.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// The scene cannot be rendered.
    #[error(transparent)]
    Scene(#[from] ImageError),
    /// A caller's image does not fit the sensor or holds bad values.
    #[error("{0}")]
    Image(String),
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
    setup.validate()?;
    // The budget before the scene is rendered at the sensor's size.
    crate::memory::check_setup(setup, crate::memory::SIMULATE_BYTES, "a simulation")?;
    let truth = scene.render(setup.sensor.height_px, setup.sensor.width_px)?;
    let source = format!("simulated scene {}", scene.name());
    simulate_image(setup, truth, sampling, boundary, seed, source)
}

/// Simulates the image `truth` (the sensor's `setup` size, values >= 0)
/// as [`simulate`] does a scene; `source` names it in the stacks' records.
pub fn simulate_image(
    setup: &Setup,
    truth: Array2<f64>,
    sampling: Sampling,
    boundary: Boundary,
    seed: u64,
    source: String,
) -> Result<Simulation, SimulateError> {
    setup.validate()?;
    let (h, w) = (setup.sensor.height_px, setup.sensor.width_px);
    if truth.dim() != (h, w) {
        return Err(SimulateError::Image(format!(
            "the image is {} x {} (rows x columns); the sensor is {h} x {w}",
            truth.dim().0,
            truth.dim().1
        )));
    }
    if let Some(v) = truth.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
        return Err(SimulateError::Image(format!(
            "the image holds {v}: intensities must be finite and >= 0"
        )));
    }
    crate::memory::check_setup(setup, crate::memory::SIMULATE_BYTES, "a simulation")?;
    let t = Instant::now();
    let kernels = KernelStack::build(setup, sampling)?;
    let psf_s = t.elapsed().as_secs_f64();
    if kernels.is_empty() {
        return Err(SimulateError::NoBins {
            min_bin_photons: setup.min_bin_photons,
        });
    }
    through_kernels(kernels, truth, boundary, seed, psf_s, source)
}

/// The expected and Poisson counts of `truth` through `kernels`.
fn through_kernels(
    kernels: KernelStack,
    truth: Array2<f64>,
    boundary: Boundary,
    seed: u64,
    psf_s: f64,
    source: String,
) -> Result<Simulation, SimulateError> {
    let t = Instant::now();
    let model = ForwardModel::new(&kernels, boundary);
    let spectra_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let expected = model.expected_scene(truth.view());
    let forward_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let counts = poisson_counts(&expected.counts, seed);
    let poisson_s = t.elapsed().as_secs_f64();
    let mut meta = StackMeta::simulated(&kernels, ValueKind::ExpectedCounts, source);
    meta.clamped_negative = expected.clamped as u64;
    meta.boundary = Some(boundary);
    let expected_stack = Stack::new(expected.counts.mapv(|v| v as f32), meta.clone());
    meta.kind = ValueKind::Counts;
    meta.seed = Some(seed);
    Ok(Simulation {
        truth,
        kernels,
        model,
        expected: expected_stack,
        counts: Stack::new(counts.mapv(|v| v as f32), meta),
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

impl Simulation {
    /// Writes `truth.{exr,png}`, `expected.{exr,png}` and `counts.{exr,png}`
    /// (and `.npy` copies of both stacks with `npy`) into `dir` (created if
    /// missing); returns the files.
    pub fn write(
        &self,
        dir: &Path,
        npy: bool,
        scale: SheetScale,
    ) -> Result<Vec<PathBuf>, StackError> {
        std::fs::create_dir_all(dir).map_err(|e| StackError::io(dir, e))?;
        let truth = dir.join("truth.exr");
        crate::formats::exr::write_image(self.truth.mapv(|v| v as f32).view(), &truth)?;
        let png = dir.join("truth.png");
        crate::formats::png::write_png(self.truth.view(), Some(1.0), &png)?;
        let mut files = vec![truth, png];
        for (name, stack) in [("expected", &self.expected), ("counts", &self.counts)] {
            let exr = dir.join(format!("{name}.exr"));
            stack.save(&exr)?;
            let sheet = dir.join(format!("{name}.png"));
            crate::formats::png::write_contact_sheet(stack, scale, &sheet)?;
            files.extend([exr, sheet]);
            if npy {
                let file = dir.join(format!("{name}.npy"));
                stack.save(&file)?;
                files.push(file);
            }
        }
        Ok(files)
    }

    /// What was simulated, one line each: the scene, bins and photons, a
    /// table per bin, clamped round-off and the run times.
    pub fn summary(&self, scene: &Scene, seed: u64) -> Vec<String> {
        let setup = &self.kernels.setup;
        let (expected, counts) = (&self.expected, &self.counts);
        let mut lines = vec![
            format!(
                "scene {} at {}x{}: {} bins kept of {}, expected {:.1} photons, sampled {} (seed {seed})",
                scene.name(),
                setup.sensor.width_px,
                setup.sensor.height_px,
                self.kernels.len(),
                setup.bins.count,
                expected.total(),
                counts.total(),
            ),
            format!(
                "{:>3} {:>8} {:>12} {:>10} {:>10}",
                "bin", "start ps", "expected", "counts", "max count"
            ),
        ];
        let sum = |s: &Stack, k: usize| s.bin(k).iter().map(|&v| f64::from(v)).sum::<f64>();
        for k in 0..counts.bins() {
            let max = counts.bin(k).iter().fold(0.0f32, |m, &v| m.max(v));
            lines.push(format!(
                "{:>3} {:>8.1} {:>12.1} {:>10} {:>10}",
                k,
                counts.meta.bin_starts_ps[k],
                sum(expected, k),
                sum(counts, k),
                max
            ));
        }
        if self.clamped > 0 {
            lines.push(format!(
                "clamped {} expected-count values made negative by FFT round-off (most negative {:.3e}) to 0",
                self.clamped, self.most_negative
            ));
        }
        let t = self.timings;
        lines.push(format!(
            "run time: PSF {:.1} ms, kernel spectra {:.1} ms, forward model {:.1} ms, Poisson {:.1} ms",
            t.psf_s * 1e3,
            t.spectra_s * 1e3,
            t.forward_s * 1e3,
            t.poisson_s * 1e3
        ));
        lines
    }
}
