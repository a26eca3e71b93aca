//! What the time axis adds, and whether the default weighs whole-stack
//! Richardson-Lucy against the time-summed methods (rule R90a).
//!
//! For a flat object under Poisson noise, bin `k` carries Fisher
//! information about the object's spatial frequency `f` in proportion to
//! `|H_k(f)|^2 / m_k` (`m_k` its kernel's light); the time-summed stack
//! carries `|sum_k H_k(f)|^2 / M`. Their ratio, the time axis's
//! information gain `G(f)`, is at least 1 (Cauchy-Schwarz) and is 1 where
//! every bin's kernel has the same shape. [`information_gain`] is its
//! median over the frequencies where the summed kernel passes
//! [`GAIN_TRANSFER`] of the light: the time-summed stack's resolution
//! limit.
//!
//! Rule R90a (its bound from rule R90b): where the gain is under
//! [`MIN_GAIN`] the default leaves whole-stack RL out (it costs several
//! times the time-summed search and gains a few tenths of a dB there). Above it, each bin's counts are
//! thinned into two halves; the default's check runs on their sums, RL on
//! the whole stack runs its cross-validated search on them, and each
//! candidate's halves predict the other half's counts in every bin
//! ([`held_back`]): whole-stack RL is returned when it predicts them
//! better than the check's choice by more than [`STACK_TAU`] noise
//! standard deviations.

use ndarray::Array2;
use rayon::prelude::*;
use rustfft::num_complex::Complex64;

use super::em::DENOMINATOR_GUARD;
use crate::forward::ForwardModel;
use crate::poisson::deviance::paired_deviances;

/// The summed kernel's transfer (its light at a spatial frequency over
/// its light at zero) at which the gain is taken; frequencies within a
/// fifth of it either side are used.
pub const GAIN_TRANSFER: f64 = 0.1;

/// The information gain below which the default leaves whole-stack RL
/// out (rule R90b, forty-sixth session): the largest of 5, 3, 2 and 1.5
/// under which no tuning stack of light by Monte Carlo transport seen
/// through a 50 or 100 ps FWHM response (gains 3.3-4.0 and 1.4-1.6) falls
/// more than 0.5 dB below the better of weighing whole-stack RL and not,
/// and above every gain of the paper's preset by Eq. 6 (1.31 without a
/// response, 1.10-1.17 with 50 ps), which so never pays for it. R90a's 5,
/// chosen without a response, left it out at 50 ps.
pub const MIN_GAIN: f64 = 1.5;

/// The time axis's information gain of the model's `bins` (see the
/// module); `None` with fewer than two bins or no light.
pub fn information_gain(model: &ForwardModel, bins: &[usize]) -> Option<f64> {
    if bins.len() < 2 {
        return None;
    }
    let masses: Vec<f64> = bins.iter().map(|&k| model.mass(k)).collect();
    let total: f64 = masses.iter().sum();
    if total.is_nan() || total <= 0.0 {
        return None;
    }
    let len = model.spectrum(bins[0]).len();
    let mut gains: Vec<f64> = (0..len)
        .into_par_iter()
        .filter_map(|i| {
            let mut sum = Complex64::default();
            let mut info = 0.0;
            for (&k, &m) in bins.iter().zip(&masses) {
                let v = model.spectrum(k)[i];
                sum += v;
                if m > 0.0 {
                    info += v.norm_sqr() / m;
                }
            }
            let transfer = sum.norm() / total;
            ((transfer - GAIN_TRANSFER).abs() <= 0.2 * GAIN_TRANSFER)
                .then(|| info / (sum.norm_sqr() / total))
        })
        .collect();
    if gains.is_empty() {
        return None;
    }
    gains.sort_by(f64::total_cmp);
    Some(gains[gains.len() / 2])
}

/// How many noise standard deviations better whole-stack RL must
/// predict the held-back counts to be returned: the smallest of 0, 2, 4,
/// 10, 20 and 50 under which no tuning stack (five tuning images at 0.1x,
/// 1x and 10x, light by Monte Carlo transport) falls more than 0.5 dB
/// below the better of whole-stack RL and the check's choice. (A smooth
/// scene at 1x: z = -13 for whole-stack RL, which was 6.6 dB worse than
/// the network; the smallest z of a stack where it was better: -21.)
pub const STACK_TAU: f64 = 20.0;

/// Two candidates' held-back deviances over every bin, both folds.
#[derive(Debug, Clone, Copy)]
pub struct HeldBack {
    /// Whole-stack RL's.
    pub stack: f64,
    /// The other candidate's.
    pub other: f64,
    /// The noise standard deviation of their difference.
    pub sigma: f64,
}

impl HeldBack {
    /// Whether whole-stack RL predicts the held-back counts better by more
    /// than `tau` noise standard deviations.
    pub fn stack_wins(&self, tau: f64) -> bool {
        self.stack < self.other - tau * self.sigma
    }

    /// The difference in noise standard deviations (negative: whole-stack
    /// RL predicts the held-back counts better).
    pub fn z(&self) -> f64 {
        (self.stack - self.other) / self.sigma.max(f64::MIN_POSITIVE)
    }
}

