//! Forward model: object -> expected photon counts per time bin -> Poisson counts.
//!
//! Each kept bin convolves the object with that bin's ST-PSF kernel, done
//! with real FFTs; kernel spectra are computed once when the model is built
//! and reused for every object. Two boundaries ([`Boundary`]):
//!
//! - [`Boundary::Sensor`] (the default): a real sensor. Light that lands off
//!   the sensor is lost, and object points outside the sensor's field send
//!   light into its edge pixels. The object lives on a grid padded by the
//!   kernel's support (`margin` pixels on every side, rounded up to an FFT
//!   size with factors 2, 3 and 5); only the sensor window is observed. On
//!   that grid the periodic FFT convolution is exactly the linear one inside
//!   the window, because no kernel reaches across the padding.
//! - [`Boundary::Periodic`]: wrap-around convolution on the sensor grid (the
//!   paper's simulation); grid and sensor coincide.
//!
//! Work that cannot change the answer is left out: the margin is the
//! smallest radius outside which every kernel carries less than
//! [`EDGE_TAIL`] of its light, far below the Poisson noise of any pixel.

use ndarray::parallel::prelude::*;
use ndarray::{Array2, Array3, ArrayView2, Axis, s};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson};
use rustfft::num_complex::Complex64;
use scatterscope_physics::KernelStack;
use serde::{Deserialize, Serialize};

use crate::fft2::Fft2;
use crate::named::named;

/// Fraction of a kernel's light that may fall outside the modelled margin.
pub const EDGE_TAIL: f64 = 1e-4;

/// How the edges of the sensor are modelled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Boundary {
    /// A sensor with edges: light off the sensor is lost, light from outside
    /// its field reaches the edge pixels (real sensors and the mock).
    #[default]
    Sensor,
    /// Wrap-around convolution on the sensor grid (the paper's simulation).
    Periodic,
}

named!(Boundary {
    Sensor => "sensor",
    Periodic => "periodic",
});

/// Convolution with cached kernel spectra on an object grid that holds the
/// sensor window.
#[derive(Clone)]
pub struct ForwardModel {
    fft: Fft2,
    spectra: Vec<Vec<Complex64>>,
    /// Object grid (rows, columns).
    grid: (usize, usize),
    /// Sensor window: top-left corner in the grid and its size.
    offset: (usize, usize),
    sensor: (usize, usize),
    boundary: Boundary,
    margin: usize,
    /// Background counts per sensor pixel and bin (dark counts, ambient
    /// light), uniform in time and space: the measurement is
    /// `Poisson(H_k o + background)`.
    background: f64,
}

/// Noise-free expected counts and what had to be corrected in them.
#[derive(Debug, Clone)]
pub struct Expected {
    /// K x H x W expected photon counts on the sensor, all finite and >= 0.
    pub counts: Array3<f64>,
    /// How many values FFT round-off made negative and were set to 0.
    pub clamped: usize,
    /// The most negative value before clamping (0 when none).
    pub most_negative: f64,
}

impl ForwardModel {
    /// Transforms every kept kernel once.
    pub fn new(kernels: &KernelStack, boundary: Boundary) -> Self {
        let all: Vec<usize> = (0..kernels.len()).collect();
        Self::with_bins(kernels, &all, boundary)
    }

    /// Transforms only the kept kernels listed in `bins` (stack order), e.g.
    /// the bins present in a measured stack.
    pub fn with_bins(kernels: &KernelStack, bins: &[usize], boundary: Boundary) -> Self {
        let (_, h, w) = kernels.kernels.dim();
        Self::build(kernels, bins, (h, w), boundary)
    }

    /// A sensor of `sensor` pixels (rows, columns) with edges
    /// ([`Boundary::Sensor`]) whose kernels were computed on larger arrays
    /// than the sensor: blurs wider than half the sensor, whose light from
    /// an object point reaches past the sensor's half-width.
    pub fn with_sensor(kernels: &KernelStack, sensor: (usize, usize)) -> Self {
        let all: Vec<usize> = (0..kernels.len()).collect();
        Self::build(kernels, &all, sensor, Boundary::Sensor)
    }

