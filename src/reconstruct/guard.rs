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

use ndarray::{Array2, Axis};

use super::data::Data;
use super::em::{Acceleration, DENOMINATOR_GUARD, Keep};
use super::error::ReconstructError;
use super::learned::inputs::{CHECKPOINTS, Iterated, assemble, kernel_rms_radius};
use super::learned::net::LearnedNet;
use super::learned::stages::run_stages;
use super::rl_sum::{RlOperator, search_halves, thinned_halves};
use super::run::{Estimate, Run};
use crate::poisson::deviance::{m_log_m, point_deviance};

/// How many noise standard deviations worse than Richardson-Lucy's the
/// network's held-back deviance may be and still pass: rule R82b's
/// largest candidate (of -2, -1, 0, 1, 2, 4) under which no tuning stack
/// (the benchmark's 19 tuning images and 9 kinds of stress scene from an
/// independent forward model, each at 0.1x, 1x and 10x) falls more than
/// 0.5 dB below `rl-sum` CV.
pub const GUARD_TAU: f64 = 4.0;

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
/// `run`.
pub fn check(
    net: &LearnedNet,
    data: &Data<'_>,
    (max_iters, acceleration): (usize, Acceleration),
    run: &mut Run<'_>,
) -> Result<Option<Verdict>, ReconstructError> {
    let model = data.model;
    let rl = RlOperator::new(model, data.bins);
    let summed = data.counts.sum_axis(Axis(0));
    let (halves, how) = thinned_halves(&summed)?;
    if halves.iter().any(|h| h.sum() <= 0.0) || rl.mass <= 0.0 {
        return Ok(None);
    }
    // Plain steps from the flat object are the network's own Richardson-
    // Lucy: the search keeps its iterates at the checkpoints for it.
    let plain = acceleration == Acceleration::None;
    let best = search_halves(
        data,
        &rl,
        [&halves[0], &halves[1]],
        None,
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
    let (mut network, mut richardson_lucy, mut variance) = (0.0, 0.0, 0.0);
    for (fold, net_estimate) in [first, second].iter().enumerate() {
        let other: Vec<f64> = halves[1 - fold].iter().copied().collect();
        let y_net = rl.apply(net_estimate);
        let y_rl = rl.apply(&best.points[fold]);
        for ((&n, &a), &b) in other.iter().zip(&y_net).zip(&y_rl) {
            let (a, b) = ((a + bg).max(guard), (b + bg).max(guard));
            let (la, lb) = (a.ln(), b.ln());
            let nl = m_log_m(n);
            network += point_deviance(n, nl, a, la);
            richardson_lucy += point_deviance(n, nl, b, lb);
            variance += n * (la - lb) * (la - lb);
        }
    }
    let grid: Vec<f64> = best.points[0]
        .iter()
        .zip(&best.points[1])
        .map(|(a, b)| a + b)
        .collect();
    Ok(Some(Verdict {
        network,
        richardson_lucy,
        sigma: 2.0 * variance.sqrt(),
        fallback: Estimate {
            image: best.image,
            iteration: best.iteration,
        },
        fallback_grid: Array2::from_shape_vec(model.grid_shape(), grid).expect("the model's grid"),
    }))
}
