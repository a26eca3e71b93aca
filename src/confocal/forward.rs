//! The confocal forward model in counts: a hidden volume's expected photon
//! counts per scan point and time bin,
//!
//! ```text
//! mu = K * (A rho) + b
//! ```
//!
//! `A` the free-space light-cone operator ([`super::light_cone`]), `K` the
//! slab's in-and-out kernel (a three-dimensional convolution over time and
//! the scan's lateral offsets, by FFT), `b` a background per time bin
//! shared by every scan point (dark counts and the slab's own late light).
//!
//! The in-and-out kernel follows from the physics crate's slab
//! transmittance `T(t)` (the model `calibrate-slab` fits) at the medium's
//! parameters: light spends `t1` in the slab going in and `t2` coming out,
//! and its lateral spread is Gaussian with variance `2 D v (t1 + t2)` per
//! axis, which depends only on the total `t`; so the kernel is the temporal
//! self-convolution `(T * T)(t)` times that Gaussian, integrated over each
//! time bin and each scan cell.

use ndarray::{Array1, Array3, ArrayView3, Zip, s};
use ndrustfft::Complex;
use scatterscope_physics::diffusion::{gaussian_interval_fraction, light_speed_cm_per_ps};
use scatterscope_physics::slab::SlabTransmittance;

use super::fft3::{Fft3, complex};
use super::light_cone::{ConeGrid, LightCone};
use super::slab_kernel::SlabOptics;
use crate::forward::fft_size;

/// Fine time samples per bin when the kernel is built.
const KERNEL_SUBSAMPLES: usize = 8;

/// The kernel is cut where the slab's transmittance has fallen below this
/// fraction of its peak.
const KERNEL_TAIL: f64 = 1e-7;

/// The slab's transmittance model at `optics` (the physics crate's, with
/// `optics`' source depth and extrapolation distance).
pub fn slab_transmittance(optics: &SlabOptics) -> SlabTransmittance {
    let c_cm_per_ps = light_speed_cm_per_ps(optics.refractive_index);
    SlabTransmittance {
        thickness_cm: optics.thickness_cm,
        source_depth_cm: optics.source_depth_cm,
        extrapolation_cm: optics.extrapolation_cm,
        dc_cm2_per_ps: optics.diffusion_cm() * c_cm_per_ps,
        absorption_per_ps: optics.mu_a_per_cm * c_cm_per_ps,
    }
}