    fn build(
        kernels: &KernelStack,
        bins: &[usize],
        (h, w): (usize, usize),
        boundary: Boundary,
    ) -> Self {
        let (margin, grid) = match boundary {
            Boundary::Periodic => (0, (h, w)),
            Boundary::Sensor => {
                let margin = bins
                    .iter()
                    .map(|&k| edge_margin(kernels.kernel(k), EDGE_TAIL))
                    .max()
                    .unwrap_or(0);
                (margin, (fft_size(h + 2 * margin), fft_size(w + 2 * margin)))
            }
        };
        let offset = ((grid.0 - h) / 2, (grid.1 - w) / 2);
        let fft = Fft2::new(grid.0, grid.1);
        let spectra = bins
            .par_iter()
            .map(|&k| fft.forward(&origin_centred(kernels.kernel(k), grid, margin, boundary)))
            .collect();
        Self {
            fft,
            spectra,
            grid,
            offset,
            sensor: (h, w),
            boundary,
            margin,
            background: 0.0,
        }
    }

    /// The same model with `background` counts per pixel and bin added to
    /// every expected count (what the solvers fit; [`Self::expected`] stays
    /// `H o`).
    pub fn with_background(mut self, background: f64) -> Self {
        self.background = background;
        self
    }

    /// Background counts per sensor pixel and bin.
    pub fn background(&self) -> f64 {
        self.background
    }

    /// A one-bin model whose kernel is the sum of the kernels of `bins`
    /// (all bins: the time-summed ST-PSF), with their summed background.
    pub fn summed(&self, bins: &[usize]) -> Self {
        let mut sum = vec![Complex64::default(); self.fft.spectrum_len()];
        for &k in bins {
            sum.iter_mut()
                .zip(&self.spectra[k])
                .for_each(|(a, b)| *a += b);
        }
        Self {
            fft: self.fft.clone(),
            spectra: vec![sum],
            background: self.background * bins.len() as f64,
            ..*self
        }
    }

    /// Total kernel mass of bin `k`: the light a unit object pixel sends
    /// into the whole plane during the bin.
    pub fn mass(&self, k: usize) -> f64 {
        self.spectra[k][0].re
    }

    /// Number of time bins.
    pub fn bins(&self) -> usize {
        self.spectra.len()
    }

    /// The cached spectrum of kept bin `k` (layout of [`Fft2`]).
    pub fn spectrum(&self, k: usize) -> &[Complex64] {
        &self.spectra[k]
    }

    /// The planned transform of the object grid.
    pub fn fft(&self) -> &Fft2 {
        &self.fft
    }

    /// Object grid shape (rows, columns).
    pub fn grid_shape(&self) -> (usize, usize) {
        self.grid
    }

    /// Sensor shape (H, W): the shape of every count image.
    pub fn sensor_shape(&self) -> (usize, usize) {
        self.sensor
    }

    /// Top-left corner of the sensor window in the object grid.
    pub fn sensor_offset(&self) -> (usize, usize) {
        self.offset
    }

    /// The boundary model.
    pub fn boundary(&self) -> Boundary {
        self.boundary
    }

    /// Object pixels modelled beyond each sensor edge (0 when periodic).
    pub fn margin(&self) -> usize {
        self.margin
    }

    /// Whether grid pixel `(r, c)` lies in the sensor window.
    fn in_window(&self, r: usize, c: usize) -> bool {
        let (oy, ox) = self.offset;
        r >= oy && r < oy + self.sensor.0 && c >= ox && c < ox + self.sensor.1
    }

    /// A row-major grid image that is 1 in the sensor window and 0 outside.
    fn window_mask(&self) -> Vec<f64> {
        let (gh, gw) = self.grid;
        (0..gh * gw)
            .map(|i| f64::from(u8::from(self.in_window(i / gw, i % gw))))
            .collect()
    }

    /// The sensor window of a grid image.
    pub fn crop(&self, grid: ArrayView2<f64>) -> Array2<f64> {
        assert_eq!(grid.dim(), self.grid, "grid shape");
        let (oy, ox) = self.offset;
        let (h, w) = self.sensor;
        grid.slice(s![oy..oy + h, ox..ox + w]).to_owned()
    }

