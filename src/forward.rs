//! Forward model: object -> expected photon counts per time bin -> Poisson counts.
//!
//! Each kept bin is a block-circulant (periodic) convolution of the object
//! with that bin's ST-PSF kernel, done with real FFTs. Kernel spectra are
//! computed once when the model is built and reused for every object.

use ndarray::parallel::prelude::*;
use ndarray::{Array3, ArrayView2, Axis};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson};
use rustfft::num_complex::Complex64;
use scatterscope_physics::KernelStack;

use crate::fft2::Fft2;

/// Block-circulant convolution with cached kernel spectra.
pub struct ForwardModel {
    fft: Fft2,
    spectra: Vec<Vec<Complex64>>,
    height: usize,
    width: usize,
}

/// Noise-free expected counts and what had to be corrected in them.
#[derive(Debug, Clone)]
pub struct Expected {
    /// K x H x W expected photon counts, all finite and >= 0.
    pub counts: Array3<f64>,
    /// How many values FFT round-off made negative and were set to 0.
    pub clamped: usize,
    /// The most negative value before clamping (0 when none).
    pub most_negative: f64,
}

impl ForwardModel {
    /// Transforms every kept kernel once.
    pub fn new(kernels: &KernelStack) -> Self {
        let all: Vec<usize> = (0..kernels.len()).collect();
        Self::with_bins(kernels, &all)
    }

    /// Transforms only the kept kernels listed in `bins` (stack order), e.g.
    /// the bins present in a measured stack.
    pub fn with_bins(kernels: &KernelStack, bins: &[usize]) -> Self {
        let (_, h, w) = kernels.kernels.dim();
        let fft = Fft2::new(h, w);
        let spectra = bins
            .par_iter()
            .map(|&k| fft.forward(&origin_centred(kernels.kernel(k))))
            .collect();
        Self {
            fft,
            spectra,
            height: h,
            width: w,
        }
    }

    /// Number of time bins.
    pub fn bins(&self) -> usize {
        self.spectra.len()
    }

    /// The cached spectrum of kept bin `k` (layout of [`Fft2`]).
    pub fn spectrum(&self, k: usize) -> &[Complex64] {
        &self.spectra[k]
    }

    /// The planned transform the spectra belong to.
    pub fn fft(&self) -> &Fft2 {
        &self.fft
    }

    /// Image shape (H, W).
    pub fn shape(&self) -> (usize, usize) {
        (self.height, self.width)
    }

    /// Expected counts for `object` (values are transmittances, normally in [0, 1]).
    ///
    /// Panics if the object's shape differs from the kernels'.
    pub fn expected(&self, object: ArrayView2<f64>) -> Expected {
        assert_eq!(object.dim(), (self.height, self.width), "object shape");
        let obj: Vec<f64> = object.iter().copied().collect();
        let obj_spec = self.fft.forward(&obj);
        let slices: Vec<Vec<f64>> = self
            .spectra
            .par_iter()
            .map(|ks| {
                let prod = obj_spec.iter().zip(ks).map(|(a, b)| a * b).collect();
                self.fft.inverse(prod)
            })
            .collect();
        let mut counts = Array3::<f64>::zeros((self.bins(), self.height, self.width));
        let mut clamped = 0;
        let mut most_negative = 0.0f64;
        for (mut dst, src) in counts.axis_iter_mut(Axis(0)).zip(slices) {
            for (d, v) in dst.iter_mut().zip(src) {
                if v < 0.0 {
                    clamped += 1;
                    most_negative = most_negative.min(v);
                    *d = 0.0;
                } else {
                    *d = v;
                }
            }
        }
        Expected {
            counts,
            clamped,
            most_negative,
        }
    }
}

/// Moves a centred kernel (offset 0 at (H/2, W/2)) so that offset 0 sits at (0, 0).
fn origin_centred(kernel: ArrayView2<f64>) -> Vec<f64> {
    let (h, w) = kernel.dim();
    let mut out = vec![0.0; h * w];
    for ((y, x), &v) in kernel.indexed_iter() {
        let (yy, xx) = ((y + h - h / 2) % h, (x + w - w / 2) % w);
        out[yy * w + xx] = v;
    }
    out
}

/// Draws Poisson counts with the given expected values; deterministic for a
/// seed, independent of thread count (each bin has its own stream).
pub fn poisson_counts(expected: &Array3<f64>, seed: u64) -> Array3<f64> {
    let mut out = Array3::<f64>::zeros(expected.dim());
    out.axis_iter_mut(Axis(0))
        .into_par_iter()
        .zip(expected.axis_iter(Axis(0)))
        .enumerate()
        .for_each(|(k, (mut dst, src))| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(k as u64);
            for (d, &lambda) in dst.iter_mut().zip(src) {
                *d = poisson(lambda, &mut rng);
            }
        });
    out
}

fn poisson(lambda: f64, rng: &mut ChaCha8Rng) -> f64 {
    if lambda > 0.0 {
        Poisson::new(lambda)
            .expect("finite positive mean below the sampler's limit")
            .sample(rng)
    } else {
        0.0
    }
}
