//! Richardson-Lucy on the whole stack: the EM iteration of the Poisson
//! likelihood of every kept bin with its own kernel (Shepp and Vardi's
//! ML-EM, as multi-frame Richardson-Lucy),
//! `o <- o sum_k H_k^T(m_k / (H_k o + b)) / sum_k H_k^T 1`, which uses the
//! time axis where RL on the time-summed stack throws it away. Like RL, its
//! only regularisation is when it stops: after a fixed count, or where
//! two-fold cross-validation on thinned halves of each bin says.
//!
//! The bins' kernels go through a [`TimeBasis`]: the forward and
//! back-projection of all K bins take one transform per basis kernel
//! (11 for the paper preset's 20 bins) instead of one per bin.

use ndarray::Axis;
use rayon::prelude::*;

use super::data::{Data, flat_level};
use super::em::{
    Acceleration, CvBest, DENOMINATOR_GUARD, Keep, RlStop, cv_search, em_multiply, fixed_steps,
    half_scores,
};
use super::error::ReconstructError;
use super::run::{Estimate, Reconstructor, Run, WorkShape, grid_note};
use crate::forward::ForwardModel;
use crate::poisson::deviance::m_log_m;
use crate::poisson::thinning::{THINNING_SEED, thin_halves};
use crate::time_basis::{BASIS_TOLERANCE, TimeBasis};

/// Whole-stack Richardson-Lucy.
///
/// With [`RlStop::CrossValidated`] it chooses its own iteration count
/// without a truth: each bin's counts are thinned into two independent
/// halves ([`thin_halves`], one seed per bin), the iteration runs on each
/// half, and after every step each half's estimate predicts the other
/// half's counts in every bin (their Poisson deviance is the score). The
/// stop and the output are those of [`super::rl_sum::RlSum`]:
/// [`super::em::CV_PATIENCE`] past the best score, the sum of the halves'
/// estimates there.
#[derive(Debug, Clone, Copy)]
pub struct RlStack {
    /// When it stops.
    pub stop: RlStop,
}

impl Reconstructor for RlStack {
    fn name(&self, _bins: usize) -> &'static str {
        "rl-stack"
    }

    fn reconstruct(
        &self,
        data: &Data<'_>,
        run: &mut Run<'_>,
    ) -> Result<Estimate, ReconstructError> {
        match self.stop {
            RlStop::After(iterations) => fixed(data, iterations, run),
            RlStop::CrossValidated {
                max_iters,
                acceleration,
            } => cross_validated(data, max_iters, acceleration, run),
        }
    }

    /// Per bin: the counts, their two thinned halves and their `m log m`,
    /// each half's prediction (sensor, f64), and the time basis's spectra
    /// (at most one per bin). Shared: the two estimates and the
    /// back-projections on the grid.
    fn working_bytes(&self, shape: &WorkShape) -> u64 {
        shape.bytes([80, 8, 16], [0, 64, 32])
    }
}

/// `iterations` whole-stack RL steps from the flat object.
fn fixed(
    data: &Data<'_>,
    iterations: usize,
    run: &mut Run<'_>,
) -> Result<Estimate, ReconstructError> {
    let (model, counts, bins) = (data.model, data.counts, data.bins);
    let em = StackEm::new(model, bins);
    let (h, w) = model.sensor_shape();
    let m: Vec<Vec<f64>> = counts
        .axis_iter(Axis(0))
        .map(|img| img.iter().copied().collect())
        .collect();
    let total: f64 = counts.sum();
    if total == 0.0 || em.mass <= 0.0 {
        return Ok(run.no_photons((h, w)));
    }
    let bg = model.background();
    let guard = DENOMINATOR_GUARD * total / (bins.len() * h * w) as f64;
    let o = vec![flat_level(total, bg, bins.len(), em.mass, h * w); em.sensitivity.len()];
    run.note(em.note(model, guard));
    run.note_background(model);
    let step = |o: &mut [f64]| {
        let y = em.forward(o);
        em.update(o, &y, &m, bg, guard, true)
    };
    let image = fixed_steps(model, o, iterations, run, step);
    Ok(Estimate {
        image,
        iteration: iterations,
    })
}

