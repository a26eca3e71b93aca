//! Two-dimensional real FFT built from `realfft` (rows) and `rustfft` (columns).
//!
//! Spectra are stored transposed: `W/2 + 1` rows (horizontal frequency) of `H`
//! complex values (vertical frequency), so that the column transforms run on
//! contiguous memory. Only pointwise products are ever taken of spectra, so
//! the layout is private to this module's users.
//!
//! `Fft2` is double precision; `Fft2<f32>` serves the split solver's
//! per-bin images, where single precision halves the memory traffic that
//! bounds the solver (BENCHMARKS.md).

use std::cell::RefCell;
use std::sync::Arc;

use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex;
use rustfft::num_traits::Zero;
use rustfft::{Fft, FftNum, FftPlanner};

/// A sample type the transforms run in (`f32` or `f64`), with this
/// thread's reused scratch for the column transforms.
pub trait FftFloat: FftNum {
    /// Runs `fft` in place on `buffer` with this thread's scratch.
    /// `Fft::process` would allocate and zero a buffer as large as the whole
    /// spectrum on every call (about 0.8 MB on the paper preset's padded
    /// grid, 42 times per split-solver iteration).
    fn process_columns(fft: &dyn Fft<Self>, buffer: &mut [Complex<Self>]);
}

macro_rules! column_scratch {
    ($t:ty, $name:ident) => {
        thread_local! {
            /// Scratch of the column transforms, grown to the largest plan used.
            static $name: RefCell<Vec<Complex<$t>>> = const { RefCell::new(Vec::new()) };
        }

        impl FftFloat for $t {
            fn process_columns(fft: &dyn Fft<$t>, buffer: &mut [Complex<$t>]) {
                $name.with_borrow_mut(|scratch| {
                    let need = fft.get_inplace_scratch_len();
                    if scratch.len() < need {
                        scratch.resize(need, Complex::zero());
                    }
                    fft.process_with_scratch(buffer, &mut scratch[..need]);
                });
            }
        }
    };
}

column_scratch!(f64, COLUMN_SCRATCH_F64);
column_scratch!(f32, COLUMN_SCRATCH_F32);

/// A planned H x W real 2-D transform; cheap to share between threads.
#[derive(Clone)]
pub struct Fft2<T: FftFloat = f64> {
    height: usize,
    width: usize,
    row_forward: Arc<dyn RealToComplex<T>>,
    row_inverse: Arc<dyn ComplexToReal<T>>,
    col_forward: Arc<dyn Fft<T>>,
    col_inverse: Arc<dyn Fft<T>>,
}

