//! Poisson negative log-likelihood of the whole stack (Eq. 10) and its
//! gradient (Eq. 11), with the surrogate logarithm of Eq. 16.
//!
//! `L(o) = sum_k sum_j (H^k o)_j - m^k_j kappa((H^k o)_j)`.
//!
//! Work the data does not need is left out: for periodic convolution
//! `sum_j (H^k o)_j = mass_k * sum(o)`, so the linear term and its gradient
//! (`sum_k H^k^T 1 = M * 1`) cost nothing; pixels with zero counts add
//! nothing to the log term; bins with no counts at all are not transformed.
//! One value-and-gradient evaluation costs `2 + 2 K'` FFTs for `K'` bins
//! with counts: one of `o`, one inverse and one forward per such bin, and one
//! inverse of the accumulated spectrum.

use ndarray::parallel::prelude::*;
use ndarray::{Array3, Axis};
use rustfft::num_complex::Complex64;

use crate::fft2::Fft2;
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
    spectrum: Vec<Complex64>,
    /// Dense counts of the bin (zeros included, used as a mask).
    counts: Vec<f64>,
}

/// The data term for a stack of counts and its kernels.
pub struct PoissonLikelihood {
    fft: Fft2,
    active: Vec<ActiveBin>,
    total_mass: f64,
    kappa: SurrogateLog,
    /// `sum m - m log m` over counts, so that deviance = 2 (L - this).
    saturated: f64,
    bins: usize,
    pixels: usize,
}

/// Value and gradient of the data term at one point.
pub struct Evaluation {
    /// `L(o)`.
    pub value: f64,
    /// `dL/do`.
    pub gradient: Vec<f64>,
}

impl PoissonLikelihood {
    /// The likelihood of `counts` (K x H x W, bins in the order of the kept
    /// bins of `model`) with surrogate switch point `eps`.
    pub fn new(model: &ForwardModel, counts: &Array3<f64>, bins: &[usize], eps: f64) -> Self {
        assert_eq!(counts.shape()[0], bins.len(), "one count image per bin");
        let mut active = Vec::new();
        let mut total_mass = 0.0;
        let mut saturated = 0.0;
        for (img, &k) in counts.axis_iter(Axis(0)).zip(bins) {
            let spectrum = model.spectrum(k);
            total_mass += spectrum[0].re;
            if img.iter().all(|&m| m == 0.0) {
                continue;
            }
            saturated += img
                .iter()
                .filter(|&&m| m > 0.0)
                .map(|&m| m - m * m.ln())
                .sum::<f64>();
            active.push(ActiveBin {
                spectrum: spectrum.to_vec(),
                counts: img.iter().copied().collect(),
            });
        }
        let (h, w) = model.shape();
        Self {
            fft: model.fft().clone(),
            active,
            total_mass,
            kappa: SurrogateLog::new(eps),
            saturated,
            bins: bins.len(),
            pixels: h * w,
        }
    }

    /// Total kernel mass M over all bins: `dL/do` of the linear term.
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

    /// Number of pixels N of one image.
    pub fn pixels(&self) -> usize {
        self.pixels
    }

    /// Poisson deviance `2 (L(o) - L_saturated)` for a value of `L`.
    pub fn deviance(&self, value: f64) -> f64 {
        2.0 * (value - self.saturated)
    }

    /// `L(o)` and its gradient.
    pub fn evaluate(&self, o: &[f64]) -> Evaluation {
        let o_spec = self.fft.forward(o);
        let parts: Vec<(f64, Vec<Complex64>)> = self
            .active
            .par_iter()
            .map(|bin| {
                let prod = o_spec
                    .iter()
                    .zip(&bin.spectrum)
                    .map(|(a, b)| a * b)
                    .collect();
                let mut y = self.fft.inverse(prod);
                let mut log_term = 0.0;
                for (yj, &m) in y.iter_mut().zip(&bin.counts) {
                    if m > 0.0 {
                        log_term += m * self.kappa.value(*yj);
                        *yj = m * self.kappa.derivative(*yj);
                    } else {
                        *yj = 0.0;
                    }
                }
                let r_spec = self
                    .fft
                    .forward(&y)
                    .iter()
                    .zip(&bin.spectrum)
                    .map(|(a, b)| a * b.conj())
                    .collect();
                (log_term, r_spec)
            })
            .collect();
        let mut acc = vec![Complex64::default(); self.fft.spectrum_len()];
        let mut log_total = 0.0;
        for (log_term, spec) in parts {
            log_total += log_term;
            acc.iter_mut().zip(&spec).for_each(|(a, s)| *a += s);
        }
        let back = self.fft.inverse(acc);
        let sum_o: f64 = o.iter().sum();
        Evaluation {
            value: self.total_mass * sum_o - log_total,
            gradient: back.iter().map(|g| self.total_mass - g).collect(),
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
