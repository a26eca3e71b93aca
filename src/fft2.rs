//! Two-dimensional real FFT built from `realfft` (rows) and `rustfft` (columns).
//!
//! Spectra are stored transposed: `W/2 + 1` rows (horizontal frequency) of `H`
//! complex values (vertical frequency), so that the column transforms run on
//! contiguous memory. Only pointwise products are ever taken of spectra, so
//! the layout is private to this module's users.

use std::cell::RefCell;
use std::sync::Arc;

use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex64;
use rustfft::{Fft, FftPlanner};

thread_local! {
    /// Scratch of the column transforms, one per thread and grown to the
    /// largest plan used. `Fft::process` would allocate and zero a buffer
    /// as large as the whole spectrum on every call (about 0.8 MB on the
    /// paper preset's padded grid, 42 times per split-solver iteration);
    /// measured, that allocation and zeroing was 4 % of a reconstruction.
    static COLUMN_SCRATCH: RefCell<Vec<Complex64>> = const { RefCell::new(Vec::new()) };
}

/// Runs `fft` in place on `buffer` with this thread's reused scratch.
fn process_columns(fft: &dyn Fft<f64>, buffer: &mut [Complex64]) {
    COLUMN_SCRATCH.with_borrow_mut(|scratch| {
        let need = fft.get_inplace_scratch_len();
        if scratch.len() < need {
            scratch.resize(need, Complex64::default());
        }
        fft.process_with_scratch(buffer, &mut scratch[..need]);
    });
}

/// A planned H x W real 2-D transform; cheap to share between threads.
#[derive(Clone)]
pub struct Fft2 {
    height: usize,
    width: usize,
    row_forward: Arc<dyn RealToComplex<f64>>,
    row_inverse: Arc<dyn ComplexToReal<f64>>,
    col_forward: Arc<dyn Fft<f64>>,
    col_inverse: Arc<dyn Fft<f64>>,
}

impl Fft2 {
    /// Plans transforms for `height` x `width` images.
    pub fn new(height: usize, width: usize) -> Self {
        let mut real = RealFftPlanner::<f64>::new();
        let mut complex = FftPlanner::<f64>::new();
        Self {
            height,
            width,
            row_forward: real.plan_fft_forward(width),
            row_inverse: real.plan_fft_inverse(width),
            col_forward: complex.plan_fft_forward(height),
            col_inverse: complex.plan_fft_inverse(height),
        }
    }

    /// Number of complex values in one spectrum.
    pub fn spectrum_len(&self) -> usize {
        (self.width / 2 + 1) * self.height
    }

    /// Forward transform of a row-major `height * width` image.
    pub fn forward(&self, image: &[f64]) -> Vec<Complex64> {
        let mut spectrum = vec![Complex64::default(); self.spectrum_len()];
        self.forward_into(image, &mut spectrum);
        spectrum
    }

    /// Forward transform into a caller's buffer of [`Self::spectrum_len`]
    /// values (hot loops reuse their buffers).
    pub fn forward_into(&self, image: &[f64], spectrum: &mut [Complex64]) {
        let (h, w) = (self.height, self.width);
        assert_eq!(image.len(), h * w, "image size does not match the plan");
        let wc = w / 2 + 1;
        assert_eq!(
            spectrum.len(),
            wc * h,
            "spectrum size does not match the plan"
        );
        let mut row = vec![0.0; w];
        let mut row_spec = vec![Complex64::default(); wc];
        let mut scratch = self.row_forward.make_scratch_vec();
        for (y, src) in image.chunks_exact(w).enumerate() {
            row.copy_from_slice(src);
            self.row_forward
                .process_with_scratch(&mut row, &mut row_spec, &mut scratch)
                .expect("buffer sizes come from the plan");
            for (kx, v) in row_spec.iter().enumerate() {
                spectrum[kx * h + y] = *v;
            }
        }
        process_columns(self.col_forward.as_ref(), spectrum);
    }

    /// Inverse transform, normalised so that `inverse(forward(x)) == x`.
    /// Consumes the spectrum as scratch.
    pub fn inverse(&self, mut spectrum: Vec<Complex64>) -> Vec<f64> {
        let mut out = vec![0.0; self.height * self.width];
        self.inverse_into(&mut spectrum, &mut out);
        out
    }

    /// Inverse transform into a caller's buffer; the spectrum is used as
    /// scratch and left changed.
    pub fn inverse_into(&self, spectrum: &mut [Complex64], out: &mut [f64]) {
        let (h, w) = (self.height, self.width);
        let wc = w / 2 + 1;
        assert_eq!(
            spectrum.len(),
            wc * h,
            "spectrum size does not match the plan"
        );
        assert_eq!(out.len(), h * w, "image size does not match the plan");
        process_columns(self.col_inverse.as_ref(), spectrum);
        let scale = 1.0 / (h * w) as f64;
        let mut row_spec = vec![Complex64::default(); wc];
        let mut scratch = self.row_inverse.make_scratch_vec();
        for (y, dst) in out.chunks_exact_mut(w).enumerate() {
            for (kx, v) in row_spec.iter_mut().enumerate() {
                *v = spectrum[kx * h + y];
            }
            // A real signal has real DC and Nyquist terms; drop round-off.
            row_spec[0].im = 0.0;
            if w % 2 == 0 {
                row_spec[wc - 1].im = 0.0;
            }
            self.row_inverse
                .process_with_scratch(&mut row_spec, dst, &mut scratch)
                .expect("buffer sizes come from the plan");
            dst.iter_mut().for_each(|v| *v *= scale);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_circular_convolution() {
        for (h, w) in [(8, 8), (5, 7), (6, 9)] {
            let fft = Fft2::new(h, w);
            let x: Vec<f64> = (0..h * w).map(|i| ((i * 37) % 11) as f64 - 3.0).collect();
            let back = fft.inverse(fft.forward(&x));
            for (a, b) in x.iter().zip(&back) {
                assert!((a - b).abs() < 1e-12);
            }
            // Convolution with a shifted delta is a circular shift.
            let mut delta = vec![0.0; h * w];
            delta[w + 2] = 1.0; // shift by (1, 2)
            let prod: Vec<_> = fft
                .forward(&x)
                .iter()
                .zip(fft.forward(&delta))
                .map(|(a, b)| a * b)
                .collect();
            let y = fft.inverse(prod);
            for r in 0..h {
                for c in 0..w {
                    let src = ((r + h - 1) % h) * w + (c + w - 2) % w;
                    assert!((y[r * w + c] - x[src]).abs() < 1e-12);
                }
            }
        }
    }
}