impl<T: FftFloat> Fft2<T> {
    /// Plans transforms for `height` x `width` images.
    pub fn new(height: usize, width: usize) -> Self {
        let mut real = RealFftPlanner::<T>::new();
        let mut complex = FftPlanner::<T>::new();
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

    /// Weight of each spectrum value in Parseval's sum over the whole
    /// plane: 1 for the horizontal frequencies stored once (zero and, for
    /// an even width, Nyquist), 2 for those that stand for a conjugate pair.
    pub fn parseval_weights(&self) -> Vec<f64> {
        let (h, w) = (self.height, self.width);
        (0..self.spectrum_len())
            .map(|i| {
                let kx = i / h;
                if kx == 0 || (w % 2 == 0 && kx == w / 2) {
                    1.0
                } else {
                    2.0
                }
            })
            .collect()
    }

    /// Forward transform of a row-major `height * width` image.
    pub fn forward(&self, image: &[T]) -> Vec<Complex<T>> {
        let mut spectrum = vec![Complex::zero(); self.spectrum_len()];
        self.forward_into(image, &mut spectrum);
        spectrum
    }

    /// Forward transform into a caller's buffer of [`Self::spectrum_len`]
    /// values (hot loops reuse their buffers).
    pub fn forward_into(&self, image: &[T], spectrum: &mut [Complex<T>]) {
        let (h, w) = (self.height, self.width);
        assert_eq!(image.len(), h * w, "image size does not match the plan");
        let wc = w / 2 + 1;
        assert_eq!(
            spectrum.len(),
            wc * h,
            "spectrum size does not match the plan"
        );
        let mut row = vec![T::zero(); w];
        let mut row_spec = vec![Complex::zero(); wc];
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
        T::process_columns(self.col_forward.as_ref(), spectrum);
    }

    /// Inverse transform, normalised so that `inverse(forward(x)) == x`.
    /// Consumes the spectrum as scratch.
    pub fn inverse(&self, mut spectrum: Vec<Complex<T>>) -> Vec<T> {
        let mut out = vec![T::zero(); self.height * self.width];
        self.inverse_into(&mut spectrum, &mut out);
        out
    }

    /// Inverse transform into a caller's buffer; the spectrum is used as
    /// scratch and left changed.
    pub fn inverse_into(&self, spectrum: &mut [Complex<T>], out: &mut [T]) {
        let (h, w) = (self.height, self.width);
        let wc = w / 2 + 1;
        assert_eq!(
            spectrum.len(),
            wc * h,
            "spectrum size does not match the plan"
        );
        assert_eq!(out.len(), h * w, "image size does not match the plan");
        T::process_columns(self.col_inverse.as_ref(), spectrum);
        let scale = T::from_f64(1.0 / (h * w) as f64).expect("a float type");
        let mut row_spec = vec![Complex::zero(); wc];
        let mut scratch = self.row_inverse.make_scratch_vec();
        for (y, dst) in out.chunks_exact_mut(w).enumerate() {
            for (kx, v) in row_spec.iter_mut().enumerate() {
                *v = spectrum[kx * h + y];
            }
            // A real signal has real DC and Nyquist terms; drop round-off.
            row_spec[0].im = T::zero();
            if w % 2 == 0 {
                row_spec[wc - 1].im = T::zero();
            }
            self.row_inverse
                .process_with_scratch(&mut row_spec, dst, &mut scratch)
                .expect("buffer sizes come from the plan");
            dst.iter_mut().for_each(|v| *v = *v * scale);
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

    #[test]
    fn single_precision_matches_double_to_its_round_off() {
        // The split solver's use: a smooth kernel (a Gaussian blob) times an
        // image's spectrum, on the paper preset's padded grid size.
        let (h, w) = (320, 320);
        let (f64t, f32t) = (Fft2::<f64>::new(h, w), Fft2::<f32>::new(h, w));
        let x: Vec<f64> = (0..h * w)
            .map(|i| 20.0 + 10.0 * (((i * 7919) % 101) as f64 / 101.0))
            .collect();
        let kernel: Vec<f64> = (0..h * w)
            .map(|i| {
                let (r, c) = ((i / w) as f64, (i % w) as f64);
                let (dr, dc) = (r.min(h as f64 - r), c.min(w as f64 - c));
                (-(dr * dr + dc * dc) / 50.0).exp()
            })
            .collect();
        let (xs, ks) = (f64t.forward(&x), f64t.forward(&kernel));
        let exact = f64t.inverse(xs.iter().zip(&ks).map(|(a, b)| a * b).collect());
        let single = |v: &[f64]| v.iter().map(|&a| a as f32).collect::<Vec<f32>>();
        let (xs32, ks32) = (f32t.forward(&single(&x)), f32t.forward(&single(&kernel)));
        let approx = f32t.inverse(xs32.iter().zip(&ks32).map(|(a, b)| a * b).collect());
        let peak = exact.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst = exact
            .iter()
            .zip(&approx)
            .fold(0.0f64, |m, (a, b)| m.max((a - f64::from(*b)).abs()));
        assert!(worst < 1e-6 * peak, "worst {worst:e} of peak {peak:e}");
        // And a round trip in single precision.
        let back = f32t.inverse(f32t.forward(&single(&x)));
        for (a, b) in x.iter().zip(&back) {
            assert!((a - f64::from(*b)).abs() < 1e-5 * a.abs());
        }
    }
}
