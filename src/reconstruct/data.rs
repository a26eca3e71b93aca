//! What every method reconstructs from: a forward model, the counts of
//! some of its bins, checked once.

use ndarray::{Array3, Axis};

use super::error::ReconstructError;
use crate::forward::ForwardModel;

/// Counts and the model that explains them: `counts` holds one sensor
/// image per entry of `bins`, the model's kept bins they were measured in.
#[derive(Clone, Copy)]
pub struct Data<'a> {
    /// The forward model (kernels, sensor window, background).
    pub model: &'a ForwardModel,
    /// One count image per listed bin, finite and >= 0.
    pub counts: &'a Array3<f64>,
    /// The model's bins the images belong to.
    pub bins: &'a [usize],
}

impl<'a> Data<'a> {
    /// Checks that `counts` are finite and >= 0 and hold one image per
    /// entry of `bins`.
    pub fn new(
        model: &'a ForwardModel,
        counts: &'a Array3<f64>,
        bins: &'a [usize],
    ) -> Result<Self, ReconstructError> {
        validate_counts(counts)?;
        if counts.shape()[0] != bins.len() {
            return Err(ReconstructError::Shape(format!(
                "{} count images for {} kernels",
                counts.shape()[0],
                bins.len()
            )));
        }
        Ok(Self {
            model,
            counts,
            bins,
        })
    }

    /// The sum of every count.
    pub fn total(&self) -> f64 {
        self.counts.sum()
    }
}

/// Rejects counts that are not finite non-negative numbers.
pub fn validate_counts(counts: &Array3<f64>) -> Result<(), ReconstructError> {
    for (bin, img) in counts.axis_iter(Axis(0)).enumerate() {
        if let Some(((row, col), &value)) = img
            .indexed_iter()
            .find(|(_, v)| !v.is_finite() || **v < 0.0)
        {
            return Err(ReconstructError::InvalidCount {
                bin,
                row,
                col,
                value,
            });
        }
    }
    Ok(())
}

/// Share of the total count kept as signal when the background explains
/// all of it (so that starting levels stay positive).
pub const SIGNAL_FLOOR: f64 = 1e-3;

/// Least-squares flat object for the data: the counts the object explains
/// (the total less `background` per pixel in each of `bins` bins, at least
/// [`SIGNAL_FLOOR`] of the total) over (mass x pixels); 0 without mass.
pub fn flat_level(
    total_counts: f64,
    background: f64,
    bins: usize,
    mass: f64,
    pixels: usize,
) -> f64 {
    let signal =
        (total_counts - background * (bins * pixels) as f64).max(SIGNAL_FLOOR * total_counts);
    if mass > 0.0 {
        signal / (mass * pixels as f64)
    } else {
        0.0
    }
}
