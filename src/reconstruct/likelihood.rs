//! Poisson negative log-likelihood of the whole stack (Eq. 10) and its
//! gradient (Eq. 11), with the surrogate logarithm of Eq. 16.
//!
//! `L(o) = sum_k sum_j (H^k o)_j - m^k_j kappa((H^k o)_j)`.
//!
//! Work the data does not need is left out: the linear term is
//! `<s, o>` with `s = sum_k H^k^T 1` over the sensor window, computed once
//! (the total mass everywhere for a periodic model), so it and its gradient
//! cost no FFT; pixels with zero counts add nothing to the log term; bins
//! with no counts at all are not transformed.
//! One value-and-gradient evaluation costs `2 + 2 K'` FFTs for `K'` bins
//! with counts: one of `o`, one inverse and one forward per such bin, and one
//! inverse of the accumulated spectrum.

use ndarray::parallel::prelude::*;
use ndarray::{Array3, Axis};
use rustfft::num_complex::Complex64;

use crate::forward::ForwardModel;

/// The surrogate logarithm of Eq. 16: `log x` above `eps`, below it the
/// quadratic `a x^2 + b x + c` that matches the value, slope and curvature
/// of `log` at `eps` (so `kappa` stays concave and `L` convex).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurrogateLog {
    /// Switch point epsilon.
    pub eps: f64,
    a: f64,
    b: f64,
    c: f64,
}

impl SurrogateLog {
    /// The surrogate with switch point `eps > 0`.
    pub fn new(eps: f64) -> Self {
        let a = -0.5 / (eps * eps);
        let b = 2.0 / eps;
        let c = eps.ln() - 1.5;
        Self { eps, a, b, c }
    }

    /// kappa(x).
    pub fn value(&self, x: f64) -> f64 {
        if x > self.eps {
            x.ln()
        } else {
            (self.a * x + self.b) * x + self.c
        }
    }

    /// kappa'(x), the derivative of exactly the function [`Self::value`] computes.
    pub fn derivative(&self, x: f64) -> f64 {
        if x > self.eps {
            1.0 / x
        } else {
            2.0 * self.a * x + self.b
        }
    }
}

/// A bin that has at least one count.
struct ActiveBin {
    /// Position of the bin in the model.
    bin: usize,
    /// Dense counts of the bin on the sensor (zeros included, used as a mask).
    counts: Vec<f64>,
}

/// The data term for a stack of counts and its kernels.
pub struct PoissonLikelihood<'a> {
    model: &'a ForwardModel,
    active: Vec<ActiveBin>,
    /// `sum_k H_k^T 1_window`: gradient of the linear term.
    sensitivity: Vec<f64>,
    total_mass: f64,
    kappa: SurrogateLog,
    /// `sum m - m log m` over counts, so that deviance = 2 (L - this).
    saturated: f64,
    bins: usize,
    /// The model's background per pixel and bin, and its total over the
    /// sensor and all bins (a constant of `L`).
    background: f64,
    background_total: f64,
}

/// Value and gradient of the data term at one point.
pub struct Evaluation {
    /// `L(o)`.
    pub value: f64,
    /// `dL/do`.
    pub gradient: Vec<f64>,
}

impl<'a> PoissonLikelihood<'a> {
    /// The likelihood of `counts` (K x H x W on the sensor, bins in the
    /// order of the kept bins of `model`) with surrogate switch point `eps`.
    pub fn new(model: &'a ForwardModel, counts: &Array3<f64>, bins: &[usize], eps: f64) -> Self {
        assert_eq!(counts.shape()[0], bins.len(), "one count image per bin");
        let mut active = Vec::new();
        let mut total_mass = 0.0;
        let mut saturated = 0.0;
        for (img, &k) in counts.axis_iter(Axis(0)).zip(bins) {
            total_mass += model.mass(k);
            if img.iter().all(|&m| m == 0.0) {
                continue;
            }
            saturated += img
                .iter()
                .filter(|&&m| m > 0.0)
                .map(|&m| m - m * m.ln())
                .sum::<f64>();
            active.push(ActiveBin {
                bin: k,
                counts: img.iter().copied().collect(),
            });
        }
        Self {
            model,
            active,
            sensitivity: model.sensitivity(bins),
            total_mass,
            kappa: SurrogateLog::new(eps),
            saturated,
            bins: bins.len(),
            background: model.background(),
            background_total: model.background()
                * (bins.len() * model.sensor_shape().0 * model.sensor_shape().1) as f64,
        }
    }

    /// Total kernel mass M over all bins.
    pub fn total_mass(&self) -> f64 {
        self.total_mass
    }

    /// Bins whose counts are all zero and that are never transformed.
    pub fn skipped_bins(&self) -> usize {
        self.bins - self.active.len()
    }

    /// FFTs one value-and-gradient evaluation performs.
    pub fn ffts_per_gradient(&self) -> usize {
        2 + 2 * self.active.len()
    }

    /// Poisson deviance `2 (L(o) - L_saturated)` for a value of `L`.
    pub fn deviance(&self, value: f64) -> f64 {
        2.0 * (value - self.saturated)
    }

    /// `L(o)` and its gradient, for `o` on the model's grid.
    pub fn evaluate(&self, o: &[f64]) -> Evaluation {
        let fft = self.model.fft();
        let o_spec = fft.forward(o);
        let parts: Vec<(f64, Vec<Complex64>)> = self
            .active
            .par_iter()
            .map(|bin| {
                let mut y = self.model.apply_spectrum(bin.bin, &o_spec);
                let mut log_term = 0.0;
                let bg = self.background;
                for (yj, &m) in y.iter_mut().zip(&bin.counts) {
                    if m > 0.0 {
                        log_term += m * self.kappa.value(*yj + bg);
                        *yj = m * self.kappa.derivative(*yj + bg);
                    } else {
                        *yj = 0.0;
                    }
                }
                let r_spec = fft
                    .forward(&self.model.embed_vec(&y))
                    .iter()
                    .zip(self.model.spectrum(bin.bin))
                    .map(|(a, b)| a * b.conj())
                    .collect();
                (log_term, r_spec)
            })
            .collect();
        let mut acc = vec![Complex64::default(); fft.spectrum_len()];
        let mut log_total = 0.0;
        for (log_term, spec) in parts {
            log_total += log_term;
            acc.iter_mut().zip(&spec).for_each(|(a, s)| *a += s);
        }
        let back = fft.inverse(acc);
        let linear: f64 = o.iter().zip(&self.sensitivity).map(|(a, b)| a * b).sum();
        Evaluation {
            value: linear + self.background_total - log_total,
            gradient: back
                .iter()
                .zip(&self.sensitivity)
                .map(|(g, s)| s - g)
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn surrogate_is_continuous_and_differentiable_at_eps() {
        let k = SurrogateLog::new(1e-3);
        let (e, h) = (1e-3, 1e-9);
        assert!((k.value(e - h) - k.value(e + h)).abs() < 1e-5);
        assert!((k.derivative(e - h) - k.derivative(e + h)).abs() / k.derivative(e) < 1e-5);
        // Derivative agrees with finite differences of the value on both sides.
        for x in [2e-4, 5e-4, 3e-3, 0.7] {
            let fd = (k.value(x + 1e-9) - k.value(x - 1e-9)) / 2e-9;
            assert!(
                (fd - k.derivative(x)).abs() / k.derivative(x).abs() < 1e-4,
                "{x}"
            );
        }
        // Concave everywhere, finite at 0 and below.
        assert!(k.value(0.0).is_finite() && k.value(-1.0).is_finite());
        assert!(k.derivative(-1.0) > k.derivative(0.0));
    }
}
