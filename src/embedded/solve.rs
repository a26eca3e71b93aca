//! The object's transmission from the transformed counts: Richardson-Lucy
//! (EM) for the Poisson likelihood of `z` against
//! `H_g (b o) / gain + n_g beta_p`, over the used pixels only, with each
//! pixel's background `beta_p` (per bin) fitted beside the object by its
//! own EM step. `H_g` is the back slab's kernel summed over the bins of
//! time group `g` (`n_g` bins), `b` the beam's light at the object plane.
//!
//! When to stop: two-fold cross-validation over the pixels' parity
//! (a checkerboard): each half is fitted alone and scored on the other
//! half's likelihood (each held-out pixel's background fitted to its own
//! counts under the prediction), and the iteration where the two held-out
//! deviances sum least is run on all pixels. Unlike thinning, which needs
//! Poisson counts, the split needs only noise independent from pixel to
//! pixel (the filtered pixels, averages of their neighbours, are left out
//! before).

use ndarray::Array2;
use rayon::prelude::*;
use rustfft::num_complex::Complex64;
use serde::Serialize;

use crate::forward::ForwardModel;
use crate::reconstruct::discrepancy::ExpectedDeviance;
use crate::reconstruct::em::CV_PATIENCE;

/// Held-out deviance differences below this are not told apart: the
/// search keeps the earliest iteration within it of the least.
pub const RESOLVED_DEVIANCE: f64 = 1.0;

/// The largest extrapolation of an EM step along the last change.
pub const MAX_PUSH: f64 = 0.9;

/// EM steps of a held-out pixel's background per iteration (warm-started).
const HELD_OUT_STEPS: usize = 5;

/// The data the solver fits.
pub struct Problem<'a> {
    /// One kernel per time group, on the object grid.
    pub model: &'a ForwardModel,
    /// Transformed counts per group, each on the sensor (row-major).
    pub counts: Vec<Vec<f64>>,
    /// Bins in each group.
    pub group_bins: Vec<f64>,
    /// Starting background per bin, per sensor pixel (row-major).
    pub offset: Vec<f64>,
    /// Pixels in the likelihood (row-major, sensor).
    pub used: Vec<bool>,
    /// The beam's light at each object-grid pixel.
    pub beam: Vec<f64>,
    /// Variance per unit mean of the untransformed counts.
    pub gain: f64,
}

/// What the solver found.
#[derive(Debug, Clone, Serialize)]
pub struct Fit {
    /// The transmission on the object grid (row-major), beam divided out.
    #[serde(skip)]
    pub object: Vec<f64>,
    /// Fitted background per bin, per sensor pixel.
    #[serde(skip)]
    pub background: Vec<f64>,
    /// Iterations run on all pixels.
    pub iterations: usize,
    /// Held-out deviance (both halves summed) after each iteration.
    pub held_out: Vec<f64>,
    /// Whether the search reached its cap before its best was clear.
    pub stopped_at_cap: bool,
    /// The fit's deviance over the used pixels and groups.
    pub deviance: f64,
    /// What Poisson noise alone gives around the same means (less one per
    /// used pixel, for its fitted background), and its sd.
    pub expected_deviance: (f64, f64),
}

impl Fit {
    /// How many standard deviations of the noise the deviance lies above
    /// its expectation.
    pub fn misfit_z(&self) -> f64 {
        (self.deviance - self.expected_deviance.0) / self.expected_deviance.1.max(1e-300)
    }
}

/// One EM walk over a set of pixels.
struct Walker {
    /// The last EM iterate.
    object: Vec<f64>,
    /// Where the next EM step starts: the last iterate pushed along its
    /// last change.
    point: Vec<f64>,
    /// The last EM step's change, `object - point before it`.
    change: Option<Vec<f64>>,
    background: Vec<f64>,
    fitted: Vec<bool>,
    sensitivity: Vec<f64>,
}

