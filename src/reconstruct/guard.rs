//! The default's check of the learned reconstruction against the counts,
//! without a truth: does the network explain counts it was not given as
//! well as Richardson-Lucy with its cross-validated stop does?
//!
//! The time-summed counts are thinned into the two halves `rl-sum`'s
//! cross-validated stop uses (binomial thinning: two independent Poisson
//! halves of the same scene); `rl-sum` runs its search on them; the
//! network runs on each half; each estimate predicts the other half's
//! counts (`H x + b/2`), and the two Poisson deviances are summed, for the
//! network (`D_net`) and for Richardson-Lucy at its chosen stop (`D_rl`).
//! The noise of the difference given the two predictions is `sigma = 2
//! sqrt(sum n (ln mu_net - ln mu_rl)^2)` over both folds (the Poisson
//! standard deviation of the log-likelihood difference, twice: deviances
//! are twice the log-likelihood). The network
//! passes when `D_net <= D_rl + tau sigma` (rule R82b, `tau` chosen on
//! tuning stacks: [`GUARD_TAU`]). Richardson-Lucy's output, the sum of
//! the halves' estimates at the stop, is what `rl-sum` returns, so it
//! stands ready when the network fails.
//!
//! A growing acquisition (the live view's snapshots) may carry the search
//! from one snapshot to the next ([`CarriedSearch`]): each search starts
//! from the last one's best estimates of the halves, scaled to the new
//! halves' photons, and takes a bounded number of steps more.

use std::sync::Mutex;

use ndarray::{Array2, Axis};

use super::data::Data;
use super::em::{Acceleration, DENOMINATOR_GUARD, Keep};
use super::error::ReconstructError;
use super::learned::inputs::{CHECKPOINTS, Iterated, assemble, kernel_rms_radius};
use super::learned::net::LearnedNet;
use super::learned::stages::run_stages;
use super::rl_sum::{RlOperator, search_halves, thinned_halves};
use super::run::{Estimate, Run};
use crate::poisson::deviance::paired_deviances;
use crate::poisson::thinning::{THINNING_SEED, thin_halves};

/// How many noise standard deviations worse than Richardson-Lucy's the
/// network's held-back deviance may be and still pass: rule R82b's
/// largest candidate (of -2, -1, 0, 1, 2, 4) under which no tuning stack
/// (the benchmark's 19 tuning images and 9 kinds of stress scene from an
/// independent forward model, each at 0.1x, 1x and 10x) falls more than
/// 0.5 dB below `rl-sum` CV.
pub const GUARD_TAU: f64 = 4.0;

/// The check's Richardson-Lucy search carried from one snapshot of a
/// growing acquisition to the next. The halves grow with the counts: each
/// photon stays in the half it was thinned into, and only the photons
/// since the last snapshot are thinned anew (thinned afresh, a half would
/// share photons with the estimate fitted to the other, and the held-back
/// score would favour that estimate). RL's best stop only moves later as
/// photons arrive, so each search starts from the last one's best
/// estimates (scaled to the new halves' photons) and takes at most
/// [`CarriedSearch::steps`] steps more (the first, from the flat object,
/// as many).
#[derive(Debug)]
pub struct CarriedSearch {
    /// The most steps one snapshot's search takes.
    pub steps: usize,
    last: Mutex<Option<Carried>>,
}

/// The last search's halves and best estimates.
#[derive(Debug)]
struct Carried {
    /// The two halves of the time-summed counts.
    halves: [Array2<f64>; 2],
    /// Each half's best estimate on the model's grid.
    points: Vec<Vec<f64>>,
    /// RL steps from the flat object to these estimates, all searches.
    iterations: usize,
}

/// Halves grown from the last snapshot's, and the search's start on them.
struct Grown {
    halves: [Array2<f64>; 2],
    how: String,
    start: Vec<Vec<f64>>,
    before: usize,
}

impl CarriedSearch {
    /// The steps each snapshot's search takes at most in the live view:
    /// set before any run, at a tenth of `rl-sum`'s search (about 0.5 s on
    /// the mock's 320 x 320 grid on one core).
    pub const LIVE_STEPS: usize = 100;

    /// Nothing carried yet; at most `steps` steps per snapshot.
    pub fn new(steps: usize) -> Self {
        Self {
            steps,
            last: Mutex::new(None),
        }
    }

    fn last(&self) -> std::sync::MutexGuard<'_, Option<Carried>> {
        self.last.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The last snapshot's halves grown by the photons of `summed` since,
    /// with the search's start on a grid of `len` points; `None` when
    /// nothing carried fits (none yet, another shape or grid, or counts
    /// that are not the last snapshot's and more).
    fn grow(&self, summed: &Array2<f64>, len: usize) -> Result<Option<Grown>, ReconstructError> {
        let last = self.last();
        let Some(c) = last.as_ref() else {
            return Ok(None);
        };
        if c.halves[0].dim() != summed.dim() || c.points.iter().any(|p| p.len() != len) {
            return Ok(None);
        }
        let new = summed - &c.halves[0] - &c.halves[1];
        if new.iter().any(|&v| v < 0.0) {
            return Ok(None);
        }
        let (a, b) = thin_halves(&new, THINNING_SEED, "the counts since the last snapshot")?;
        let halves = [&c.halves[0] + &a, &c.halves[1] + &b];
        let mut start = c.points.clone();
        for ((point, old), grown) in start.iter_mut().zip(&c.halves).zip(&halves) {
            let scale = grown.sum() / old.sum().max(1.0);
            point.iter_mut().for_each(|v| *v *= scale);
        }
        let how = format!(
            "the counts in two halves of {} and {} photons, grown from the last snapshot's ({} and {}) by thinning the photons since (seed {THINNING_SEED:#x}); the search carried from that snapshot's best ({} steps from the flat object), scaled to these halves' photons, at most {} steps more",
            halves[0].sum(),
            halves[1].sum(),
            c.halves[0].sum(),
            c.halves[1].sum(),
            c.iterations,
            self.steps
        );
        Ok(Some(Grown {
            halves,
            how,
            start,
            before: c.iterations,
        }))
    }

