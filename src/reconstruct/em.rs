//! What both Richardson-Lucy variants ([`super::rl_sum`] on time-summed
//! bins, [`super::rl_stack`] on every bin) share: the multiplicative EM
//! step, a fixed number of steps, and the cross-validated search for when
//! to stop.

use ndarray::Array2;
use rayon::prelude::*;

use super::run::Run;
use crate::forward::ForwardModel;
use crate::poisson::deviance::point_deviance;

/// Guard of the RL denominator, relative to the mean count.
pub const DENOMINATOR_GUARD: f64 = 1e-6;

/// Iterations the cross-validated stop searches past its best so far:
/// at least this many, and at least a quarter of the best's count.
pub const CV_PATIENCE: usize = 25;

/// When Richardson-Lucy stops (its only regularisation is its iteration
/// count).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stopping {
    /// After this many iterations.
    After(usize),
    /// At the iteration chosen by two-fold cross-validation on thinned
    /// halves of the counts, searched up to `max_iters`.
    CrossValidated {
        /// The most iterations searched.
        max_iters: usize,
    },
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

/// `iterations` Richardson-Lucy steps of `o` (on the model's grid), each
/// by `step`, which returns the negative log-likelihood before it; one
/// trace row per step. Returns the estimate on the sensor window.
pub(crate) fn fixed_steps(
    model: &ForwardModel,
    mut o: Vec<f64>,
    iterations: usize,
    run: &mut Run<'_>,
    mut step: impl FnMut(&mut [f64]) -> f64,
) -> Array2<f64> {
    let (h, w) = model.sensor_shape();
    let crop = |o: &[f64]| Array2::from_shape_vec((h, w), model.crop_vec(o)).expect("shape");
    for it in 1..=iterations {
        let nll = step(&mut o);
        let mut row = run.row(it);
        row.objective = Some(nll);
        if run.scores() {
            run.score(&mut row, crop(&o).view());
        }
        run.push(row);
    }
    crop(&o)
}

/// The search both cross-validated Richardson-Lucy variants share: the two
/// halves' estimates `o` (on the model's grid) step together; before each
/// step `forward` predicts from each and `held_out(prediction, half)`
/// scores half `half`'s prediction on the other half's counts. The search
/// stops [`CV_PATIENCE`] iterations (or a quarter of the best count, if
/// more) past the best summed score, or at `max_iters`. Returns the best
/// iteration and the sum of the halves' estimates there on the sensor
/// window, with the stop's notes in `run`.
pub(crate) fn cv_search<Y: Send + Sync>(
    model: &ForwardModel,
    mut o: Vec<Vec<f64>>,
    max_iters: usize,
    run: &mut Run<'_>,
    forward: impl Fn(&[f64]) -> Y + Sync,
    held_out: impl Fn(&Y, usize) -> f64,
    update: impl Fn(usize, &mut [f64], &Y) + Sync,
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
        let mut row = run.row(it);
        row.objective = Some(score_cv);
        if improved || run.scores() {
            let estimate = crop_sum(&o);
            run.score(&mut row, estimate.view());
            if improved {
                best = (score_cv, it, estimate);
            }
        }
        run.push(row);
        if it == max_iters || it >= best.1 + CV_PATIENCE.max(best.1 / 4) {
            break;
        }
        o.par_iter_mut()
            .zip(y.par_iter())
            .enumerate()
            .for_each(|(half, (x, yx))| update(half, x, yx));
    }
    let (_, k, image) = best;
    run.note(format!(
        "stopped: iteration {k} predicted the held-back halves best (searched to {searched} of at most {max_iters}); the output is the sum of the two halves' estimates there"
    ));
    if k == max_iters {
        run.note(format!(
            "the cross-validated score was still falling at the cap of {max_iters} iterations: more may help (a higher cap: rl_max_iters)"
        ));
    }
    run.note(format!("output: iteration {k}"));
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
