//! The "valid" part of the linear convolution of a signal with a fixed
//! instrument response, by real FFTs.
//!
//! A whole-period response ([`super::measured_irf::MeasuredIrf::from_histogram_period`])
//! has about 12 500 entries: the direct sum over a 1 600-bin window would
//! cost 2e7 multiply-adds per model evaluation, the transforms (length
//! 16 384) about 1e6. The response's spectrum is computed once.

use std::sync::Arc;

use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex64;

/// Convolves signals of one length with one response.
pub struct ResponseConvolution {
    forward: Arc<dyn RealToComplex<f64>>,
    inverse: Arc<dyn ComplexToReal<f64>>,
    response_spectrum: Vec<Complex64>,
    response_len: usize,
    out_len: usize,
}

impl ResponseConvolution {
    /// For `response` (`m` entries) and outputs of `out_len` entries, from
    /// signals of `out_len + m - 1` entries.
    pub fn new(response: &[f64], out_len: usize) -> Self {
        let m = response.len();
        let len = (out_len + m).next_power_of_two();
        let mut planner = RealFftPlanner::<f64>::new();
        let forward = planner.plan_fft_forward(len);
        let inverse = planner.plan_fft_inverse(len);
        let mut padded = forward.make_input_vec();
        padded[..m].copy_from_slice(response);
        let mut response_spectrum = forward.make_output_vec();
        forward
            .process(&mut padded, &mut response_spectrum)
            .expect("buffers made by the plan");
        Self {
            forward,
            inverse,
            response_spectrum,
            response_len: m,
            out_len,
        }
    }

    /// Entries a signal must have: `out_len + m - 1`.
    pub fn signal_len(&self) -> usize {
        self.out_len + self.response_len - 1
    }

    /// `out[i] = sum_j response[j] signal[i + m - 1 - j]` for `i` in
    /// `0..out_len`.
    pub fn apply(&self, signal: &[f64]) -> Vec<f64> {
        assert_eq!(signal.len(), self.signal_len(), "signal length");
        let mut padded = self.forward.make_input_vec();
        padded[..signal.len()].copy_from_slice(signal);
        let mut spectrum = self.forward.make_output_vec();
        self.forward
            .process(&mut padded, &mut spectrum)
            .expect("buffers made by the plan");
        spectrum
            .iter_mut()
            .zip(&self.response_spectrum)
            .for_each(|(s, r)| *s *= r);
        let mut full = self.inverse.make_output_vec();
        self.inverse
            .process(&mut spectrum, &mut full)
            .expect("buffers made by the plan");
        let scale = 1.0 / full.len() as f64;
        let m = self.response_len;
        full[m - 1..m - 1 + self.out_len]
            .iter()
            .map(|v| v * scale)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_direct_sum() {
        let response: Vec<f64> = (0..37).map(|j| ((j * 7 % 11) as f64).powi(2)).collect();
        let out_len = 50;
        let signal: Vec<f64> = (0..out_len + response.len() - 1)
            .map(|k| (k as f64 * 0.37).sin().abs() + 1e-3 * k as f64)
            .collect();
        let conv = ResponseConvolution::new(&response, out_len);
        let fast = conv.apply(&signal);
        let m = response.len();
        for (i, f) in fast.iter().enumerate() {
            let direct: f64 = response
                .iter()
                .enumerate()
                .map(|(j, r)| r * signal[i + m - 1 - j])
                .sum();
            assert!(
                (f - direct).abs() <= 1e-12 * direct.abs().max(1.0),
                "{i}: {f} vs {direct}"
            );
        }
    }
}
