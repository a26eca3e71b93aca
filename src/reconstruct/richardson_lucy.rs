//! Richardson-Lucy deconvolution (the paper's baseline), on one bin or on
//! the time-summed stack with the time-summed kernel.

use std::time::Instant;

use ndarray::{Array2, Array3, ArrayView2, Axis};

use super::operator::Convolution;
use super::trace::{Trace, TraceRow};
use super::{
    ReconstructError, Reconstruction, finish, flat_level, grid_note, no_photons, note_background,
    score, validate_counts,
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
    on_iter: impl FnMut(&TraceRow),
) -> Result<Reconstruction, ReconstructError> {
    validate_counts(counts)?;
    let method = if bins.len() == 1 { "rl" } else { "rl-sum" };
    let (h, w) = model.sensor_shape();
    let mut trace = Trace::new(method);
    let Some(o) = rl_steps(model, counts, bins, iterations, truth, &mut trace, on_iter) else {
        return Ok(no_photons(trace, (h, w), truth));
    };
    let image = finish(o, method, iterations)?;
    Ok(Reconstruction { image, trace })
}

/// The RL steps of [`richardson_lucy`] from the flat object: the estimate
/// on the sensor window (the model's grid beyond it is iterated too, not
/// returned); rows and notes go to `trace`. `None` without photons or
/// kernel mass.
pub(crate) fn rl_steps(
    model: &ForwardModel,
    counts: &Array3<f64>,
    bins: &[usize],
    iterations: usize,
    truth: Option<ArrayView2<f64>>,
    trace: &mut Trace,
    mut on_iter: impl FnMut(&TraceRow),
) -> Option<Array2<f64>> {
    let start = Instant::now();
    let op = Convolution::from_bins(model, bins);
    let data = counts.sum_axis(Axis(0));
    let (h, w) = data.dim();
    let (gh, gw) = model.grid_shape();
    let m: Vec<f64> = data.iter().copied().collect();
    let total: f64 = m.iter().sum();
    let mass = op.mass();
    if total == 0.0 || mass <= 0.0 {
        return None;
    }
    // H^T 1 over the window: the normaliser of RL with a sensor of finite
    // size (Bertero and Boccacci 2005); the kernel mass for a periodic model.
    // Object pixels the sensor does not see keep their value.
    let sensitivity = op.sensitivity();
    let seen = 1e-9 * mass;
    // Background of the summed bins, per pixel: the data are
    // Poisson(H o + bg) and RL divides by H o + bg.
    let bg = model.background() * bins.len() as f64;
    let mut o = vec![flat_level(total, bg, 1, mass, h * w); gh * gw];
    let guard = DENOMINATOR_GUARD * total / (h * w) as f64;
    trace.notes.push(format!(
        "denominator guarded at {guard:.3e} ({DENOMINATOR_GUARD:e} x mean count); 4 FFTs per iteration; {}",
        grid_note(model)
    ));
    note_background(trace, model);
    let crop = |o: &[f64]| Array2::from_shape_vec((h, w), model.crop_vec(o)).expect("shape");
    for it in 1..=iterations {
        let y = op.apply(&o);
        let mut nll = 0.0;
        let ratio: Vec<f64> = y
            .iter()
            .zip(&m)
            .map(|(&yj, &mj)| {
                let d = (yj + bg).max(guard);
                nll += d - if mj > 0.0 { mj * d.ln() } else { 0.0 };
                mj / d
            })
            .collect();
        let back = op.adjoint(&ratio);
        o.iter_mut()
            .zip(&back)
            .zip(&sensitivity)
            .filter(|(_, s)| **s > seen)
            .for_each(|((oj, b), s)| *oj *= (b / s).max(0.0));
        let mut row = TraceRow {
            iteration: it,
            wall_s: start.elapsed().as_secs_f64(),
            objective: Some(nll),
            ..Default::default()
        };
        if truth.is_some() {
            score(&mut row, crop(&o).view(), truth);
        }
        on_iter(&row);
        trace.rows.push(row);
    }
    Some(crop(&o))
}