/// The in-and-out kernel on `bins` time bins of `bin_ps` and lateral
/// offsets `spacing_m` apart, indexed (time, row offset, column offset)
/// with offsets from `-(rows - 1)` to `rows - 1` stored at
/// `offset + rows - 1`.
pub fn in_and_out_kernel(
    optics: &SlabOptics,
    bins: usize,
    bin_ps: f64,
    rows: usize,
    cols: usize,
    spacing_m: f64,
) -> Array3<f64> {
    let slab = slab_transmittance(optics);
    let fine = bin_ps / KERNEL_SUBSAMPLES as f64;
    let peak = slab.peak_time_ps();
    let top = slab.log_density(peak);
    // Fine samples (at their centres) until the tail is negligible.
    let mut once = Vec::new();
    loop {
        let t = (once.len() as f64 + 0.5) * fine;
        let log = slab.log_density(t);
        once.push(if log.is_finite() {
            (log - top).exp()
        } else {
            0.0
        });
        if (t > peak && log - top < KERNEL_TAIL.ln()) || once.len() >= bins * KERNEL_SUBSAMPLES {
            break;
        }
    }
    // Self-convolution: sample n of the sum of two delays sits at
    // (n + 1) fine steps.
    let n = once.len();
    let mut twice = vec![0.0; 2 * n - 1];
    for (i, a) in once.iter().enumerate() {
        for (j, b) in once.iter().enumerate() {
            twice[i + j] += a * b;
        }
    }
    let mut per_bin = Array1::<f64>::zeros(bins);
    let mut mean_t = Array1::<f64>::zeros(bins);
    for (k, w) in twice.iter().enumerate() {
        let t = (k + 1) as f64 * fine;
        let bin = (t / bin_ps).floor() as usize;
        if bin < bins {
            per_bin[bin] += w;
            mean_t[bin] += w * t;
        }
    }
    let total = per_bin.sum();
    let d_c_cm2_per_ps = slab.dc_cm2_per_ps;
    let (nr, nc) = (2 * rows - 1, 2 * cols - 1);
    let mut kernel = Array3::<f64>::zeros((bins, nr, nc));
    let spacing_cm = spacing_m * crate::units::CM_PER_M;
    for i in 0..bins {
        if per_bin[i] <= 0.0 {
            continue;
        }
        let t = mean_t[i] / per_bin[i];
        // exp(-x^2 / s^2) with s^2 = 4 D c t: variance 2 D c t per axis.
        let s_cm = (4.0 * d_c_cm2_per_ps * t).sqrt();
        let cell = |offset: i64| {
            let x = offset as f64 * spacing_cm;
            gaussian_interval_fraction(x - 0.5 * spacing_cm, x + 0.5 * spacing_cm, s_cm)
        };
        let gr: Vec<f64> = (0..nr)
            .map(|a| cell(a as i64 - (rows as i64 - 1)))
            .collect();
        let gc: Vec<f64> = (0..nc)
            .map(|b| cell(b as i64 - (cols as i64 - 1)))
            .collect();
        let weight = per_bin[i] / total;
        for a in 0..nr {
            for b in 0..nc {
                kernel[[i, a, b]] = weight * gr[a] * gc[b];
            }
        }
    }
    kernel
}

/// The kernel's lateral reach ends where an offset carries less than this
/// fraction of its light.
const LATERAL_TAIL: f64 = 1e-3;

/// The slab's blur as a linear map from a transient on the widened grid
/// (time, rows + 2 reach, cols + 2 reach) to expected counts on the scan
/// grid, by FFT on a grid large enough that nothing wraps.
pub struct SlabBlur {
    /// Time bins of the transient.
    bins: usize,
    /// Time bins of the counts (the transient's and up to the kernel's
    /// length more, where the scan has them).
    pub count_bins: usize,
    rows: usize,
    cols: usize,
    /// Scan points the transient's grid reaches beyond each edge.
    pub reach: usize,
    spectrum: Array3<Complex<f64>>,
    fft: Fft3,
}

impl SlabBlur {
    /// The in-and-out kernel of `optics` on `bins` time bins of `bin_ps`
    /// and scan points `spacing_m` apart, counts observed on up to
    /// `available` bins (at least `bins`, at most a kernel's length more).
    pub fn new(
        optics: &SlabOptics,
        bins: usize,
        available: usize,
        bin_ps: f64,
        rows: usize,
        cols: usize,
        spacing_m: f64,
    ) -> Self {
        let full = in_and_out_kernel(optics, bins, bin_ps, rows, cols, spacing_m);
        let kt = full.dim().0;
        let (cr, cc) = (rows - 1, cols - 1);
        // Lateral reach: offsets that carry at least LATERAL_TAIL of the
        // kernel's light (summed over time and the other axis).
        let along = |a: usize| full.slice(s![.., cr + a, ..]).sum();
        let total = full.sum().max(1e-300);
        let reach = (0..=cr.min(cc))
            .rev()
            .find(|&a| along(a) > LATERAL_TAIL * total)
            .unwrap_or(0);
        let length = (0..kt)
            .rev()
            .find(|&i| full[[i, cr, cc]] > 0.0)
            .map_or(1, |i| i + 1);
        let dim = (
            fft_size(bins + length),
            fft_size(rows + 4 * reach),
            fft_size(cols + 4 * reach),
        );
        let mut padded = Array3::<f64>::zeros(dim);
        for i in 0..length {
            for a in -(reach as i64)..=reach as i64 {
                for b in -(reach as i64)..=reach as i64 {
                    let w = full[[i, (cr as i64 + a) as usize, (cc as i64 + b) as usize]];
                    padded[[
                        i,
                        a.rem_euclid(dim.1 as i64) as usize,
                        b.rem_euclid(dim.2 as i64) as usize,
                    ]] += w;
                }
            }
        }
        let fft = Fft3::new(dim);
        let mut spectrum = complex(&padded);
        fft.forward(&mut spectrum);
        Self {
            bins,
            count_bins: available.clamp(bins, bins + length),
            rows,
            cols,
            reach,
            spectrum,
            fft,
        }
    }

