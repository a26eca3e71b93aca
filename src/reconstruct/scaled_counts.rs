//! Scaled counts, the reference without deblurring: counts divided by the
//! kernel mass.

use ndarray::Axis;

use super::data::Data;
use super::error::ReconstructError;
use super::operator::Convolution;
use super::run::{Estimate, Reconstructor, Run, WorkShape};
use super::trace::TraceRow;

/// Sum of the counts of the data's bins, less their background, divided
/// by their kernel mass (at least 0): the object estimate a perfectly
/// sharp PSF would give.
#[derive(Debug, Clone, Copy, Default)]
pub struct ScaledCounts;

impl Reconstructor for ScaledCounts {
    fn name(&self, bins: usize) -> &'static str {
        if bins == 1 {
            "scaled-counts"
        } else {
            "scaled-counts-sum"
        }
    }

    fn reconstruct(
        &self,
        data: &Data<'_>,
        run: &mut Run<'_>,
    ) -> Result<Estimate, ReconstructError> {
        let mass = Convolution::from_bins(data.model, data.bins).mass();
        // The background of the summed bins is subtracted first.
        let bg = data.model.background() * data.bins.len() as f64;
        let image = data.counts.sum_axis(Axis(0)).mapv(|m| {
            if mass > 0.0 {
                ((m - bg) / mass).max(0.0)
            } else {
                0.0
            }
        });
        let mut row = TraceRow::default();
        run.score(&mut row, image.view());
        run.push(row);
        run.note(format!(
            "kernel mass {mass:.4} photons per unit object pixel"
        ));
        Ok(Estimate {
            image,
            iteration: 0,
        })
    }

    /// The summed counts and the scaled image (sensor), the sensitivity
    /// (grid).
    fn working_bytes(&self, shape: &WorkShape) -> u64 {
        shape.bytes([0; 3], [24, 4, 0])
    }
}