    /// The steps from the flat object to the last search's best, if one
    /// was carried.
    pub fn steps_taken(&self) -> Option<usize> {
        self.last().as_ref().map(|c| c.iterations)
    }

    fn keep(&self, carried: Carried) {
        *self.last() = Some(carried);
    }
}

/// What the check found.
pub struct Verdict {
    /// The network's held-back deviance, both folds.
    pub network: f64,
    /// Richardson-Lucy's at its cross-validated stop.
    pub richardson_lucy: f64,
    /// The noise standard deviation of their difference.
    pub sigma: f64,
    /// `rl-sum`'s output (cross-validated stop).
    pub fallback: Estimate,
    /// Its estimate on the model's grid (the halves' sum).
    pub fallback_grid: Array2<f64>,
    /// Each half's Richardson-Lucy estimate at its stop, on the model's
    /// grid.
    pub rl_points: Vec<Vec<f64>>,
    /// Each half's network estimate, on the model's grid.
    pub network_points: [Vec<f64>; 2],
}

impl Verdict {
    /// The difference in noise standard deviations (positive: the network
    /// explains the held-back counts worse).
    pub fn z(&self) -> f64 {
        (self.network - self.richardson_lucy) / self.sigma.max(f64::MIN_POSITIVE)
    }

    /// Whether the network passes at `tau`.
    pub fn passes(&self, tau: f64) -> bool {
        self.network <= self.richardson_lucy + tau * self.sigma
    }
}

/// Runs the check of `net` on `data`, which holds photons (`None` when a
/// half holds none: nothing to check against); the network on each half
/// starts from the search's own iterates where its steps are plain.
/// `rl-sum`'s search up to
/// `max_iters` steps of `acceleration` writing its rows and notes to
/// `run`. The halves are `given` (two halves of the time-summed counts,
/// and how they were made), else carried or thinned here.
pub fn check(
    net: &LearnedNet,
    data: &Data<'_>,
    (max_iters, acceleration): (usize, Acceleration),
    carried: Option<&CarriedSearch>,
    given: Option<([Array2<f64>; 2], String)>,
    run: &mut Run<'_>,
) -> Result<Option<Verdict>, ReconstructError> {
    let model = data.model;
    let rl = RlOperator::new(model, data.bins);
    let summed = data.counts.sum_axis(Axis(0));
    let grown = match (carried, &given) {
        (Some(c), None) => c.grow(&summed, rl.len())?,
        _ => None,
    };
    let (halves, how, start, before, max_iters) = match grown {
        Some(g) => (
            g.halves,
            g.how,
            Some(g.start),
            g.before,
            carried.map_or(0, |c| c.steps),
        ),
        None => {
            let (halves, how) = match given {
                Some(g) => g,
                None => thinned_halves(&summed)?,
            };
            let most = carried.map_or(max_iters, |c| c.steps.min(max_iters));
            (halves, how, None, 0, most)
        }
    };
    if halves.iter().any(|h| h.sum() <= 0.0) || rl.mass <= 0.0 {
        return Ok(None);
    }
    // Plain steps from the flat object are the network's own Richardson-
    // Lucy: the search keeps its iterates at the checkpoints for it.
    let plain = acceleration == Acceleration::None && start.is_none();
    let best = search_halves(
        data,
        &rl,
        [&halves[0], &halves[1]],
        start,
        &how,
        (max_iters, acceleration),
        Keep {
            points: true,
            iterates: if plain { &CHECKPOINTS } else { &[] },
        },
        run,
    );
    let (h, w) = model.sensor_shape();
    let bg = model.background() * data.bins.len() as f64 / 2.0;
    let guard = DENOMINATOR_GUARD * summed.sum() / 2.0 / (h * w) as f64;
    let width = kernel_rms_radius(&model.summed(data.bins));
    let network_on = |half: usize| {
        let m: Vec<f64> = halves[half].iter().copied().collect();
        let start = if plain {
            Iterated::from(
                best.last[half].clone(),
                best.searched,
                best.iterates[half].clone(),
            )
        } else {
            Iterated::flat(&rl, &m, bg)
        };
        let iterates = start.continued(&rl, &m, bg, guard);
        let inputs = assemble(model, &rl, m, (bg, guard), iterates, width);
        run_stages(net, model, &rl, &inputs)
    };
    let (first, second) = rayon::join(|| network_on(0), || network_on(1));
    let nets = [first, second];
    let (mut network, mut richardson_lucy, mut variance) = (0.0, 0.0, 0.0);
    for (fold, net_estimate) in nets.iter().enumerate() {
        let other: Vec<f64> = halves[1 - fold].iter().copied().collect();
        let y_net = rl.apply(net_estimate);
        let y_rl = rl.apply(&best.points[fold]);
        let [a, b, v] = paired_deviances(&other, &y_net, &y_rl, bg, guard);
        network += a;
        richardson_lucy += b;
        variance += v;
    }
    let fallback_grid = best.grid(model.grid_shape());
    if let Some(c) = carried {
        c.keep(Carried {
            halves,
            points: best.points.clone(),
            iterations: before + best.iteration,
        });
    }
    Ok(Some(Verdict {
        network,
        richardson_lucy,
        sigma: 2.0 * variance.sqrt(),
        fallback: Estimate {
            image: best.image,
            iteration: before + best.iteration,
        },
        fallback_grid,
        rl_points: best.points,
        network_points: nets,
    }))
}