    /// Shape of the transient: (bins, rows + 2 reach, cols + 2 reach).
    pub fn transient_dim(&self) -> (usize, usize, usize) {
        (
            self.bins,
            self.rows + 2 * self.reach,
            self.cols + 2 * self.reach,
        )
    }

    /// Expected counts (scan grid) of `tau` (widened grid), background
    /// left out.
    pub fn forward(&self, tau: &Array3<f64>) -> Array3<f64> {
        self.convolve(tau, None, false, |out| out.mapv(|z| z.re.max(0.0)))
    }

    /// [`Self::forward`] of two transients at the cost of one: the kernel
    /// is real, so the blur of `a + i b` is the blur of `a` plus `i` times
    /// the blur of `b` (the two halves of the Poisson stop share every
    /// transform).
    pub fn forward_pair(&self, a: &Array3<f64>, b: &Array3<f64>) -> (Array3<f64>, Array3<f64>) {
        self.convolve(a, Some(b), false, split)
    }

    /// The transpose of [`Self::forward`].
    pub fn adjoint(&self, counts: &Array3<f64>) -> Array3<f64> {
        self.convolve(counts, None, true, |out| out.mapv(|z| z.re.max(0.0)))
    }

    /// [`Self::adjoint`] of two count volumes at the cost of one (see
    /// [`Self::forward_pair`]).
    pub fn adjoint_pair(&self, a: &Array3<f64>, b: &Array3<f64>) -> (Array3<f64>, Array3<f64>) {
        self.convolve(a, Some(b), true, split)
    }

    /// `re + i im` (`im` 0 when absent) through the blur, or with
    /// `adjoint` its transpose (transient grid to counts, or back), by FFT
    /// on the padded grid; `read` takes the output's region.
    fn convolve<T>(
        &self,
        re: &Array3<f64>,
        im: Option<&Array3<f64>>,
        adjoint: bool,
        read: impl FnOnce(ArrayView3<Complex<f64>>) -> T,
    ) -> T {
        let (m, wr, wc) = self.transient_dim();
        let r = self.reach;
        let transient = s![..m, ..wr, ..wc];
        let counts = s![..self.count_bins, r..r + self.rows, r..r + self.cols];
        let (input, output) = if adjoint {
            (counts, transient)
        } else {
            (transient, counts)
        };
        let mut padded = Array3::<Complex<f64>>::zeros(self.spectrum.dim());
        let mut region = padded.slice_mut(input);
        match im {
            Some(im) => Zip::from(&mut region)
                .and(re)
                .and(im)
                .for_each(|d, &x, &y| *d = Complex::new(x, y)),
            None => Zip::from(&mut region).and(re).for_each(|d, &x| d.re = x),
        }
        self.fft.forward(&mut padded);
        Zip::from(&mut padded)
            .and(&self.spectrum)
            .par_for_each(|p, &h| *p *= if adjoint { h.conj() } else { h });
        self.fft.inverse(&mut padded);
        read(padded.slice(output))
    }
}

/// The real and imaginary parts of a paired result, each non-negative.
fn split(out: ArrayView3<Complex<f64>>) -> (Array3<f64>, Array3<f64>) {
    (out.mapv(|z| z.re.max(0.0)), out.mapv(|z| z.im.max(0.0)))
}

/// The whole model on one scan grid: the light cone, then the slab's blur
/// of its transient (no light enters beyond the scan's edge).
pub struct ConfocalModel {
    cone: LightCone,
    blur: SlabBlur,
}

