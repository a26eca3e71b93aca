//! Richardson-Lucy deconvolution (the paper's baseline), on one bin or on
//! the time-summed stack with the time-summed kernel, stopped after a fixed
//! count or where two-fold cross-validation on thinned halves of the counts
//! says.

use ndarray::{Array2, Array3, Axis};

use super::data::{Data, flat_level};
use super::em::{
    Acceleration, CvBest, DENOMINATOR_GUARD, Keep, RlStop, cv_search, em_multiply, fixed_steps,
    half_scores,
};
use super::error::ReconstructError;
use super::operator::Convolution;
use super::run::{Estimate, Reconstructor, Run, WorkShape, grid_note};
use crate::forward::ForwardModel;
use crate::poisson::deviance::m_log_m;
use crate::poisson::thinning::{THINNING_SEED, thin_halves};

/// Richardson-Lucy on the sum of the data's bins (one bin: the single-bin
/// baseline; all bins: RL on the time-summed image).
///
/// With [`RlStop::CrossValidated`] it chooses its own iteration count
/// without a truth, by two-fold cross-validation: the summed counts are
/// thinned into two independent halves ([`thin_halves`]), RL runs on each
/// from its flat object, and after every iteration each half's estimate
/// predicts the other half's counts (the Poisson deviance of the pair is
/// the score). The search stops [`super::em::CV_PATIENCE`] iterations (or
/// a quarter of the best count, if more) past the best score, or at
/// `max_iters`; the output is the sum of the two halves' estimates at the
/// best iteration (an estimate of the whole light).
///
/// Early stopping is RL's only regularisation, and the best count ranges
/// from a few iterations on smooth scenes to hundreds on sharp or sparse
/// ones (BENCHMARKS.md: on the benchmark's held-out images this choice came
/// within 0.12-0.25 dB of the best iteration chosen with the truth on
/// average at each light level, and never more than 1.7 dB below it).
#[derive(Debug, Clone, Copy)]
pub struct RlSum {
    /// When it stops.
    pub stop: RlStop,
}

impl Reconstructor for RlSum {
    fn name(&self, bins: usize) -> &'static str {
        if bins == 1 { "rl" } else { "rl-sum" }
    }

    fn reconstruct(
        &self,
        data: &Data<'_>,
        run: &mut Run<'_>,
    ) -> Result<Estimate, ReconstructError> {
        match self.stop {
            RlStop::After(iterations) => {
                let Some(image) = rl_steps(data.model, data.counts, data.bins, iterations, run)
                else {
                    return Ok(run.no_photons(data.model.sensor_shape()));
                };
                Ok(Estimate {
                    image,
                    iteration: iterations,
                })
            }
            RlStop::CrossValidated {
                max_iters,
                acceleration,
            } => cross_validated(data, max_iters, acceleration, run),
        }
    }

    /// One image however many bins: the summed counts, their halves and
    /// predictions (sensor), the two estimates and the correlations (grid),
    /// the summed kernel's spectrum and the transforms' buffers.
    fn working_bytes(&self, shape: &WorkShape) -> u64 {
        shape.bytes([0; 3], [64, 80, 64])
    }
}

/// `iterations` RL steps on the sum of `bins` from the flat object: the
/// estimate on the sensor window (the model's grid beyond it is iterated
/// too, not returned); rows and notes go to `run`. `None` without photons
/// or kernel mass.
pub(crate) fn rl_steps(
    model: &ForwardModel,
    counts: &Array3<f64>,
    bins: &[usize],
    iterations: usize,
    run: &mut Run<'_>,
) -> Option<Array2<f64>> {
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
    run.note(format!(
        "denominator guarded at {guard:.3e} ({DENOMINATOR_GUARD:e} x mean count); 4 FFTs per iteration; {}",
        grid_note(model)
    ));
    run.note_background(model);
    let step = |o: &mut [f64]| {
        let y = rl.op.apply(o);
        rl.update(o, &y, &m, bg, guard, true)
    };
    Some(fixed_steps(model, o, iterations, run, step))
}

/// The cross-validated stop (see [`RlSum`]).
fn cross_validated(
    data: &Data<'_>,
    max_iters: usize,
    acceleration: Acceleration,
    run: &mut Run<'_>,
) -> Result<Estimate, ReconstructError> {
    let rl = RlOperator::new(data.model, data.bins);
    let summed = data.counts.sum_axis(Axis(0));
    if summed.sum() == 0.0 || rl.mass <= 0.0 {
        return Ok(run.no_photons(data.model.sensor_shape()));
    }
    let ([first, second], how) = thinned_halves(&summed)?;
    let best = search_halves(
        data,
        &rl,
        [&first, &second],
        None,
        &how,
        (max_iters, acceleration),
        Keep::NOTHING,
        run,
    );
    Ok(Estimate {
        image: best.image,
        iteration: best.iteration,
    })
}

/// The summed counts thinned into the cross-validated search's two halves
/// (seed [`THINNING_SEED`]), with the words that say so.
pub(crate) fn thinned_halves(
    summed: &Array2<f64>,
) -> Result<([Array2<f64>; 2], String), ReconstructError> {
    let (first, second) = thin_halves(summed, THINNING_SEED, "the time-summed counts")?;
    let how = format!(
        "the counts thinned into two halves of {} and {} photons (seed {THINNING_SEED:#x})",
        first.sum(),
        second.sum()
    );
    Ok(([first, second], how))
}