/// Each candidate's estimate of each half (on the model's grid, fitted
/// to that half) predicting the other half's counts in every bin of
/// `bins` (`halves`: per half, one row-major image per bin), scored by
/// the Poisson deviance, summed over both folds; the noise of the
/// difference as the default's check takes it
/// (`2 sqrt(sum n (ln mu_a - ln mu_b)^2)`).
pub fn held_back(
    model: &ForwardModel,
    bins: &[usize],
    halves: &[Vec<Vec<f64>>; 2],
    stack: [&[f64]; 2],
    other: [&[f64]; 2],
) -> HeldBack {
    let (h, w) = model.sensor_shape();
    let total: f64 = halves.iter().flatten().flatten().sum();
    let bg = model.background() / 2.0;
    let guard = DENOMINATOR_GUARD * total / 2.0 / (bins.len() * h * w) as f64;
    let parts: Vec<[f64; 3]> = (0..2)
        .flat_map(|fold| (0..bins.len()).map(move |j| (fold, j)))
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|(fold, j)| {
            let counts = &halves[1 - fold][j];
            let a = model.apply(bins[j], stack[fold]);
            let b = model.apply(bins[j], other[fold]);
            paired_deviances(counts, &a, &b, bg, guard)
        })
        .collect();
    let [stack, other, variance] = parts
        .iter()
        .fold([0.0; 3], |s, p| [s[0] + p[0], s[1] + p[1], s[2] + p[2]]);
    HeldBack {
        stack,
        other,
        sigma: 2.0 * variance.sqrt(),
    }
}

/// The halves' sums over the bins: two halves of the time-summed counts
/// on the sensor (`shape`).
pub fn summed_halves(halves: &[Vec<Vec<f64>>; 2], shape: (usize, usize)) -> [Array2<f64>; 2] {
    halves.each_ref().map(|half| {
        let mut sum = vec![0.0; shape.0 * shape.1];
        for img in half {
            sum.iter_mut().zip(img).for_each(|(s, v)| *s += v);
        }
        Array2::from_shape_vec(shape, sum).expect("the sensor's shape")
    })
}

#[cfg(test)]
mod tests {
    use ndarray::{Array3, s};

    use super::*;
    use crate::forward::Boundary;
    use crate::physics::{KernelStack, Preset, Sampling};

    /// The paper's setup on a 64-pixel sensor (Eq. 6).
    fn paper(size: usize) -> KernelStack {
        let mut setup = Preset::Paper.setup();
        setup.sensor.width_px = size;
        setup.sensor.height_px = size;
        setup.sensor.fov_cm = 50.0 * size as f64 / 256.0;
        KernelStack::build(&setup, Sampling::Integrated).unwrap()
    }

    /// Kernels that are one shape scaled carry no more than their sum:
    /// the gain is 1 (Cauchy-Schwarz's equality); the paper's preset by
    /// Eq. 6 gains little (under rule R90a's bound); a first bin that is
    /// a point (ballistic light) beside a blurred one gains far more.
    #[test]
    fn the_gain_is_one_for_one_shape_and_large_for_a_ballistic_bin() {
        let mut kernels = paper(64);
        let bins: Vec<usize> = (0..kernels.kernels.dim().0).collect();
        let eq6 =
            information_gain(&ForwardModel::new(&kernels, Boundary::Periodic), &bins).unwrap();
        assert!(eq6 > 1.0 && eq6 < MIN_GAIN, "{eq6}");

        let summed = kernels.kernels.sum_axis(ndarray::Axis(0));
        let k = kernels.kernels.dim().0;
        let mut same = Array3::<f64>::zeros(kernels.kernels.dim());
        for i in 0..k {
            same.slice_mut(s![i, .., ..])
                .assign(&(&summed * (1.0 + i as f64)));
        }
        kernels.kernels = same;
        let one =
            information_gain(&ForwardModel::new(&kernels, Boundary::Periodic), &bins).unwrap();
        assert!((one - 1.0).abs() < 1e-9, "{one}");

        // Bin 0 a point at the centre holding 8 % of the light, the
        // others as before: where the sum passes 8-12 %, the point
        // carries most of it, and G = 0.08 / t^2 lies in 5.6-12.5 (most
        // such frequencies lie far out, where the sum passes 8 %).
        let mut ballistic = kernels.kernels.clone();
        ballistic.slice_mut(s![0, .., ..]).fill(0.0);
        let others = ballistic.sum();
        ballistic[[0, 32, 32]] = others * 0.08 / 0.92;
        kernels.kernels = ballistic;
        let gain =
            information_gain(&ForwardModel::new(&kernels, Boundary::Periodic), &bins).unwrap();
        assert!(gain > MIN_GAIN && gain < 12.5 + 1e-6, "{gain}");
        assert_eq!(
            information_gain(&ForwardModel::new(&kernels, Boundary::Periodic), &bins[..1]),
            None
        );
    }

    /// The same estimates score the same (difference 0, no noise); an
    /// estimate of the truth predicts a held-back half better than a
    /// flat one, by many noise standard deviations.
    #[test]
    fn held_back_prefers_the_truth_and_ties_itself() {
        let kernels = paper(32);
        let model = ForwardModel::new(&kernels, Boundary::Periodic);
        let bins: Vec<usize> = (0..model.bins()).collect();
        let truth = crate::scene::Scene::parse("disks").render(32, 32).unwrap();
        let expected = model.expected(truth.view());
        let counts = crate::forward::poisson_counts(&(&expected.counts * 50.0), 3);
        let data = super::super::data::Data::new(&model, &counts, &bins).unwrap();
        let halves = super::super::rl_stack::stack_halves(&data).unwrap();
        let t: Vec<f64> = truth.iter().map(|v| v * 25.0).collect();
        let flat = vec![t.iter().sum::<f64>() / t.len() as f64; t.len()];
        let tie = held_back(&model, &bins, &halves, [&t, &t], [&t, &t]);
        assert_eq!(tie.stack, tie.other);
        assert_eq!(tie.sigma, 0.0);
        let h = held_back(&model, &bins, &halves, [&t, &t], [&flat, &flat]);
        assert!(h.stack_wins(STACK_TAU), "{h:?}");
        let summed = summed_halves(&halves, (32, 32));
        assert_eq!(summed[0].sum() + summed[1].sum(), counts.sum());
    }
}
