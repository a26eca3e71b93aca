//! Richardson-Lucy deconvolution (the paper's baseline), on one bin or on
//! the time-summed stack with the time-summed kernel, stopped after a fixed
//! count or where two-fold cross-validation on thinned halves of the counts
//! says.

use std::time::Instant;

use ndarray::{Array2, Array3, ArrayView2, Axis};
use rayon::prelude::*;

use super::discrepancy::{m_log_m, point_deviance};
use super::operator::Convolution;
use super::thinning::{THINNING_SEED, thin_halves};
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
    let method = method_name(bins);
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
    let rl = RlOperator::new(model, bins);
    let data = counts.sum_axis(Axis(0));
    let (h, w) = data.dim();
    let m: Vec<f64> = data.iter().copied().collect();
    let total: f64 = m.iter().sum();
    if total == 0.0 || rl.mass <= 0.0 {
        return None;
    }
    // Background of the summed bins, per pixel: the data are
    // Poisson(H o + bg) and RL divides by H o + bg.
    let bg = model.background() * bins.len() as f64;
    let o = vec![flat_level(total, bg, 1, rl.mass, h * w); rl.sensitivity.len()];
    let guard = DENOMINATOR_GUARD * total / (h * w) as f64;
    trace.notes.push(format!(
        "denominator guarded at {guard:.3e} ({DENOMINATOR_GUARD:e} x mean count); 4 FFTs per iteration; {}",
        grid_note(model)
    ));
    note_background(trace, model);
    let step = |o: &mut [f64]| {
        let y = rl.op.apply(o);
        rl.update(o, &y, &m, bg, guard)
    };
    Some(fixed_steps(
        model,
        o,
        iterations,
        truth,
        start,
        trace,
        step,
        &mut on_iter,
    ))
}

