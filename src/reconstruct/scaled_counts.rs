//! Scaled counts, the reference without deblurring: counts divided by the
//! kernel mass.

use ndarray::{Array3, ArrayView2, Axis};

use super::operator::Convolution;
use super::trace::{Trace, TraceRow};
use super::{ReconstructError, Reconstruction, finish, score, validate_counts};
use crate::forward::ForwardModel;

/// Sum of the counts of `bins`, less their background, divided by their
/// kernel mass (at least 0): the object estimate a perfectly sharp PSF
/// would give.
pub fn scaled_counts(
    model: &ForwardModel,
    counts: &Array3<f64>,
    bins: &[usize],
    truth: Option<ArrayView2<f64>>,
) -> Result<Reconstruction, ReconstructError> {
    validate_counts(counts)?;
    let mass = Convolution::from_bins(model, bins).mass();
    // The background of the summed bins is subtracted first.
    let bg = model.background() * bins.len() as f64;
    let image = counts.sum_axis(Axis(0)).mapv(|m| {
        if mass > 0.0 {
            ((m - bg) / mass).max(0.0)
        } else {
            0.0
        }
    });
    let image = finish(image, "scaled-counts", 0)?;
    let mut trace = Trace::new(if bins.len() == 1 {
        "scaled-counts"
    } else {
        "scaled-counts-sum"
    });
    let mut row = TraceRow::default();
    score(&mut row, image.view(), truth);
    trace.rows.push(row);
    trace.notes.push(format!(
        "kernel mass {mass:.4} photons per unit object pixel"
    ));
    Ok(Reconstruction { image, trace })
}
