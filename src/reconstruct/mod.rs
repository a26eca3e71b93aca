//! Reconstruction of the object from a transient stack.
//!
//! - [`split`]: Poisson Plug-and-Play ADMM with exact splitting (P4IP), the
//!   default PnP solver: closed-form Poisson prox, exact o-update.
//! - [`pnp`]: the paper's Algorithm 1 (L-BFGS o-update), with a data-driven
//!   stopping rule ([`discrepancy`]).
//! - [`richardson_lucy`]: the classical baseline, on one bin or on the
//!   time-summed stack.
//! - [`rl_stack`]: Richardson-Lucy on the whole stack, every bin with its
//!   own kernel.
//! - [`thinning`]: photon counts split into two independent halves, so
//!   that Richardson-Lucy can choose its own iteration count.
//! - [`scaled_counts`]: counts divided by kernel mass (no deblurring),
//!   for reference.
//!
//! Every method returns the image and a per-iteration [`trace::Trace`].

pub mod discrepancy;
pub mod likelihood;
pub mod method;
pub mod operator;
pub mod pnp;
pub mod problem;
pub mod richardson_lucy;
pub mod rl_stack;
pub mod scaled_counts;
pub mod split;
pub mod thinning;
pub mod trace;

use ndarray::{Array2, Array3, ArrayView2, Axis};

use crate::forward::{Boundary, ForwardModel};
use crate::metrics;
use trace::{Trace, TraceRow};

/// Why a reconstruction cannot run.
#[derive(Debug, thiserror::Error)]
pub enum ReconstructError {
    /// A count is NaN, infinite or negative.
    #[error(
        "counts: bin {bin}, row {row}, column {col} is {value}; counts must be finite and >= 0"
    )]
    InvalidCount {
        /// Bin index in the stack.
        bin: usize,
        /// Row.
        row: usize,
        /// Column.
        col: usize,
        /// The offending value.
        value: f64,
    },
    /// Cross-validation by thinning met a count that is not a whole number
    /// of photons.
    #[error(
        "cross-validation by thinning needs whole photon counts: row {row}, column {col} of {what} is {value} (expected counts, or a scaled or background-subtracted stack: stop Richardson-Lucy after a fixed count instead)"
    )]
    NotWholeCounts {
        /// The image (e.g. "the time-summed counts").
        what: String,
        /// Row.
        row: usize,
        /// Column.
        col: usize,
        /// The offending value.
        value: f64,
    },
    /// Stack and kernels do not fit together.
    #[error("{0}")]
    Shape(String),
    /// The optimiser reported an error.
    #[error("L-BFGS o-update: {0}")]
    Optimiser(String),
    /// A non-finite value appeared in the estimate.
    #[error("{method}: the estimate became non-finite at iteration {iteration}")]
    NonFinite {
        /// Method name.
        method: String,
        /// Iteration at which it happened.
        iteration: usize,
    },
}

/// A reconstructed image and how it was obtained.
#[derive(Debug, Clone)]
pub struct Reconstruction {
    /// The estimate of the object, finite and >= 0.
    pub image: Array2<f64>,
    /// Per-iteration trace.
    pub trace: Trace,
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

/// Checks the counts of a PnP run (finite, >= 0, one image per listed bin)
/// and names the method: `pnp` on several bins, `pnp-slice` on one.
pub(crate) fn pnp_method(
    counts: &Array3<f64>,
    bins: &[usize],
) -> Result<&'static str, ReconstructError> {
    validate_stack(counts, bins)?;
    Ok(if bins.len() == 1 { "pnp-slice" } else { "pnp" })
}

/// Checks a stack's counts (finite, >= 0) and that it holds one image per
/// listed bin.
pub(crate) fn validate_stack(counts: &Array3<f64>, bins: &[usize]) -> Result<(), ReconstructError> {
    validate_counts(counts)?;
    if counts.shape()[0] != bins.len() {
        return Err(ReconstructError::Shape(format!(
            "{} count images for {} kernels",
            counts.shape()[0],
            bins.len()
        )));
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

/// Says in the trace which background the likelihood holds, if any.
pub(crate) fn note_background(trace: &mut Trace, model: &ForwardModel) {
    let bg = model.background();
    if bg > 0.0 {
        trace.notes.push(format!(
            "background: {bg:.4e} counts per pixel and bin in the likelihood"
        ));
    }
}

/// Fills the truth-dependent columns of a trace row, scoring the estimate
/// clamped to >= 0 as every method outputs it.
pub(crate) fn score(row: &mut TraceRow, estimate: ArrayView2<f64>, truth: Option<ArrayView2<f64>>) {
    if let Some(t) = truth {
        let clamped = estimate.mapv(|v| v.max(0.0));
        row.psnr = Some(metrics::psnr(clamped.view(), t));
        row.ssim = Some(metrics::ssim(clamped.view(), t));
    }
}

/// The result for data without a single photon: the estimate is 0 and no
/// iteration can change it.
pub(crate) fn no_photons(
    mut trace: Trace,
    shape: (usize, usize),
    truth: Option<ArrayView2<f64>>,
) -> Reconstruction {
    trace.notes.push(
        "no photons: the maximum-likelihood object is 0 and no iteration can change it".into(),
    );
    let image = Array2::zeros(shape);
    let mut row = TraceRow::default();
    score(&mut row, image.view(), truth);
    trace.rows.push(row);
    Reconstruction { image, trace }
}

/// What the model assumes of the sensor's edges, for a trace note.
pub(crate) fn grid_note(model: &ForwardModel) -> String {
    let (h, w) = model.sensor_shape();
    let (gh, gw) = model.grid_shape();
    match model.boundary() {
        Boundary::Periodic => {
            format!("boundary: periodic (wrap-around) on the {h} x {w} sensor grid")
        }
        Boundary::Sensor => format!(
            "boundary: sensor with edges; object estimated on a {gh} x {gw} grid, {} px beyond each sensor edge (the kernels carry < {:e} of their light farther out; farther object points left out), output is the {h} x {w} sensor window",
            model.margin(),
            crate::forward::EDGE_TAIL
        ),
    }
}

/// Clamps an estimate to >= 0, failing on any non-finite value.
pub(crate) fn finish(
    image: Array2<f64>,
    method: &str,
    iteration: usize,
) -> Result<Array2<f64>, ReconstructError> {
    if image.iter().any(|v| !v.is_finite()) {
        return Err(ReconstructError::NonFinite {
            method: method.into(),
            iteration,
        });
    }
    Ok(image.mapv(|v| v.max(0.0)))
}