/// The cross-validated stop (see [`RlStack`]).
fn cross_validated(
    data: &Data<'_>,
    max_iters: usize,
    acceleration: Acceleration,
    run: &mut Run<'_>,
) -> Result<Estimate, ReconstructError> {
    let (model, counts, bins) = (data.model, data.counts, data.bins);
    let total: f64 = counts.sum();
    if total == 0.0 || bins.iter().map(|&k| model.mass(k)).sum::<f64>() <= 0.0 {
        return Ok(run.no_photons(model.sensor_shape()));
    }
    let halves = stack_halves(data)?;
    let best = search_stack(data, &halves, (max_iters, acceleration), Keep::NOTHING, run);
    Ok(Estimate {
        image: best.image,
        iteration: best.iteration,
    })
}

/// Each bin's counts thinned into two independent halves (binomial
/// thinning, seed [`THINNING_SEED`] plus the bin's index): per half, one
/// row-major image per bin. Summed over the bins, each half is a thinned
/// half of the time-summed counts.
pub(crate) fn stack_halves(data: &Data<'_>) -> Result<[Vec<Vec<f64>>; 2], ReconstructError> {
    let mut firsts = Vec::with_capacity(data.bins.len());
    let mut seconds = Vec::with_capacity(data.bins.len());
    for (k, img) in data.counts.axis_iter(Axis(0)).enumerate() {
        let (a, b) = thin_halves(
            &img.to_owned(),
            THINNING_SEED.wrapping_add(k as u64),
            &format!("bin {k}'s counts"),
        )?;
        firsts.push(a.iter().copied().collect::<Vec<f64>>());
        seconds.push(b.iter().copied().collect::<Vec<f64>>());
    }
    Ok([firsts, seconds])
}

/// Whole-stack RL's cross-validated search on the per-bin `halves`
/// ([`stack_halves`]): the iteration run on each half from the flat
/// object, each scored on the other's counts in every bin, up to
/// `max_iters` steps of `acceleration`; with what `keep` asks for. The
/// data hold photons.
pub(crate) fn search_stack(
    data: &Data<'_>,
    halves: &[Vec<Vec<f64>>; 2],
    (max_iters, acceleration): (usize, Acceleration),
    keep: Keep<'_>,
    run: &mut Run<'_>,
) -> CvBest {
    let (model, counts, bins) = (data.model, data.counts, data.bins);
    let em = StackEm::new(model, bins);
    let (h, w) = model.sensor_shape();
    let total: f64 = counts.sum();
    let halves_log = halves.each_ref().map(|h| {
        h.iter()
            .map(|m| m.iter().map(|&x| m_log_m(x)).collect())
            .collect::<Vec<Vec<f64>>>()
    });
    let photons = halves
        .each_ref()
        .map(|h| h.iter().map(|m| m.iter().sum::<f64>()).sum::<f64>());
    // Each half holds half the light and half the background.
    let bg = model.background() / 2.0;
    let guard = DENOMINATOR_GUARD * total / 2.0 / (bins.len() * h * w) as f64;
    let o: Vec<Vec<f64>> = photons
        .iter()
        .map(|&p| vec![flat_level(p, bg, bins.len(), em.mass, h * w); em.sensitivity.len()])
        .collect();
    run.note(format!(
        "stop chosen by two-fold cross-validation: each bin's counts thinned into two halves ({} and {} photons, seed {THINNING_SEED:#x} plus the bin's index), the iteration run on each, each scored on the other's counts in every bin",
        photons[0], photons[1]
    ));
    run.note(em.note(model, guard));
    run.note_background(model);
    cv_search(
        model,
        o,
        max_iters,
        acceleration,
        keep,
        run,
        |x| em.forward(x),
        |y, half| {
            let other = 1 - half;
            stack_half_scores(
                y,
                &halves[half],
                &halves[other],
                &halves_log[other],
                bg,
                guard,
            )
        },
        |half, x, y| {
            // The cross-validated search scores the held-back half, not
            // this likelihood: its logarithms are left out.
            em.update(x, y, &halves[half], bg, guard, false);
        },
    )
}