/// The cross-validated search on two halves of the summed counts, `how`
/// saying how they were made: RL on each from `start` (each half's
/// estimate on the model's grid; the flat object when `None`), each scored
/// on the other's counts, up to `max_iters` steps of `acceleration`; with
/// what `keep` asks for comes back too.
/// The halves hold photons ([`RlOperator::mass`] > 0 and some counts).
#[allow(clippy::too_many_arguments)]
pub(crate) fn search_halves(
    data: &Data<'_>,
    rl: &RlOperator,
    halves: [&Array2<f64>; 2],
    start: Option<Vec<Vec<f64>>>,
    how: &str,
    (max_iters, acceleration): (usize, Acceleration),
    keep: Keep<'_>,
    run: &mut Run<'_>,
) -> CvBest {
    let model = data.model;
    let (h, w) = model.sensor_shape();
    let total: f64 = halves.iter().map(|m| m.sum()).sum();
    let halves: [Vec<f64>; 2] = halves.map(|m| m.iter().copied().collect());
    let halves_log = halves
        .each_ref()
        .map(|m| m.iter().map(|&x| m_log_m(x)).collect::<Vec<f64>>());
    // Each half holds half the light and half the background.
    let bg = model.background() * data.bins.len() as f64 / 2.0;
    let guard = DENOMINATOR_GUARD * total / 2.0 / (h * w) as f64;
    let o: Vec<Vec<f64>> = start.unwrap_or_else(|| {
        halves
            .iter()
            .map(|m| vec![flat_level(m.iter().sum(), bg, 1, rl.mass, h * w); rl.sensitivity.len()])
            .collect()
    });
    run.note(format!(
        "stop chosen by two-fold cross-validation: {how}, RL on each, each scored on the other's counts; 8 FFTs per iteration; {}",
        grid_note(model)
    ));
    run.note_background(model);
    cv_search(
        model,
        o,
        max_iters,
        acceleration,
        keep,
        run,
        |x| rl.op.apply(x),
        |y, half| {
            let other = 1 - half;
            half_scores(
                y,
                &halves[half],
                &halves[other],
                &halves_log[other],
                bg,
                guard,
            )
        },
        |half, x, y| {
            // The search has this likelihood from its scores: its
            // logarithms are left out here.
            rl.update(x, y, &halves[half], bg, guard, false);
        },
    )
}

/// The operator of RL on a sum of bins, with its normaliser.
pub(crate) struct RlOperator {
    op: Convolution,
    /// Kernel mass.
    pub(crate) mass: f64,
    /// `H^T 1` over the window: the normaliser of RL with a sensor of
    /// finite size (Bertero and Boccacci 2005); the kernel mass for a
    /// periodic model.
    sensitivity: Vec<f64>,
}

impl RlOperator {
    /// The operator of the sum of `bins`.
    pub(crate) fn new(model: &ForwardModel, bins: &[usize]) -> Self {
        let op = Convolution::from_bins(model, bins);
        Self {
            mass: op.mass(),
            sensitivity: op.sensitivity(),
            op,
        }
    }

    /// `H o` on the sensor window for `o` on the model's grid.
    pub(crate) fn apply(&self, o: &[f64]) -> Vec<f64> {
        self.op.apply(o)
    }

    /// Object pixels (the model's grid).
    pub(crate) fn len(&self) -> usize {
        self.sensitivity.len()
    }

    /// The EM factor of `o` for counts `m`, `H^T(m / (H o + bg)) / H^T 1`
    /// on the grid, the denominator guarded at `guard`; 1 at pixels whose
    /// sensitivity is at most `unseen` times the kernel mass (an EM step
    /// leaves them).
    pub(crate) fn em_ratio(
        &self,
        o: &[f64],
        m: &[f64],
        bg: f64,
        guard: f64,
        unseen: f64,
    ) -> Vec<f64> {
        let y = self.op.apply(o);
        let ratio: Vec<f64> = y
            .iter()
            .zip(m)
            .map(|(&yj, &mj)| mj / (yj + bg).max(guard))
            .collect();
        let seen = unseen * self.mass;
        self.op
            .adjoint(&ratio)
            .into_iter()
            .zip(&self.sensitivity)
            .map(|(b, &s)| if s > seen { b / s } else { 1.0 })
            .collect()
    }

    /// One RL step of `o` for counts `m` given `y = H o`: `o <- o H^T(m /
    /// (y + bg)) / H^T 1`, the denominator guarded at `guard`. Object pixels
    /// the sensor does not see keep their value. Returns the negative
    /// log-likelihood at `o` before the step when `with_nll` (else 0: its
    /// logarithm per pixel is the largest cost outside the transforms).
    pub(crate) fn update(
        &self,
        o: &mut [f64],
        y: &[f64],
        m: &[f64],
        bg: f64,
        guard: f64,
        with_nll: bool,
    ) -> f64 {
        let mut nll = 0.0;
        let ratio: Vec<f64> = y
            .iter()
            .zip(m)
            .map(|(&yj, &mj)| {
                let d = (yj + bg).max(guard);
                if with_nll {
                    nll += d - if mj > 0.0 { mj * d.ln() } else { 0.0 };
                }
                mj / d
            })
            .collect();
        em_multiply(o, &self.op.adjoint(&ratio), &self.sensitivity, self.mass);
        nll
    }
}
