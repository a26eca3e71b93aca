//! A stack matched with the kernels of its physics: what every method needs.

use ndarray::{Array2, Array3};
use scatterscope_physics::{KernelStack, Sampling, Setup};

use crate::forward::ForwardModel;
use crate::stack::{Stack, ValueKind};

/// Counts and the forward model of exactly the stack's bins.
pub struct Problem {
    /// Kernel spectra of the stack's bins, in stack order.
    pub model: ForwardModel,
    /// The counts, K x H x W.
    pub counts: Array3<f64>,
    /// Start of each bin (ps).
    pub bin_starts_ps: Vec<f64>,
    /// The physics used.
    pub setup: Setup,
}

/// Why a stack and a physics setup do not fit together.
#[derive(Debug, thiserror::Error)]
pub enum ProblemError {
    /// The mismatch, naming both values.
    #[error("{0}")]
    Mismatch(String),
    /// Invalid physics.
    #[error(transparent)]
    Param(#[from] scatterscope_physics::ParamError),
}

impl Problem {
    /// Matches each bin of `stack` with the kernel of `setup` that starts at
    /// the same time. Kernels are built for every bin of the setup (none
    /// dropped, so that the light budget normalisation is the recorded one)
    /// but only the stack's bins are transformed.
    pub fn new(stack: &Stack, setup: &Setup, sampling: Sampling) -> Result<Self, ProblemError> {
        if stack.meta.kind == ValueKind::Kernel {
            return Err(ProblemError::Mismatch(
                "the stack holds ST-PSF kernels, not counts".into(),
            ));
        }
        let (_, h, w) = stack.data.dim();
        if (setup.sensor.height_px, setup.sensor.width_px) != (h, w) {
            return Err(ProblemError::Mismatch(format!(
                "the stack is {h} x {w} pixels but the physics sensor is {} x {} (set --size)",
                setup.sensor.height_px, setup.sensor.width_px
            )));
        }
        let width = setup.bins.width_ps;
        if (stack.meta.bin_width_ps - width).abs() > 1e-9 * width {
            return Err(ProblemError::Mismatch(format!(
                "the stack's bins are {} ps wide but the physics uses {width} ps (set --bin-width)",
                stack.meta.bin_width_ps
            )));
        }
        let mut all = *setup;
        all.min_bin_photons = 0.0;
        let kernels = KernelStack::build(&all, sampling)?;
        let positions = stack
            .meta
            .bin_starts_ps
            .iter()
            .enumerate()
            .map(|(i, &start)| {
                let index = ((start - setup.bins.start_ps) / width).round();
                let matches = index >= 0.0
                    && (index as usize) < setup.bins.count
                    && (setup.bins.edges_ps(index as usize).0 - start).abs() <= 1e-6 * width;
                matches
                    .then(|| kernels.position_of_bin(index as usize))
                    .flatten()
                    .ok_or_else(|| {
                        ProblemError::Mismatch(format!(
                            "stack bin {i} starts at {start} ps, which is not a bin of the physics ({} x {width} ps from {} ps) that receives photons",
                            setup.bins.count, setup.bins.start_ps
                        ))
                    })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            model: ForwardModel::with_bins(&kernels, &positions),
            counts: stack.data.mapv(f64::from),
            bin_starts_ps: stack.meta.bin_starts_ps.clone(),
            setup: *setup,
        })
    }

    /// Indices of all bins, `0..K`.
    pub fn all_bins(&self) -> Vec<usize> {
        (0..self.counts.shape()[0]).collect()
    }

    /// The counts of bin `k` alone, as a 1 x H x W stack.
    pub fn single_bin(&self, k: usize) -> Array3<f64> {
        let img: Array2<f64> = self.counts.index_axis(ndarray::Axis(0), k).to_owned();
        img.insert_axis(ndarray::Axis(0))
    }
}