/// The whole-stack EM operator: every kept bin's kernel (through a
/// [`TimeBasis`] of them) and the normaliser `sum_k H_k^T 1`.
///
/// The transforms stay in double precision: with single-precision ones
/// (tried, BENCHMARKS.md, fifteenth session) the cross-validated score of
/// a sparse star field on black rose after 7 iterations and the output
/// came out 10 dB worse (presumably the roundoff of the bright points'
/// light exceeding the light of the black background).
struct StackEm<'a> {
    /// The bins' kernels, transformed once per basis kernel.
    basis: TimeBasis<'a>,
    /// Number of bins.
    bins: usize,
    /// Total kernel mass over the bins.
    mass: f64,
    /// `sum_k H_k^T 1` over the window.
    sensitivity: Vec<f64>,
}

impl<'a> StackEm<'a> {
    fn new(model: &'a ForwardModel, bins: &[usize]) -> Self {
        Self {
            basis: TimeBasis::new(model, bins, BASIS_TOLERANCE),
            bins: bins.len(),
            mass: bins.iter().map(|&k| model.mass(k)).sum(),
            sensitivity: model.sensitivity(bins),
        }
    }

    /// The trace's note on the operator.
    fn note(&self, model: &ForwardModel, guard: f64) -> String {
        format!(
            "EM over {} bins, each with its own kernel; denominator guarded at {guard:.3e} ({DENOMINATOR_GUARD:e} x mean count per bin); {}; 2 + 2 x {} FFTs per iteration and estimate (double precision), a bin without counts adds no back-projection; {}",
            self.bins,
            self.basis.note(),
            self.basis.rank(),
            grid_note(model)
        )
    }

    /// `H_k o` on the sensor window for every bin.
    fn forward(&self, o: &[f64]) -> Vec<Vec<f64>> {
        self.basis.forward(o)
    }

    /// One EM step of `o` for counts `m` given `y = H o`; object pixels the
    /// sensor does not see keep their value. Returns the negative
    /// log-likelihood at `o` before the step when `with_nll` (else 0: its
    /// logarithm per pixel and bin is the step's largest cost).
    fn update(
        &self,
        o: &mut [f64],
        y: &[Vec<f64>],
        m: &[Vec<f64>],
        bg: f64,
        guard: f64,
        with_nll: bool,
    ) -> f64 {
        let parts: Vec<(f64, Option<Vec<f64>>)> = y
            .par_iter()
            .zip(m.par_iter())
            .map(|(yk, mk)| {
                let mut lit = false;
                let ratio: Vec<f64> = yk
                    .iter()
                    .zip(mk)
                    .map(|(&yj, &mj)| {
                        lit |= mj > 0.0;
                        mj / (yj + bg).max(guard)
                    })
                    .collect();
                let nll = if with_nll {
                    yk.iter()
                        .zip(mk)
                        .map(|(&yj, &mj)| {
                            let d = (yj + bg).max(guard);
                            if mj > 0.0 { d - mj * d.ln() } else { d }
                        })
                        .sum()
                } else {
                    0.0
                };
                // A bin without counts back-projects zero.
                (nll, lit.then_some(ratio))
            })
            .collect();
        let nll = parts.iter().map(|(part, _)| part).sum();
        let ratios: Vec<Option<Vec<f64>>> = parts.into_iter().map(|(_, r)| r).collect();
        em_multiply(
            o,
            &self.basis.adjoint_sum(&ratios),
            &self.sensitivity,
            self.mass,
        );
        nll
    }
}

/// [`half_scores`] of every bin, summed over the bins.
fn stack_half_scores(
    y: &[Vec<f64>],
    own: &[Vec<f64>],
    other: &[Vec<f64>],
    other_log: &[Vec<f64>],
    bg: f64,
    guard: f64,
) -> (f64, f64) {
    y.par_iter()
        .zip(own.par_iter())
        .zip(other.par_iter().zip(other_log.par_iter()))
        .map(|((yk, mk), (ok, lk))| half_scores(yk, mk, ok, lk, bg, guard))
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
}
