//! Richardson-Lucy deconvolution (the paper's baseline), on one bin or on
//! the time-summed stack with the time-summed kernel.

use std::time::Instant;

use ndarray::{Array2, Array3, ArrayView2, Axis};

use super::operator::Convolution;
use super::trace::{Trace, TraceRow};
use super::{
    ReconstructError, Reconstruction, finish, flat_level, no_photons, score, validate_counts,
};
use crate::forward::ForwardModel;

/// Guard of the RL denominator, relative to the mean count.
pub const DENOMINATOR_GUARD: f64 = 1e-6;

/// `iterations` RL steps on the sum of `bins` (one bin: the single-bin
/// baseline; all bins: RL on the time-summed image).
pub fn richardson_lucy(
    model: &ForwardModel,
    counts: &Array3<f64>,
    bins: &[usize],
    iterations: usize,
    truth: Option<ArrayView2<f64>>,
    mut on_iter: impl FnMut(&TraceRow),
) -> Result<Reconstruction, ReconstructError> {
    validate_counts(counts)?;
    let method = if bins.len() == 1 { "rl" } else { "rl-sum" };
    let start = Instant::now();
    let op = Convolution::from_bins(model, bins);
    let data = counts.sum_axis(Axis(0));
    let (h, w) = data.dim();
    let n = h * w;
    let m: Vec<f64> = data.iter().copied().collect();
    let total: f64 = m.iter().sum();
    let mass = op.mass();
    let mut trace = Trace::new(method);
    if total == 0.0 || mass <= 0.0 {
        return Ok(no_photons(trace, (h, w), truth));
    }
    let mut o = vec![flat_level(total, mass, n); n];
    let guard = DENOMINATOR_GUARD * total / n as f64;
    trace.notes.push(format!(
        "denominator guarded at {guard:.3e} ({DENOMINATOR_GUARD:e} x mean count); 4 FFTs per iteration"
    ));
    for it in 1..=iterations {
        let y = op.apply(&o);
        let mut nll = 0.0;
        let ratio: Vec<f64> = y
            .iter()
            .zip(&m)
            .map(|(&yj, &mj)| {
                let d = yj.max(guard);
                nll += d - if mj > 0.0 { mj * d.ln() } else { 0.0 };
                mj / d
            })
            .collect();
        let back = op.adjoint(&ratio);
        o.iter_mut()
            .zip(&back)
            .for_each(|(oj, b)| *oj *= (b / mass).max(0.0));
        let image = Array2::from_shape_vec((h, w), o.clone()).expect("shape");
        let mut row = TraceRow {
            iteration: it,
            wall_s: start.elapsed().as_secs_f64(),
            objective: Some(nll),
            ..Default::default()
        };
        score(&mut row, image.view(), truth);
        on_iter(&row);
        trace.rows.push(row);
    }
    let image = finish(
        Array2::from_shape_vec((h, w), o).expect("shape"),
        method,
        iterations,
    )?;
    Ok(Reconstruction { image, trace })
}
