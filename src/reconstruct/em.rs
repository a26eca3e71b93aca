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
/// count). By name (settings, flags, reports): `fixed` or `cv`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RlStop {
    /// After this many iterations.
    After(usize),
    /// At the iteration chosen by two-fold cross-validation on thinned
    /// halves of the counts, searched up to `max_iters`.
    CrossValidated {
        /// The most iterations searched.
        max_iters: usize,
        /// How the search steps.
        acceleration: Acceleration,
    },
}

impl RlStop {
    /// Iterations of a fixed stop unless set.
    pub const DEFAULT_ITERS: usize = 200;
    /// The most iterations the cross-validated stop searches unless set.
    pub const DEFAULT_MAX_ITERS: usize = 1000;
    /// The fixed stop at its default count.
    pub const FIXED: Self = Self::After(Self::DEFAULT_ITERS);
    /// The cross-validated stop with its default search.
    pub const CROSS_VALIDATED: Self = Self::CrossValidated {
        max_iters: Self::DEFAULT_MAX_ITERS,
        acceleration: Acceleration::None,
    };

    /// The same rule with its counts: `iters` for a fixed stop,
    /// `max_iters` and `acceleration` for the cross-validated one (the
    /// other rule's settings are not used).
    pub fn with_counts(self, iters: usize, max_iters: usize, acceleration: Acceleration) -> Self {
        match self {
            Self::After(_) => Self::After(iters),
            Self::CrossValidated { .. } => Self::CrossValidated {
                max_iters,
                acceleration,
            },
        }
    }
}

/// The rules by name, each with its default counts.
impl crate::named::Named for RlStop {
    const ALL: &'static [Self] = &[Self::FIXED, Self::CROSS_VALIDATED];
    fn name(self) -> &'static str {
        match self {
            Self::After(_) => "fixed",
            Self::CrossValidated { .. } => "cv",
        }
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

/// How the cross-validated search moves between Richardson-Lucy steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Acceleration {
    /// Plain EM steps, each from the last (the default).
    #[default]
    None,
    /// Vector extrapolation (Biggs and Andrews 1997, as in MATLAB's
    /// `deconvlucy`): each step starts from the last iterate pushed along
    /// its last change, `x + a (x - x_prev)`, with `a` the correlation of
    /// the last two steps' changes, clamped to [0, 0.5], from the 11th
    /// step on; a point whose training likelihood is worse than the last
    /// one's is dropped for the plain iterate and the extrapolation
    /// restarts, so the likelihood never goes up. On the benchmark's
    /// tuning images: 1.7-1.8x fewer seconds at 1x and 10x, mean PSNR
    /// within 0.05 dB of plain steps, at worst 0.34 dB below them
    /// (BENCHMARKS.md); not the default.
    Extrapolated,
}

/// One half's place in the cross-validated search: the point the next
/// step starts from and, when extrapolating, what the extrapolation
/// needs. Its buffers are kept from step to step: fresh ones for every
/// step (four grids) cost as much as the step's transforms on the
/// development VM, where the kernel zeroes each new page.
struct Walker {
    /// Where the next EM step starts (scored before it).
    point: Vec<f64>,
    /// The last EM iterate (the point before extrapolation).
    iterate: Vec<f64>,
    /// The start of the step under way.
    start: Vec<f64>,
    /// The last EM step's change (its output minus its start); unused
    /// right after a (re)start.
    change: Vec<f64>,
    /// Whether `change` holds a step's change.
    has_change: bool,
    /// Training negative log-likelihood at the last scored point.
    nll: f64,
    /// Whether `point` is extrapolated (else it is `iterate`).
    extrapolated: bool,
    /// Extrapolated points dropped for their likelihood.
    rejected: usize,
    /// EM steps taken.
    steps: usize,
}