    /// A sensor-sized image placed in the window of a grid filled with `fill`.
    pub fn embed(&self, sensor: ArrayView2<f64>, fill: f64) -> Array2<f64> {
        assert_eq!(sensor.dim(), self.sensor, "sensor shape");
        let (oy, ox) = self.offset;
        let (h, w) = self.sensor;
        let mut out = Array2::from_elem(self.grid, fill);
        out.slice_mut(s![oy..oy + h, ox..ox + w]).assign(&sensor);
        out
    }

    /// Expected counts of a scene that fills the sensor's field and is dark
    /// outside it (simulations and the mock device).
    pub fn expected_scene(&self, scene: ArrayView2<f64>) -> Expected {
        self.expected(self.embed(scene, 0.0).view())
    }

    /// `H_k^T r` on the grid for `r` on the sensor window (row-major).
    pub fn adjoint(&self, k: usize, r: &[f64]) -> Vec<f64> {
        self.fft.inverse(self.adjoint_spectrum(k, r))
    }

    /// The spectrum of `H_k^T r` (so that several bins' back-projections
    /// can be summed before one inverse transform).
    pub fn adjoint_spectrum(&self, k: usize, r: &[f64]) -> Vec<Complex64> {
        self.adjoint_spectrum_with(&self.spectra[k], r)
    }

    /// [`Self::adjoint_spectrum`] for any kernel given by its spectrum on
    /// this model's grid (e.g. a combination of bins' kernels).
    pub fn adjoint_spectrum_with(&self, kernel: &[Complex64], r: &[f64]) -> Vec<Complex64> {
        self.fft
            .forward(&self.embed_vec(r))
            .iter()
            .zip(kernel)
            .map(|(a, b)| a * b.conj())
            .collect()
    }

    /// `H_k x` on the sensor window (row-major) for `x` on the grid.
    pub fn apply(&self, k: usize, x: &[f64]) -> Vec<f64> {
        self.apply_spectrum(k, &self.fft.forward(x))
    }

    /// `H_k x` on the sensor window, from the spectrum of `x`.
    pub fn apply_spectrum(&self, k: usize, x_spec: &[Complex64]) -> Vec<f64> {
        self.apply_spectrum_with(&self.spectra[k], x_spec)
    }

    /// [`Self::apply_spectrum`] for any kernel given by its spectrum on this
    /// model's grid.
    pub fn apply_spectrum_with(&self, kernel: &[Complex64], x_spec: &[Complex64]) -> Vec<f64> {
        let prod = x_spec.iter().zip(kernel).map(|(a, b)| a * b).collect();
        self.crop_vec(&self.fft.inverse(prod))
    }

    /// The window of a row-major grid vector, row-major.
    pub fn crop_vec(&self, grid: &[f64]) -> Vec<f64> {
        let (_, gw) = self.grid;
        let (oy, ox) = self.offset;
        let (h, w) = self.sensor;
        let mut out = Vec::with_capacity(h * w);
        for r in oy..oy + h {
            out.extend_from_slice(&grid[r * gw + ox..r * gw + ox + w]);
        }
        out
    }

    /// A row-major sensor vector placed in a zero grid vector.
    pub fn embed_vec(&self, sensor: &[f64]) -> Vec<f64> {
        let (gh, gw) = self.grid;
        let (oy, ox) = self.offset;
        let (h, w) = self.sensor;
        let mut out = vec![0.0; gh * gw];
        for (r, src) in sensor.chunks_exact(w).enumerate().take(h) {
            out[(oy + r) * gw + ox..(oy + r) * gw + ox + w].copy_from_slice(src);
        }
        out
    }

    /// `sum_k H_k^T 1_window`: how much of each object pixel's light the
    /// sensor sees over the listed bins (the kernel mass everywhere for a
    /// periodic model; less near and beyond the edges of a sensor).
    pub fn sensitivity(&self, bins: &[usize]) -> Vec<f64> {
        let mut spec = vec![Complex64::default(); self.fft.spectrum_len()];
        for &k in bins {
            spec.iter_mut()
                .zip(&self.spectra[k])
                .for_each(|(a, b)| *a += b.conj());
        }
        if self.boundary == Boundary::Periodic {
            return vec![spec[0].re; self.grid.0 * self.grid.1];
        }
        let mask = self.fft.forward(&self.window_mask());
        let prod = mask.iter().zip(&spec).map(|(a, b)| a * b).collect();
        self.fft
            .inverse(prod)
            .into_iter()
            .map(|v| v.max(0.0))
            .collect()
    }

