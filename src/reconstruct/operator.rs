//! One blur operator `H` (and its adjoint) from cached kernel spectra.

use crate::forward::ForwardModel;

/// Convolution with one kernel, observed on the sensor window: a single bin,
/// or the sum of several bins (the time-summed kernel), whose spectrum is
/// the sum of theirs.
pub struct Convolution {
    model: ForwardModel,
}

impl Convolution {
    /// The operator of the sum of kept bins `bins` of `model`.
    pub fn from_bins(model: &ForwardModel, bins: &[usize]) -> Self {
        Self {
            model: model.summed(bins),
        }
    }

    /// Kernel mass: the sum of the kernel (the light of a unit object pixel
    /// over the whole plane).
    pub fn mass(&self) -> f64 {
        self.model.mass(0)
    }

    /// `H^T 1_window` on the grid: the light of each object pixel the
    /// sensor sees.
    pub fn sensitivity(&self) -> Vec<f64> {
        self.model.sensitivity(&[0])
    }

    /// `H x`: grid -> sensor window (2 FFTs).
    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        self.model.apply(0, x)
    }

    /// `H^T r`: sensor window -> grid, correlation with the kernel (2 FFTs).
    pub fn adjoint(&self, r: &[f64]) -> Vec<f64> {
        self.model.adjoint(0, r)
    }
}
