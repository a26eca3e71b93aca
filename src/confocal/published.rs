//! The published confocal diffuse tomography reconstruction (Lindell and
//! Wetzstein, Nature Communications 11, 4517 (2020)), step for step:
//!
//! 1. keep the bins of the first `depth` metres (417 bins of 16 ps for
//!    1 m: the round trip at the vacuum speed of light);
//! 2. resample each scan point's histogram linearly to `depth_samples`
//!    samples over the same interval, and scale the whole scan to a
//!    maximum of 1;
//! 3. zero-pad every axis to twice its length and Wiener-deconvolve the
//!    slab's in-and-out kernel ([`super::slab_kernel`]) with the constant
//!    `1 / snr`;
//! 4. f-k migration ([`super::stolt`]) and the first half of each axis;
//! 5. zero the last `trimmed_tail` depth samples (amplified noise).
//!
//! Two details are kept as published because users compare against them:
//! the kernel's time axis spans `4 depth / v` in `2 depth_samples` samples
//! (with `v = 3e8 / n`, about 58.6 ps per sample for 1 m and 128 samples,
//! while the resampled scan has about 52.5 ps per sample), and its lateral
//! axes span twice the calibrated scan side with the origin one sample off
//! centre. `scripts/cdt_reference.py` implements the same steps in numpy;
//! `tests/confocal_published.rs` compares the two.

use ndarray::{Array3, s};

use super::fft3::{Fft3, complex};
use super::slab_kernel::{KernelGrid, SlabOptics, in_and_out_spectrum};
use super::volume::HiddenVolume;
use super::{ConfocalError, ConfocalScan, stolt};
use crate::units::CM_PER_M;

/// Speed of light as the published code rounds it (m/s), used where it
/// sets the kernel's time axis.
pub const PUBLISHED_LIGHT_SPEED: f64 = 3e8;

/// Speed of light in vacuum (m/s): the physics crate's.
pub const LIGHT_SPEED: f64 = scatterscope_physics::diffusion::SPEED_OF_LIGHT_M_PER_S;

/// Settings of the published reconstruction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PublishedOptions {
    /// Wiener constant: the deconvolution divides by `|H|^2 + 1 / snr`
    /// (the authors chose 2.5e3 to 2e4 per scene).
    pub snr: f64,
    /// Depth behind the slab the volume covers (m).
    pub depth_m: f64,
    /// Samples along depth (and along the resampled time axis).
    pub depth_samples: usize,
    /// Last depth samples set to zero.
    pub trimmed_tail: usize,
}

impl Default for PublishedOptions {
    /// The published settings with the Wiener constant of the letter S
    /// and the letters U and T (1e4).
    fn default() -> Self {
        Self {
            snr: 1e4,
            depth_m: 1.0,
            depth_samples: 128,
            trimmed_tail: 15,
        }
    }
}

impl PublishedOptions {
    /// Checks the settings; errors name the setting and its value.
    pub fn validate(&self) -> Result<(), ConfocalError> {
        if !(self.snr.is_finite() && self.snr > 0.0) {
            return Err(ConfocalError::setting(
                "snr",
                format!(
                    "Wiener constant (snr) {} must be positive and finite",
                    self.snr
                ),
            ));
        }
        if !(self.depth_m.is_finite() && self.depth_m > 0.0) {
            return Err(ConfocalError::setting(
                "depth_m",
                format!("depth {} m must be positive and finite", self.depth_m),
            ));
        }
        if self.depth_samples < 4 {
            return Err(ConfocalError::setting(
                "depth_samples",
                format!(
                    "{} depth samples: at least 4 are needed",
                    self.depth_samples
                ),
            ));
        }
        if self.trimmed_tail >= self.depth_samples {
            return Err(ConfocalError::setting(
                "trimmed_tail",
                format!(
                    "{} trimmed samples leave nothing of {} depth samples",
                    self.trimmed_tail, self.depth_samples
                ),
            ));
        }
        Ok(())
    }
}

/// The authors' settings for their scans, by file stem prefix: the
/// calibrated scanned side (m) and the Wiener constant. The letter U scans
/// (`letter_u_50` ...) share one entry.
pub const AUTHORS_SETTINGS: [(&str, f64, f64); 8] = [
    ("letter_s", 0.6 * 1.06, 1e4),
    ("mannequin", 0.7 * 0.87, 2e4),
    ("letters_ut", 0.7, 1e4),
    ("letter_t", 0.7, 2.5e3),
    ("cones", 0.7, 2e4),
    ("resolution_50", 0.7 * 1.02, 1.5e4),
    ("resolution_70", 0.7 * 1.04, 1.5e4),
    ("letter_u", 0.7, 5e3),
];

/// The authors' (side, Wiener constant) for a scan named `stem`.
pub fn authors_settings(stem: &str) -> Option<(f64, f64)> {
    AUTHORS_SETTINGS
        .iter()
        .find(|(prefix, _, _)| stem.starts_with(prefix))
        .map(|&(_, side, snr)| (side, snr))
}

/// Bins of the round trip to `depth_m` at the vacuum speed of light.
pub fn crop_bins(depth_m: f64, bin_width_ps: f64) -> usize {
    (2.0 * depth_m / LIGHT_SPEED / (bin_width_ps * 1e-12)).round() as usize
}