/// `iterations` Richardson-Lucy steps of `o` (on the model's grid), each
/// by `step`, which returns the negative log-likelihood before it; one
/// trace row per step. Returns the estimate on the sensor window.
#[allow(clippy::too_many_arguments)]
pub(crate) fn fixed_steps(
    model: &ForwardModel,
    mut o: Vec<f64>,
    iterations: usize,
    truth: Option<ArrayView2<f64>>,
    start: Instant,
    trace: &mut Trace,
    mut step: impl FnMut(&mut [f64]) -> f64,
    on_iter: &mut dyn FnMut(&TraceRow),
) -> Array2<f64> {
    let (h, w) = model.sensor_shape();
    let crop = |o: &[f64]| Array2::from_shape_vec((h, w), model.crop_vec(o)).expect("shape");
    for it in 1..=iterations {
        let nll = step(&mut o);
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
    crop(&o)
}

/// Iterations the cross-validated stop searches past its best so far:
/// at least this many, and at least a quarter of the best's count.
pub const CV_PATIENCE: usize = 25;

/// Richardson-Lucy on the sum of `bins` that chooses its own iteration
/// count without a truth, by two-fold cross-validation: the summed counts
/// are thinned into two independent halves ([`thin_halves`]), RL runs on
/// each from its flat object, and after every iteration each half's
/// estimate predicts the other half's counts (the Poisson deviance of the
/// pair is the score). The search stops [`CV_PATIENCE`] iterations (or a
/// quarter of the best count, if more) past the best score, or at
/// `max_iters`; the output is the sum of the two halves' estimates at the
/// best iteration (an estimate of the whole light).
///
/// Early stopping is RL's only regularisation, and the best count ranges
/// from a few iterations on smooth scenes to hundreds on sharp or sparse
/// ones (BENCHMARKS.md: on the benchmark's held-out images this choice came
/// within 0.12-0.25 dB of the best iteration chosen with the truth on
/// average at each light level, and never more than 1.7 dB below it).
pub fn richardson_lucy_cv(
    model: &ForwardModel,
    counts: &Array3<f64>,
    bins: &[usize],
    max_iters: usize,
    truth: Option<ArrayView2<f64>>,
    mut on_iter: impl FnMut(&TraceRow),
) -> Result<Reconstruction, ReconstructError> {
    validate_counts(counts)?;
    let method = method_name(bins);
    let start = Instant::now();
    let (h, w) = model.sensor_shape();
    let mut trace = Trace::new(method);
    let rl = RlOperator::new(model, bins);
    let data = counts.sum_axis(Axis(0));
    let total = data.sum();
    if total == 0.0 || rl.mass <= 0.0 {
        return Ok(no_photons(trace, (h, w), truth));
    }
    let (first, second) = thin_halves(&data, THINNING_SEED, "the time-summed counts")?;
    let halves: [Vec<f64>; 2] = [
        first.iter().copied().collect(),
        second.iter().copied().collect(),
    ];
    let halves_log = halves
        .each_ref()
        .map(|m| m.iter().map(|&x| m_log_m(x)).collect::<Vec<f64>>());
    // Each half holds half the light and half the background.
    let bg = model.background() * bins.len() as f64 / 2.0;
    let guard = DENOMINATOR_GUARD * total / 2.0 / (h * w) as f64;
    let o: Vec<Vec<f64>> = halves
        .iter()
        .map(|m| vec![flat_level(m.iter().sum(), bg, 1, rl.mass, h * w); rl.sensitivity.len()])
        .collect();
    trace.notes.push(format!(
        "stop chosen by two-fold cross-validation: the counts thinned into two halves of {} and {} photons (seed {THINNING_SEED:#x}), RL on each, each scored on the other's counts; 8 FFTs per iteration; {}",
        first.sum(),
        second.sum(),
        grid_note(model)
    ));
    note_background(&mut trace, model);
    let (k, image) = cv_search(
        model,
        o,
        max_iters,
        truth,
        start,
        &mut trace,
        |x| rl.op.apply(x),
        |y, half| held_out_deviance(y, &halves[1 - half], &halves_log[1 - half], bg, guard),
        |half, x, y| {
            rl.update(x, y, &halves[half], bg, guard);
        },
        &mut on_iter,
    );
    let image = finish(image, method, k)?;
    Ok(Reconstruction { image, trace })
}

/// The search both cross-validated Richardson-Lucy variants share: the two
/// halves' estimates `o` (on the model's grid) step together; before each
/// step `forward` predicts from each and `held_out(prediction, half)`
/// scores half `half`'s prediction on the other half's counts. The search
/// stops [`CV_PATIENCE`] iterations (or a quarter of the best count, if
/// more) past the best summed score, or at `max_iters`. Returns the best
/// iteration and the sum of the halves' estimates there on the sensor
/// window, with the stop's notes in `trace`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn cv_search<Y: Send + Sync>(
    model: &ForwardModel,
    mut o: Vec<Vec<f64>>,
    max_iters: usize,
    truth: Option<ArrayView2<f64>>,
    start: Instant,
    trace: &mut Trace,
    forward: impl Fn(&[f64]) -> Y + Sync,
    held_out: impl Fn(&Y, usize) -> f64,
    update: impl Fn(usize, &mut [f64], &Y) + Sync,
    on_iter: &mut dyn FnMut(&TraceRow),
) -> (usize, Array2<f64>) {
    let (h, w) = model.sensor_shape();
    let crop_sum = |o: &[Vec<f64>]| {
        let sum: Vec<f64> = o[0].iter().zip(&o[1]).map(|(a, b)| a + b).collect();
        Array2::from_shape_vec((h, w), model.crop_vec(&sum)).expect("shape")
    };
    let mut best = (f64::INFINITY, 0usize, crop_sum(&o));
    let mut searched = 0;
    for it in 0..=max_iters {
        searched = it;
        // The two halves are independent: one core each.
        let y: Vec<Y> = o.par_iter().map(|x| forward(x)).collect();
        let score_cv = held_out(&y[0], 0) + held_out(&y[1], 1);
        let improved = score_cv < best.0;
        let mut row = TraceRow {
            iteration: it,
            wall_s: start.elapsed().as_secs_f64(),
            objective: Some(score_cv),
            ..Default::default()
        };
        if improved || truth.is_some() {
            let estimate = crop_sum(&o);
            score(&mut row, estimate.view(), truth);
            if improved {
                best = (score_cv, it, estimate);
            }
        }
        on_iter(&row);
        trace.rows.push(row);
        if it == max_iters || it >= best.1 + CV_PATIENCE.max(best.1 / 4) {
            break;
        }
        o.par_iter_mut()
            .zip(y.par_iter())
            .enumerate()
            .for_each(|(half, (x, yx))| update(half, x, yx));
    }
    let (_, k, image) = best;
    trace.notes.push(format!(
        "stopped: iteration {k} predicted the held-back halves best (searched to {searched} of at most {max_iters}); the output is the sum of the two halves' estimates there"
    ));
    if k == max_iters {
        trace.notes.push(format!(
            "the cross-validated score was still falling at the cap of {max_iters} iterations: more may help (a higher cap: rl_max_iters)"
        ));
    }
    trace.notes.push(format!("output: iteration {k}"));
    (k, image)
}