/// Largest extrapolation factor, and the steps taken before the first
/// extrapolation (smooth scenes stop within them). Chosen on the
/// benchmark's tuning images (thirty-third session's journal): caps of
/// 1.0, 0.8 and 0.6 from the first steps lost up to 2.0, 0.86 and 0.86 dB
/// against plain steps on some image; this pair loses at most 0.34 dB
/// (a sparse point field) and is as good on average.
const EXTRAPOLATION_CAP: f64 = 0.5;
/// See [`EXTRAPOLATION_CAP`].
const EXTRAPOLATION_START: usize = 10;

/// Fraction of an iterate an extrapolated pixel keeps at least: EM
/// cannot raise a pixel from zero, so extrapolation never sets one there.
const EXTRAPOLATION_FLOOR: f64 = 1e-3;

impl Walker {
    fn new(point: Vec<f64>, accelerate: bool) -> Self {
        let copy = |v: &Vec<f64>| if accelerate { v.clone() } else { Vec::new() };
        Self {
            iterate: copy(&point),
            start: copy(&point),
            change: copy(&point),
            has_change: false,
            point,
            nll: f64::INFINITY,
            extrapolated: false,
            rejected: 0,
            steps: 0,
        }
    }

    /// Keeps the point a step starts from.
    fn begin_step(&mut self) {
        self.start.copy_from_slice(&self.point);
    }

    /// After an EM step took `start` to `point`: the next point, the new
    /// iterate pushed along its last change by the Biggs-Andrews factor
    /// (at most [`EXTRAPOLATION_CAP`], none in the first
    /// [`EXTRAPOLATION_START`] steps).
    fn extrapolate(&mut self) {
        let (mut dot, mut norm) = (0.0, 0.0);
        for ((g_prev, x), s) in self.change.iter_mut().zip(&self.point).zip(&self.start) {
            let g = x - s;
            dot += g * *g_prev;
            norm += *g_prev * *g_prev;
            *g_prev = g;
        }
        self.steps += 1;
        let a =
            if self.steps > EXTRAPOLATION_START && self.has_change && norm > 0.0 && dot.is_finite()
            {
                (dot / norm).clamp(0.0, EXTRAPOLATION_CAP)
            } else {
                0.0
            };
        self.has_change = true;
        self.extrapolated = a > 0.0;
        for (p, x_prev) in self.point.iter_mut().zip(self.iterate.iter_mut()) {
            let x = *p;
            if self.extrapolated {
                *p = (x + a * (x - *x_prev)).max(EXTRAPOLATION_FLOOR * x);
            }
            *x_prev = x;
        }
    }

    /// Goes back from an extrapolated point to the plain iterate and
    /// restarts the extrapolation.
    fn reject(&mut self) {
        self.point.copy_from_slice(&self.iterate);
        self.has_change = false;
        self.extrapolated = false;
        self.rejected += 1;
    }
}