impl Problem<'_> {
    fn groups(&self) -> usize {
        self.counts.len()
    }

    /// `sum_g H_g^T (n-weighted) mask` on the grid, times the beam.
    fn sensitivity(&self, mask: &[bool]) -> Vec<f64> {
        let m: Vec<f64> = mask.iter().map(|&u| f64::from(u8::from(u))).collect();
        let spec = self.sum_adjoint(|_| m.clone());
        self.model
            .fft()
            .inverse(spec)
            .into_iter()
            .zip(&self.beam)
            .map(|(s, b)| s.max(0.0) * b / self.gain)
            .collect()
    }

    /// The spectrum of `sum_g H_g^T r_g`.
    fn sum_adjoint(&self, r: impl Fn(usize) -> Vec<f64> + Sync) -> Vec<Complex64> {
        (0..self.groups())
            .into_par_iter()
            .map(|g| self.model.adjoint_spectrum(g, &r(g)))
            .reduce_with(|mut a, b| {
                a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                a
            })
            .expect("at least one group")
    }

    /// `H_g (b o) / gain` for every group, on the sensor.
    fn predict(&self, object: &[f64]) -> Vec<Vec<f64>> {
        let lit: Vec<f64> = object.iter().zip(&self.beam).map(|(o, b)| o * b).collect();
        let spec = self.model.fft().forward(&lit);
        (0..self.groups())
            .into_par_iter()
            .map(|g| {
                self.model
                    .apply_spectrum(g, &spec)
                    .into_iter()
                    .map(|v| v.max(0.0) / self.gain)
                    .collect()
            })
            .collect()
    }

    fn walker(&self, fitted: &[bool]) -> Walker {
        let sensitivity = self.sensitivity(fitted);
        // A flat start that predicts the fitted pixels' light above their
        // backgrounds.
        let (mut light, mut seen) = (0.0, 0.0);
        for (p, &f) in fitted.iter().enumerate() {
            if f {
                for (g, z) in self.counts.iter().enumerate() {
                    light += z[p] - self.group_bins[g] * self.offset[p];
                }
            }
        }
        seen += sensitivity.iter().sum::<f64>();
        let level = (light / seen.max(1e-300)).max(1e-12);
        Walker {
            object: vec![level; sensitivity.len()],
            point: vec![level; sensitivity.len()],
            change: None,
            background: self.offset.clone(),
            fitted: fitted.to_vec(),
            sensitivity,
        }
    }

    /// One EM step of the object (from the extrapolated point) and of the
    /// fitted pixels' backgrounds, then the next point: vector
    /// extrapolation (Biggs and Andrews 1997), `x + a (x - x_prev)` with
    /// `a` the correlation of the last two changes, in [0, [`MAX_PUSH`]].
    fn step(&self, w: &mut Walker) {
        let pred = self.predict(&w.point);
        let n_all: f64 = self.group_bins.iter().sum();
        let ratios: Vec<Vec<f64>> = (0..self.groups())
            .map(|g| {
                (0..pred[g].len())
                    .map(|p| {
                        if w.fitted[p] {
                            let mu = pred[g][p] + self.group_bins[g] * w.background[p];
                            self.counts[g][p] / mu.max(1e-300)
                        } else {
                            0.0
                        }
                    })
                    .collect()
            })
            .collect();
        let back = self
            .model
            .fft()
            .inverse(self.sum_adjoint(|g| ratios[g].clone()));
        let seen = 1e-9 * w.sensitivity.iter().fold(0.0f64, |m, &s| m.max(s));
        let mut next = w.point.clone();
        for ((o, b), (s, beam)) in next
            .iter_mut()
            .zip(&back)
            .zip(w.sensitivity.iter().zip(&self.beam))
        {
            if *s > seen {
                *o *= (b * beam / self.gain / s).max(0.0);
            }
        }
        let change: Vec<f64> = next.iter().zip(&w.point).map(|(a, b)| a - b).collect();
        let push = w.change.as_ref().map_or(0.0, |last| {
            let (num, den) = change
                .iter()
                .zip(last)
                .fold((0.0, 0.0), |(n, d), (c, l)| (n + c * l, d + l * l));
            if den > 0.0 {
                (num / den).clamp(0.0, MAX_PUSH)
            } else {
                0.0
            }
        });
        w.point = next
            .iter()
            .zip(&w.object)
            .map(|(x, prev)| (x + push * (x - prev)).max(0.0))
            .collect();
        w.object = next;
        w.change = Some(change);
        for (p, bg) in w.background.iter_mut().enumerate() {
            if w.fitted[p] {
                let r: f64 = (0..self.groups())
                    .map(|g| self.group_bins[g] * ratios[g][p])
                    .sum();
                *bg *= r / n_all;
            }
        }
    }

    /// Deviance of the pixels in `mask` under `object` and their
    /// `background`, each one's background first fitted to its own counts
    /// under the prediction when `refit` (held-out pixels), with what
    /// Poisson noise gives (mean, variance).
    fn deviance(
        &self,
        object: &[f64],
        background: &mut [f64],
        mask: &[bool],
        refit: bool,
    ) -> (f64, f64, f64) {
        let pred = self.predict(object);
        let table = ExpectedDeviance::shared();
        let n_all: f64 = self.group_bins.iter().sum();
        let (mut d, mut e, mut v) = (0.0, 0.0, 0.0);
        for p in (0..mask.len()).filter(|&p| mask[p]) {
            let bg = &mut background[p];
            for _ in 0..if refit { HELD_OUT_STEPS } else { 0 } {
                let r: f64 = (0..self.groups())
                    .map(|g| {
                        let mu = pred[g][p] + self.group_bins[g] * *bg;
                        self.group_bins[g] * self.counts[g][p] / mu.max(1e-300)
                    })
                    .sum();
                *bg *= r / n_all;
            }
            for ((z, m), n) in self.counts.iter().zip(&pred).zip(&self.group_bins) {
                let (dp, ep, vp) = table.point(z[p], m[p] + n * *bg);
                d += dp;
                e += ep;
                v += vp;
            }
        }
        (d, e, v)
    }

    /// The fit's expected counts per group on the sensor, background
    /// included.
    pub fn model_counts(&self, fit: &Fit) -> Vec<Vec<f64>> {
        let mut pred = self.predict(&fit.object);
        for (g, m) in pred.iter_mut().enumerate() {
            for (v, b) in m.iter_mut().zip(&fit.background) {
                *v += self.group_bins[g] * b;
            }
        }
        pred
    }

    /// The transmission after `fixed` iterations, or else after those
    /// the parity split chooses, at most `max_iters`.
    pub fn solve(&self, max_iters: usize, fixed: Option<usize>) -> Fit {
        if let Some(n) = fixed {
            return self.run_all(n, Vec::new(), false);
        }
        let (h, w) = self.model.sensor_shape();
        let parity =
            |p: usize, even: bool| self.used[p] && (p / w + p % w).is_multiple_of(2) == even;
        let halves: [Vec<bool>; 2] = [
            (0..h * w).map(|p| parity(p, true)).collect(),
            (0..h * w).map(|p| parity(p, false)).collect(),
        ];
        let mut walkers = [self.walker(&halves[0]), self.walker(&halves[1])];
        let mut held = [self.offset.clone(), self.offset.clone()];
        let mut curve = Vec::new();
        let (mut best, mut best_at) = (f64::INFINITY, 0);
        let mut stopped_at_cap = true;
        for it in 1..=max_iters {
            let [a, b] = &mut walkers;
            rayon::join(|| self.step(a), || self.step(b));
            let [ha, hb] = &mut held;
            let da = self.deviance(&walkers[0].object, ha, &halves[1], true).0;
            let db = self.deviance(&walkers[1].object, hb, &halves[0], true).0;
            let total = da + db;
            curve.push(total);
            // The earliest iteration within one unit of deviance of the
            // least: the data cannot tell smaller differences apart.
            if total < best - RESOLVED_DEVIANCE {
                best_at = it;
                best = total;
            }
            if it >= best_at + CV_PATIENCE.max(best_at / 4) {
                stopped_at_cap = false;
                break;
            }
        }
        self.run_all(best_at.max(1), curve, stopped_at_cap)
    }

    /// `iterations` on every used pixel, with the search's record.
    fn run_all(&self, iterations: usize, held_out: Vec<f64>, stopped_at_cap: bool) -> Fit {
        let mut all = self.walker(&self.used);
        for _ in 0..iterations {
            self.step(&mut all);
        }
        let mut background = all.background.clone();
        let (deviance, e, v) = self.deviance(&all.object, &mut background, &self.used, false);
        // Each used pixel's fitted background takes one degree of freedom
        // from what the noise leaves.
        let e = e - self.used.iter().filter(|&&u| u).count() as f64;
        Fit {
            object: all.object,
            background: all.background,
            iterations,
            held_out,
            stopped_at_cap,
            deviance,
            expected_deviance: (e, v.sqrt()),
        }
    }
}

/// The transmission on the sensor window as an image (rows, columns).
pub fn on_sensor(model: &ForwardModel, grid: &[f64]) -> Array2<f64> {
    let (h, w) = model.sensor_shape();
    Array2::from_shape_vec((h, w), model.crop_vec(grid)).expect("sensor shape")
}
