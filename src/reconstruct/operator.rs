//! One blur operator `H` (and its adjoint) from cached kernel spectra.

use rustfft::num_complex::Complex64;

use crate::fft2::Fft2;
use crate::forward::ForwardModel;

/// Periodic convolution with one kernel: a single bin, or the sum of several
/// bins (the time-summed kernel), whose spectrum is the sum of theirs.
pub struct Convolution {
    fft: Fft2,
    spectrum: Vec<Complex64>,
}

impl Convolution {
    /// The operator of the sum of kept bins `bins` of `model`.
    pub fn from_bins(model: &ForwardModel, bins: &[usize]) -> Self {
        let mut spectrum = vec![Complex64::default(); model.fft().spectrum_len()];
        for &k in bins {
            for (s, v) in spectrum.iter_mut().zip(model.spectrum(k)) {
                *s += v;
            }
        }
        Self {
            fft: model.fft().clone(),
            spectrum,
        }
    }

    /// Kernel mass: the sum of the kernel, so that `H^T 1 = mass * 1`.
    pub fn mass(&self) -> f64 {
        self.spectrum[0].re
    }

    /// `H x` (2 FFTs).
    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        self.filter(x, |k| k)
    }

    /// `H^T r`: correlation, the conjugate spectrum (2 FFTs).
    pub fn adjoint(&self, r: &[f64]) -> Vec<f64> {
        self.filter(r, |k| k.conj())
    }

    /// Multiplies the spectrum of `x` by `kernel(spectrum)` pointwise.
    fn filter(&self, x: &[f64], kernel: impl Fn(Complex64) -> Complex64) -> Vec<f64> {
        let prod = self
            .fft
            .forward(x)
            .iter()
            .zip(&self.spectrum)
            .map(|(a, &b)| a * kernel(b))
            .collect();
        self.fft.inverse(prod)
    }
}