/// Poisson deviance of counts `m` (with `m log m` per point, computed once)
/// against the prediction `y + bg` (guarded below by `guard`): the score of
/// an estimate on counts it was not fitted to.
pub(crate) fn held_out_deviance(y: &[f64], m: &[f64], m_log_m: &[f64], bg: f64, guard: f64) -> f64 {
    y.iter()
        .zip(m)
        .zip(m_log_m)
        .map(|((&yj, &mj), &mlm)| {
            let d = (yj + bg).max(guard);
            point_deviance(mj, mlm, d, d.ln())
        })
        .sum()
}

/// The method's name in traces: `rl` on one bin, `rl-sum` on several.
fn method_name(bins: &[usize]) -> &'static str {
    if bins.len() == 1 { "rl" } else { "rl-sum" }
}

/// The operator of RL on a sum of bins, with its normaliser.
struct RlOperator {
    op: Convolution,
    /// Kernel mass.
    mass: f64,
    /// `H^T 1` over the window: the normaliser of RL with a sensor of
    /// finite size (Bertero and Boccacci 2005); the kernel mass for a
    /// periodic model.
    sensitivity: Vec<f64>,
}

impl RlOperator {
    fn new(model: &ForwardModel, bins: &[usize]) -> Self {
        let op = Convolution::from_bins(model, bins);
        Self {
            mass: op.mass(),
            sensitivity: op.sensitivity(),
            op,
        }
    }

    /// One RL step of `o` for counts `m` given `y = H o`: `o <- o H^T(m /
    /// (y + bg)) / H^T 1`, the denominator guarded at `guard`. Object pixels
    /// the sensor does not see keep their value. Returns the negative
    /// log-likelihood at `o` before the step.
    fn update(&self, o: &mut [f64], y: &[f64], m: &[f64], bg: f64, guard: f64) -> f64 {
        let mut nll = 0.0;
        let ratio: Vec<f64> = y
            .iter()
            .zip(m)
            .map(|(&yj, &mj)| {
                let d = (yj + bg).max(guard);
                nll += d - if mj > 0.0 { mj * d.ln() } else { 0.0 };
                mj / d
            })
            .collect();
        em_multiply(o, &self.op.adjoint(&ratio), &self.sensitivity, self.mass);
        nll
    }
}

/// The multiplicative EM step shared by both Richardson-Lucy variants:
/// `o <- o max(back / sensitivity, 0)` where `back` is the back-projected
/// ratio `H^T(m / (H o + b))` and `sensitivity` is `H^T 1`. Object pixels
/// the sensor does not see (sensitivity at most 1e-9 of the kernel mass
/// `mass`) keep their value.
pub(crate) fn em_multiply(o: &mut [f64], back: &[f64], sensitivity: &[f64], mass: f64) {
    let seen = 1e-9 * mass;
    o.iter_mut()
        .zip(back)
        .zip(sensitivity)
        .filter(|(_, s)| **s > seen)
        .for_each(|((oj, b), s)| *oj *= (b / s).max(0.0));
}