/// The search both cross-validated Richardson-Lucy variants share: the two
/// halves' estimates `o` (on the model's grid) step together; before each
/// step `forward` predicts from each and `evaluate(prediction, half)`
/// returns half `half`'s score on the other half's counts and its
/// negative log-likelihood on its own. The search stops [`CV_PATIENCE`]
/// iterations (or a quarter of the best count, if more) past the best
/// summed score, or at `max_iters`. Returns the best iteration and the sum
/// of the halves' estimates there on the sensor window (and what `keep`
/// asks for: each half's estimate there on the grid, its iterates at given
/// iterations), with the stop's notes in `run`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn cv_search<Y: Send + Sync>(
    model: &ForwardModel,
    o: Vec<Vec<f64>>,
    max_iters: usize,
    acceleration: Acceleration,
    keep: Keep<'_>,
    run: &mut Run<'_>,
    forward: impl Fn(&[f64]) -> Y + Sync,
    evaluate: impl Fn(&Y, usize) -> (f64, f64) + Sync,
    update: impl Fn(usize, &mut [f64], &Y) + Sync,
) -> CvBest {
    let (h, w) = model.sensor_shape();
    let accelerate = acceleration == Acceleration::Extrapolated;
    let mut best_points = if keep.points { o.clone() } else { Vec::new() };
    let mut iterates: Vec<Vec<Vec<f64>>> = vec![Vec::new(); o.len()];
    let mut walkers: Vec<Walker> = o.into_iter().map(|o| Walker::new(o, accelerate)).collect();
    let crop_sum = |walkers: &[Walker]| {
        let sum: Vec<f64> = walkers[0]
            .point
            .iter()
            .zip(&walkers[1].point)
            .map(|(a, b)| a + b)
            .collect();
        Array2::from_shape_vec((h, w), model.crop_vec(&sum)).expect("shape")
    };
    let mut best = (f64::INFINITY, 0usize, crop_sum(&walkers));
    let mut searched = 0;
    for it in 0..=max_iters {
        searched = it;
        // The two halves are independent: one core each.
        let scored: Vec<(Y, f64)> = walkers
            .par_iter_mut()
            .enumerate()
            .map(|(half, walker)| {
                let mut y = forward(&walker.point);
                let (mut held_out, mut nll) = evaluate(&y, half);
                if accelerate && walker.extrapolated && (nll.is_nan() || nll > walker.nll) {
                    walker.reject();
                    y = forward(&walker.point);
                    (held_out, nll) = evaluate(&y, half);
                }
                walker.nll = nll;
                (y, held_out)
            })
            .collect();
        if keep.iterates.contains(&it) {
            for (kept, walker) in iterates.iter_mut().zip(&walkers) {
                kept.push(walker.point.clone());
            }
        }
        let score_cv = scored[0].1 + scored[1].1;
        let improved = score_cv < best.0;
        let mut row = run.row(it);
        row.objective = Some(score_cv);
        if improved || run.scores() {
            let estimate = crop_sum(&walkers);
            run.score(&mut row, estimate.view());
            if improved {
                best = (score_cv, it, estimate);
                for (kept, walker) in best_points.iter_mut().zip(&walkers) {
                    kept.copy_from_slice(&walker.point);
                }
            }
        }
        run.push(row);
        if it == max_iters || it >= best.1 + CV_PATIENCE.max(best.1 / 4) {
            break;
        }
        walkers
            .par_iter_mut()
            .zip(scored.par_iter())
            .enumerate()
            .for_each(|(half, (walker, (y, _)))| {
                if accelerate {
                    walker.begin_step();
                }
                update(half, &mut walker.point, y);
                if accelerate {
                    walker.extrapolate();
                }
            });
    }
    let (_, k, image) = best;
    if accelerate {
        run.note(format!(
            "accelerated by vector extrapolation (Biggs and Andrews); {} extrapolated points dropped for a worse likelihood",
            walkers.iter().map(|w| w.rejected).sum::<usize>()
        ));
    }
    run.note(format!(
        "stopped: iteration {k} predicted the held-back halves best (searched to {searched} of at most {max_iters}); the output is the sum of the two halves' estimates there"
    ));
    if k == max_iters {
        run.note(format!(
            "the cross-validated score was still falling at the cap of {max_iters} iterations: more may help (a higher cap: --rl-max-iters)"
        ));
    }
    run.note(format!("output: iteration {k}"));
    CvBest {
        iteration: k,
        image,
        points: best_points,
        searched,
        iterates,
        last: if keep.iterates.is_empty() {
            Vec::new()
        } else {
            walkers.into_iter().map(|w| w.point).collect()
        },
    }
}

/// What a cross-validated search keeps beyond its best estimate.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Keep<'a> {
    /// Each half's estimate at the best iteration, on the grid.
    pub points: bool,
    /// Iterations whose estimates each half keeps (plain steps: these
    /// are the iterates of Richardson-Lucy from the flat object), and its
    /// last estimate.
    pub iterates: &'a [usize],
}

impl Keep<'_> {
    /// Nothing beyond the best estimate.
    pub(crate) const NOTHING: Keep<'static> = Keep {
        points: false,
        iterates: &[],
    };
}