impl ConfocalModel {
    /// The model on `grid` (time bins of `bin_ps`) through a slab of
    /// `optics`.
    pub fn new(grid: ConeGrid, bin_ps: f64, optics: &SlabOptics) -> Self {
        let (m, rows, cols) = (grid.depths, grid.rows, grid.cols);
        Self {
            cone: LightCone::new(grid, 2),
            blur: SlabBlur::new(optics, m, m, bin_ps, rows, cols, grid.spacing_m),
        }
    }

    /// `K * (A rho)`: the expected counts without background.
    pub fn forward(&self, volume: &Array3<f64>) -> Array3<f64> {
        let transient = self.cone.forward(volume);
        let (m, rows, cols) = transient.dim();
        let r = self.blur.reach;
        let mut widened = Array3::<f64>::zeros(self.blur.transient_dim());
        widened
            .slice_mut(s![..m, r..r + rows, r..r + cols])
            .assign(&transient);
        self.blur.forward(&widened)
    }

    /// Expected counts with `background[i]` added to every point of bin
    /// `i` (time bin 0 starts at time zero, the pulse at the slab's face).
    pub fn expected_counts(&self, volume: &Array3<f64>, background: &[f64]) -> Array3<f64> {
        let mut mu = self.forward(volume);
        for (mut plane, &b) in mu.outer_iter_mut().zip(background) {
            plane += b;
        }
        mu
    }

    /// The transpose of [`Self::forward`] (rounding aside).
    pub fn adjoint(&self, counts: &Array3<f64>) -> Array3<f64> {
        let (_, rows, cols) = counts.dim();
        let r = self.blur.reach;
        let widened = self.blur.adjoint(counts);
        let transient = widened.slice(s![.., r..r + rows, r..r + cols]).to_owned();
        let mut out = self.cone.adjoint(&transient);
        out.mapv_inplace(|v| v.max(0.0));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scatterscope_physics::{Diffusion, Medium, MediumModel};

    /// The slab model here is the one `calibrate-slab` fits: the physics
    /// crate's slab transmittance for the same medium, field for field and
    /// bit for bit.
    #[test]
    fn slab_kernel_is_the_calibrate_slab_transmittance() {
        let medium = Medium {
            mu_a_per_cm: 0.0048,
            mu_s_per_cm: 2.72,
            g: 0.0,
            refractive_index: 1.12,
            thickness_cm: 2.54,
            model: MediumModel::Slab,
        };
        let ours = slab_transmittance(&SlabOptics::from_medium(&medium).unwrap());
        let theirs = Diffusion::new(&medium).unwrap().slab.unwrap();
        assert_eq!(ours, theirs);
    }

    /// The in-and-out kernel has unit mass, its mean delay is twice the
    /// slab's mean transit time, and its lateral spread per bin is the
    /// diffusion Gaussian of the total time.
    #[test]
    fn in_and_out_kernel_doubles_the_transit() {
        let optics = SlabOptics::PUBLISHED_FOAM;
        let bin = 48.0;
        let k = in_and_out_kernel(&optics, 200, bin, 9, 9, 0.02);
        let profile: Vec<f64> = k.outer_iter().map(|p| p.sum()).collect();
        let mass: f64 = profile.iter().sum();
        assert!((mass - 1.0).abs() < 1e-3, "mass {mass}");
        let mean = profile
            .iter()
            .enumerate()
            .map(|(i, w)| (i as f64 + 0.5) * bin * w)
            .sum::<f64>();
        let slab = slab_transmittance(&optics);
        let dt = 1.0;
        let (mut m0, mut m1) = (0.0, 0.0);
        for i in 1..20_000 {
            let t = i as f64 * dt;
            let w = slab.log_density(t).exp();
            m0 += w;
            m1 += w * t;
        }
        let transit = m1 / m0;
        assert!(
            (mean - 2.0 * transit).abs() < 0.5 * bin,
            "{mean} vs 2 x {transit}"
        );
    }
}
