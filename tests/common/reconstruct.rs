//! One method run on counts of some bins of a model, as the tests of the
//! methods call it.

use ndarray::{Array3, ArrayView2};
use scatterscope::forward::ForwardModel;
use scatterscope::reconstruct::{Data, ReconstructError, Reconstruction, Reconstructor};

/// Runs `method` on `counts` (one image per entry of `bins` of `model`),
/// scored against `truth` when given.
pub fn reconstruct(
    method: &dyn Reconstructor,
    model: &ForwardModel,
    counts: &Array3<f64>,
    bins: &[usize],
    truth: Option<ArrayView2<f64>>,
) -> Result<Reconstruction, ReconstructError> {
    method.run(&Data::new(model, counts, bins)?, truth, &mut |_| {})
}