/// What the cross-validated search found.
pub(crate) struct CvBest {
    /// The best iteration.
    pub iteration: usize,
    /// The sum of the halves' estimates there, on the sensor window.
    pub image: Array2<f64>,
    /// Each half's estimate there, on the model's grid (empty unless
    /// asked for).
    pub points: Vec<Vec<f64>>,
    /// The last iteration searched.
    pub searched: usize,
    /// Per half, its estimates at the iterations asked for that the
    /// search reached, in order.
    pub iterates: Vec<Vec<Vec<f64>>>,
    /// Per half, its estimate at the last iteration searched (empty unless
    /// iterates were asked for).
    pub last: Vec<Vec<f64>>,
}

impl CvBest {
    /// The sum of the halves' estimates on the model's grid of `shape`
    /// (the points kept).
    pub fn grid(&self, shape: (usize, usize)) -> Array2<f64> {
        let sum: Vec<f64> = self.points[0]
            .iter()
            .zip(&self.points[1])
            .map(|(a, b)| a + b)
            .collect();
        Array2::from_shape_vec(shape, sum).expect("the model's grid")
    }
}

/// The two scores of one half's prediction `y + bg` (guarded below by
/// `guard`), from one logarithm per point: the Poisson deviance of the
/// other half's counts `other` (with `m log m` per point, computed once),
/// the score of an estimate on counts it was not fitted to; and the
/// negative log-likelihood of its own counts `own` (up to a constant).
pub(crate) fn half_scores(
    y: &[f64],
    own: &[f64],
    other: &[f64],
    other_log: &[f64],
    bg: f64,
    guard: f64,
) -> (f64, f64) {
    y.iter().zip(own).zip(other.iter().zip(other_log)).fold(
        (0.0, 0.0),
        |(held, nll), ((&yj, &mj), (&oj, &olj))| {
            let d = (yj + bg).max(guard);
            let log_d = d.ln();
            (
                held + point_deviance(oj, olj, d, log_d),
                nll + d - mj * log_d,
            )
        },
    )
}

#[cfg(test)]
pub(crate) mod tests {
    use std::sync::Mutex;

    use ndarray::Axis;

    use super::*;
    use crate::forward::{Boundary, poisson_counts};
    use crate::physics::{KernelStack, Preset, Sampling};
    use crate::poisson::deviance::m_log_m;
    use crate::poisson::thinning::{THINNING_SEED, thin_halves};
    use crate::reconstruct::operator::Convolution;
    use crate::scene::Scene;

    /// The paper's setup on a sensor of `size` x `size` pixels (its field
    /// of view scaled with it, periodic edges) and the disks scene: the
    /// small sharp problem the Richardson-Lucy searches are tested on.
    pub(crate) fn paper_disks(size: usize) -> (ForwardModel, Array2<f64>) {
        let mut setup = Preset::Paper.setup();
        setup.sensor.width_px = size;
        setup.sensor.height_px = size;
        setup.sensor.fov_cm = 50.0 * size as f64 / 256.0;
        let kernels = KernelStack::build(&setup, Sampling::Integrated).unwrap();
        let model = ForwardModel::new(&kernels, Boundary::Periodic);
        let truth = Scene::parse("disks").render(size, size).unwrap();
        (model, truth)
    }

    /// What the search did to one half: each scoring's training
    /// likelihood, and each step taken.
    #[derive(Debug, Clone, Copy)]
    enum Event {
        Scored(f64),
        Stepped,
    }

    /// A steady change is extrapolated from the step after
    /// [`EXTRAPOLATION_START`] on, by at most [`EXTRAPOLATION_CAP`]; a
    /// dropped point goes back to the plain iterate, and the step after it
    /// is not extrapolated (its change has no predecessor).
    #[test]
    fn a_dropped_point_goes_back_to_the_plain_iterate_and_restarts() {
        let mut w = Walker::new(vec![1.0, 2.0, 3.0], true);
        let em_step = |w: &mut Walker| {
            w.begin_step();
            w.point.iter_mut().for_each(|p| *p += 0.1);
            w.extrapolate();
        };
        for _ in 0..EXTRAPOLATION_START {
            em_step(&mut w);
            assert!(!w.extrapolated);
            assert_eq!(w.point, w.iterate);
        }
        em_step(&mut w);
        assert!(w.extrapolated);
        for (p, x) in w.point.iter().zip(&w.iterate) {
            assert!((p - (x + EXTRAPOLATION_CAP * 0.1)).abs() < 1e-12, "{p} {x}");
        }
        w.reject();
        assert_eq!(w.point, w.iterate);
        assert_eq!(w.rejected, 1);
        em_step(&mut w);
        assert!(!w.extrapolated);
        em_step(&mut w);
        assert!(w.extrapolated);
    }