/// Steps 1 and 2: the scan's first [`crop_bins`] bins after time zero
/// (zeros where the scan has none), resampled to `samples` per scan point
/// and scaled to a maximum of 1; (time, row, column).
pub fn cropped_resampled(
    scan: &ConfocalScan,
    depth_m: f64,
    samples: usize,
) -> Result<Array3<f64>, ConfocalError> {
    let (rows, cols, _) = scan.dim();
    let crop = crop_bins(depth_m, scan.bin_width_ps);
    if crop < 2 {
        return Err(ConfocalError::input(
            &scan.source,
            format!(
                "{depth_m} m of depth is {crop} bins of {} ps: too few to resample",
                scan.bin_width_ps
            ),
        ));
    }
    // Bins before time zero are dropped, missing ones are 0.
    let at = |k: usize, r: usize, c: usize| {
        scan.bin_after_zero(k)
            .map_or(0.0, |i| scan.counts[[i, r, c]])
    };
    let step = (crop - 1) as f64 / (samples - 1) as f64;
    let mut out = Array3::<f64>::zeros((samples, rows, cols));
    for j in 0..samples {
        let position = j as f64 * step;
        let lo = (position.floor() as usize).min(crop - 2);
        let frac = position - lo as f64;
        for r in 0..rows {
            for c in 0..cols {
                out[[j, r, c]] = at(lo, r, c) * (1.0 - frac) + at(lo + 1, r, c) * frac;
            }
        }
    }
    let max = out.iter().fold(0.0f64, |m, &v| m.max(v));
    if max <= 0.0 {
        let raw = (0..crop).any(|k| (0..rows).any(|r| (0..cols).any(|c| at(k, r, c) > 0.0)));
        return Err(ConfocalError::input(
            &scan.source,
            if raw {
                format!(
                    "the counts of the first {crop} bins ({depth_m} m of depth) all fall between the {samples} samples the published linear resampling reads"
                )
            } else {
                format!("no counts in the {crop} bins of the first {depth_m} m of depth")
            },
        ));
    }
    out /= max;
    Ok(out)
}

/// The published reconstruction of `scan` through a slab of `optics`.
pub fn reconstruct_published(
    scan: &ConfocalScan,
    optics: &SlabOptics,
    opts: &PublishedOptions,
) -> Result<HiddenVolume, ConfocalError> {
    opts.validate()?;
    let (rows, cols, _) = scan.dim();
    let nz = opts.depth_samples;
    let padded_dim = (2 * nz, 2 * rows, 2 * cols);
    let elements = (padded_dim.0 * padded_dim.1 * padded_dim.2) as u64;
    // Three complex volumes live at once (kernel, scan, migration).
    crate::memory::check(elements * 16 * 4, || {
        format!("the published reconstruction on a {padded_dim:?} grid")
    })?;
    let measured = cropped_resampled(scan, opts.depth_m, nz)?;
    let mut padded = Array3::<f64>::zeros(padded_dim);
    padded.slice_mut(s![..nz, ..rows, ..cols]).assign(&measured);

    let range = 4.0 * opts.depth_m;
    let linspace = |lo: f64, hi: f64, n: usize| -> Vec<f64> {
        (0..n)
            .map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
            .collect()
    };
    // The kernel in the optics' units: the scan's metres as cm, time in ps.
    let speed_cm_per_ps = PUBLISHED_LIGHT_SPEED * CM_PER_M * 1e-12 / optics.refractive_index;
    let side_cm = scan.side_m * CM_PER_M;
    let grid = KernelGrid {
        times_ps: linspace(0.0, range * CM_PER_M, 2 * nz)
            .into_iter()
            .map(|p| p / speed_cm_per_ps)
            .collect(),
        rows_cm: linspace(-side_cm, side_cm, 2 * rows),
        cols_cm: linspace(-side_cm, side_cm, 2 * cols),
        speed_cm_per_ps,
    };
    let transfer = in_and_out_spectrum(optics, &grid);
    let fft = Fft3::new(padded_dim);
    let mut spectrum = complex(&padded);
    fft.forward(&mut spectrum);
    let inverse_snr = 1.0 / opts.snr;
    ndarray::Zip::from(&mut spectrum)
        .and(&transfer)
        .par_for_each(|x, &h| *x *= h.conj() / (h.norm_sqr() + inverse_snr));
    fft.inverse(&mut spectrum);
    let deconvolved = spectrum.mapv(|z| z.re);
    let migrated = stolt::migrate(&deconvolved, scan.side_m, range);
    let mut data = migrated.slice(s![..nz, ..rows, ..cols]).to_owned();
    data.slice_mut(s![nz - opts.trimmed_tail.., .., ..])
        .fill(0.0);

    let crop = crop_bins(opts.depth_m, scan.bin_width_ps);
    let depth_step_m =
        (crop - 1) as f64 * scan.bin_width_ps * 1e-12 * LIGHT_SPEED / 2.0 / (nz - 1) as f64;
    Ok(HiddenVolume {
        data,
        depth_step_m,
        first_depth_m: 0.0,
        side_m: scan.side_m,
        notes: vec![
            format!(
                "published method: first {crop} bins ({} m of depth) resampled to {nz}, Wiener constant 1/{:e}, f-k migration; last {} depth samples zeroed",
                opts.depth_m, opts.snr, opts.trimmed_tail
            ),
            format!("slab: {}", optics.describe()),
        ],
    })
}

/// The published method with its settings.
#[derive(Debug, Clone, Copy)]
pub struct Published(pub PublishedOptions);

impl super::VolumeReconstructor for Published {
    fn reconstruct(
        &self,
        scan: &ConfocalScan,
        optics: &SlabOptics,
    ) -> Result<super::HiddenResult, ConfocalError> {
        reconstruct_published(scan, optics, &self.0).map(super::HiddenResult::volume)
    }
}