    /// Expected counts on the sensor for `object` on the grid (values are
    /// transmittances, normally in [0, 1]).
    ///
    /// Panics if the object's shape differs from the grid's.
    pub fn expected(&self, object: ArrayView2<f64>) -> Expected {
        assert_eq!(object.dim(), self.grid, "object shape");
        let obj: Vec<f64> = object.iter().copied().collect();
        let obj_spec = self.fft.forward(&obj);
        let slices: Vec<Vec<f64>> = (0..self.bins())
            .into_par_iter()
            .map(|k| self.apply_spectrum(k, &obj_spec))
            .collect();
        let (h, w) = self.sensor;
        let mut counts = Array3::<f64>::zeros((self.bins(), h, w));
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

/// Smallest radius r such that the part of `kernel` (centred, offset 0 at
/// (H/2, W/2)) outside the square of half-side r carries at most `tail` of
/// its mass.
pub fn edge_margin(kernel: ArrayView2<f64>, tail: f64) -> usize {
    let (h, w) = kernel.dim();
    let (cy, cx) = (h / 2, w / 2);
    let mut by_distance = vec![0.0f64; h.max(w) + 1];
    for ((r, c), &v) in kernel.indexed_iter() {
        by_distance[r.abs_diff(cy).max(c.abs_diff(cx))] += v;
    }
    let total: f64 = by_distance.iter().sum();
    if total <= 0.0 {
        return 0;
    }
    let mut outside = total;
    for (d, &m) in by_distance.iter().enumerate() {
        outside -= m;
        if outside <= tail * total {
            return d;
        }
    }
    by_distance.len() - 1
}

/// Smallest n' >= n whose only prime factors are 2, 3 and 5 (fast FFT sizes).
pub fn fft_size(n: usize) -> usize {
    (n.max(1)..)
        .find(|&m| {
            let mut m = m;
            for p in [2, 3, 5] {
                while m % p == 0 {
                    m /= p;
                }
            }
            m == 1
        })
        .expect("a 5-smooth number exists above every n")
}

/// Places a centred kernel (offset 0 at (H/2, W/2)) on a `grid` with offset
/// 0 at (0, 0): every offset for a periodic model, offsets within `margin`
/// for a sensor.
fn origin_centred(
    kernel: ArrayView2<f64>,
    grid: (usize, usize),
    margin: usize,
    boundary: Boundary,
) -> Vec<f64> {
    let (h, w) = kernel.dim();
    let (gh, gw) = grid;
    let mut out = vec![0.0; gh * gw];
    for ((y, x), &v) in kernel.indexed_iter() {
        let (dy, dx) = (y as i64 - (h / 2) as i64, x as i64 - (w / 2) as i64);
        if boundary == Boundary::Sensor
            && (dy.unsigned_abs().max(dx.unsigned_abs()) as usize) > margin
        {
            continue;
        }
        let yy = dy.rem_euclid(gh as i64) as usize;
        let xx = dx.rem_euclid(gw as i64) as usize;
        out[yy * gw + xx] = v;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fft_sizes_are_5_smooth_and_minimal() {
        assert_eq!(fft_size(1), 1);
        assert_eq!(fft_size(7), 8);
        assert_eq!(fft_size(310), 320);
        assert_eq!(fft_size(257), 270);
    }

    #[test]
    fn edge_margin_of_a_box_kernel() {
        let mut k = Array2::<f64>::zeros((11, 11));
        k.slice_mut(s![3..8, 3..8]).fill(1.0); // half-side 2 around (5, 5)
        assert_eq!(edge_margin(k.view(), 0.0), 2);
        // Outside radius 1 lies 16 of 25.
        assert_eq!(edge_margin(k.view(), 0.7), 1);
        assert_eq!(edge_margin(k.view(), 1.0), 0);
    }
}