    /// The extrapolated search on the summed stack of a sharp scene: the
    /// training likelihood of the point each step starts from never goes
    /// up, and the search stops after at most two thirds of the plain
    /// search's steps, within 0.3 dB of the plain search's output.
    #[test]
    fn extrapolation_keeps_the_likelihood_falling_and_needs_fewer_steps() {
        let (model, truth) = paper_disks(32);
        let counts = poisson_counts(&model.expected((&truth * 4.0).view()).counts, 7);
        let bins: Vec<usize> = (0..model.bins()).collect();
        let op = Convolution::from_bins(&model, &bins);
        let (sensitivity, mass) = (op.sensitivity(), op.mass());
        let (a, b) = thin_halves(&counts.sum_axis(Axis(0)), THINNING_SEED, "test").unwrap();
        let halves = [a.into_raw_vec_and_offset().0, b.into_raw_vec_and_offset().0];
        let logs = halves
            .each_ref()
            .map(|m| m.iter().map(|&x| m_log_m(x)).collect::<Vec<_>>());
        let search = |acceleration| {
            let events = Mutex::new([Vec::new(), Vec::new()]);
            let start = vec![vec![1.0; sensitivity.len()]; 2];
            let mut on_iter = |_: &crate::reconstruct::trace::TraceRow| {};
            let mut run = Run::new("test", Some(truth.view()), &mut on_iter);
            let CvBest {
                iteration: k,
                image,
                ..
            } = cv_search(
                &model,
                start,
                2000,
                acceleration,
                Keep::NOTHING,
                &mut run,
                |x| op.apply(x),
                |y, half| {
                    let o = 1 - half;
                    let s = half_scores(y, &halves[half], &halves[o], &logs[o], 0.0, 1e-9);
                    events.lock().unwrap()[half].push(Event::Scored(s.1));
                    s
                },
                |half, x, y| {
                    let ratio: Vec<f64> = y
                        .iter()
                        .zip(&halves[half])
                        .map(|(&yj, &m)| m / yj.max(1e-9))
                        .collect();
                    em_multiply(x, &op.adjoint(&ratio), &sensitivity, mass);
                    events.lock().unwrap()[half].push(Event::Stepped);
                },
            );
            // The estimate is in the model's units: PSNR after the gain
            // that fits it to the truth best.
            let psnr = crate::metrics::psnr_fitted(image.view(), truth.view()).unwrap();
            (k, psnr, events.into_inner().unwrap())
        };
        let (k_plain, psnr_plain, _) = search(Acceleration::None);
        let (k_fast, psnr_fast, events) = search(Acceleration::Extrapolated);
        for half in events {
            // The scoring just before each step is the point it starts
            // from; one before that, in the same iteration, was dropped.
            // A plain step's output and the end of the search are scored
            // without a step after them in the same way.
            let mut accepted = Vec::new();
            let mut last = None;
            for e in half {
                match e {
                    Event::Scored(nll) => last = Some(nll),
                    Event::Stepped => accepted.extend(last.take()),
                }
            }
            for w in accepted.windows(2) {
                assert!(w[1] <= w[0], "the likelihood went up: {} -> {}", w[0], w[1]);
            }
        }
        assert!(
            k_fast * 3 < k_plain * 2,
            "steps: {k_fast} extrapolated, {k_plain} plain"
        );
        assert!(
            psnr_fast > psnr_plain - 0.3,
            "PSNR {psnr_fast:.2} extrapolated, {psnr_plain:.2} plain"
        );
    }
}
