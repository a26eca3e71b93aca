//! The Poisson reconstruction of a hidden volume: the slab's blur is
//! undone by maximum likelihood of the photon counts, then free space by
//! f-k migration.
//!
//! The counts are modelled as `m ~ Poisson(K * tau + b)`: `tau >= 0` the
//! free-space confocal transient at the slab's far face (estimated on the
//! scan grid widened by the kernel's lateral reach, so that light entering
//! beyond the scan's edge is accounted for), `K` the slab's in-and-out
//! kernel from the physics crate's diffusion transmittance
//! ([`super::forward::in_and_out_kernel`]), `b` a background per time bin
//! shared by every scan point (dark counts, the slab's own late light).
//! Expectation maximisation (the Richardson-Lucy update with a background)
//! estimates `tau` and `b`. The scan's bins are summed in groups (every
//! photon kept, where the published method's point resampling reads about
//! 60 % of the bins) to about `step` of depth per bin; bins before the
//! first one with any count are taken as gated off by the detector and
//! left out of the likelihood.
//!
//! The stop: the counts are thinned into two halves (each photon to either
//! with probability 1/2, seeded); each half is reconstructed on its own
//! and, after every iteration, scored by the Poisson deviance of the other
//! half's counts; the transient is the sum of the two halves' at the
//! iteration that scored best, as the Richardson-Lucy stop of
//! `reconstruct` does. The two halves share every transform, packed as
//! the real and imaginary parts of one volume
//! ([`SlabBlur::forward_pair`]). Nothing is chosen per scan. The
//! transient's square root is then migrated ([`super::stolt`]) to the
//! volume.

use std::time::Instant;

use ndarray::{Array1, Array3, Axis, Zip, s};

use super::forward::SlabBlur;
use super::published::{LIGHT_SPEED, crop_bins};
use super::slab_kernel::SlabOptics;
use super::volume::HiddenVolume;
use super::{ConfocalError, ConfocalScan, stolt};
use crate::poisson::deviance::volume_deviance;
use crate::poisson::thinning::halves;

/// Seed of the halves' thinning.
pub const HALVES_SEED: u64 = 0x5ca7_2026;

/// Fraction of the largest sensitivity below which a transient element is
/// not estimated.
const SENSITIVITY_FLOOR: f64 = 0.1;

/// Settings of the Poisson reconstruction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoissonOptions {
    /// Depth behind the slab the volume covers (m).
    pub depth_m: f64,
    /// Depth per bin the scan's bins are summed to, about (m).
    pub step_m: f64,
    /// Most iterations the stop searches (150 keeps a 32 x 32 scan near
    /// 8 s on two cores; at full counts the held-out deviance is still
    /// falling there, past 1000 iterations on letter_s, and the notes say
    /// so).
    pub max_iters: usize,
}

impl Default for PoissonOptions {
    fn default() -> Self {
        Self {
            depth_m: 1.0,
            step_m: 0.0072,
            max_iters: 150,
        }
    }
}

/// One iteration of the search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoissonTraceRow {
    /// Iteration (0: the flat start).
    pub iteration: usize,
    /// Seconds since the reconstruction began.
    pub wall_s: f64,
    /// Each half's deviance on the other half's counts, summed.
    pub held_out_deviance: f64,
}

/// One half's estimate: transient and background per bin.
#[derive(Clone)]
struct Estimate {
    tau: Array3<f64>,
    background: Array1<f64>,
}

/// `counts / mu` over the bins from `onset` (0 before it and where `mu`
/// is 0): what the EM step projects back.
fn ratio(counts: &Array3<f64>, mu: &Array3<f64>, onset: usize) -> Array3<f64> {
    let mut ratio = Array3::<f64>::zeros(counts.dim());
    Zip::from(ratio.slice_mut(s![onset.., .., ..]))
        .and(counts.slice(s![onset.., .., ..]))
        .and(mu.slice(s![onset.., .., ..]))
        .for_each(|r, &y, &m| *r = if m > 0.0 { y / m } else { 0.0 });
    ratio
}

/// The EM step of `e` given its `ratio` and that ratio projected back.
fn em_step(
    e: &Estimate,
    ratio: &Array3<f64>,
    back: &Array3<f64>,
    sensitivity: &Array3<f64>,
    onset: usize,
) -> Estimate {
    let points = (ratio.dim().1 * ratio.dim().2) as f64;
    let mut tau = e.tau.clone();
    Zip::from(&mut tau)
        .and(back)
        .and(sensitivity)
        .par_for_each(|v, &b, &s| *v = if s > 0.0 { *v * b / s } else { 0.0 });
    let mut background = e.background.clone();
    for (i, b) in background.iter_mut().enumerate().skip(onset) {
        *b *= ratio.index_axis(Axis(0), i).sum() / points;
    }
    Estimate { tau, background }
}

/// The scan's counts from time zero, bins summed `group` at a time, for
/// `bins` model bins (bins the scan lacks count 0).
fn grouped(scan: &ConfocalScan, group: usize, bins: usize) -> Array3<f64> {
    let (rows, cols, _) = scan.dim();
    let mut out = Array3::<f64>::zeros((bins, rows, cols));
    for i in 0..bins {
        for k in (0..group).filter_map(|g| scan.bin_after_zero(i * group + g)) {
            let mut dst = out.index_axis_mut(Axis(0), i);
            dst += &scan.counts.index_axis(Axis(0), k);
        }
    }
    out
}

/// The Poisson reconstruction of `scan` through a slab of `optics`;
/// returns the volume (its notes say what was done) and the search's
/// trace.
pub fn reconstruct_poisson(
    scan: &ConfocalScan,
    optics: &SlabOptics,
    opts: &PoissonOptions,
) -> Result<(HiddenVolume, Vec<PoissonTraceRow>), ConfocalError> {
    let started = Instant::now();
    if !(opts.step_m.is_finite() && opts.step_m > 0.0) {
        return Err(ConfocalError::setting(
            "step_m",
            format!("depth step {} m must be positive and finite", opts.step_m),
        ));
    }
    if !(opts.depth_m.is_finite() && opts.depth_m > opts.step_m) {
        return Err(ConfocalError::setting(
            "depth_m",
            format!(
                "depth {} m must exceed the depth step {} m",
                opts.depth_m, opts.step_m
            ),
        ));
    }
    if let Some(v) = scan.counts.iter().find(|v| v.fract() != 0.0) {
        return Err(ConfocalError::input(
            &scan.source,
            format!("count {v} is not a whole number: the Poisson method needs photon counts"),
        ));
    }
    let (rows, cols, _) = scan.dim();
    let bin_s = scan.bin_width_ps * 1e-12;
    let group = ((2.0 * opts.step_m / (LIGHT_SPEED * bin_s)).round() as usize).max(1);
    let crop = crop_bins(opts.depth_m, scan.bin_width_ps);
    let bins = crop.div_ceil(group);
    let elements = (4 * bins * 4 * rows * 4 * cols) as u64;
    crate::memory::check(elements * 16 * 4, || {
        format!("the Poisson reconstruction on {bins} x {rows} x {cols}")
    })?;
    let available = ((scan.dim().2 as i64 - scan.zero_bin()).max(0) as usize) / group;
    let step_m = LIGHT_SPEED * bin_s * group as f64 / 2.0;
    let spacing_m = scan.side_m / (rows.max(cols) - 1) as f64;
    let model_bin_ps = scan.bin_width_ps * group as f64;
    let blur = SlabBlur::new(optics, bins, available, model_bin_ps, rows, cols, spacing_m);
    let count_bins = blur.count_bins;
    let counts = grouped(scan, group, count_bins);
    let onset = (0..bins)
        .find(|&i| counts.index_axis(Axis(0), i).sum() > 0.0)
        .ok_or_else(|| {
            ConfocalError::input(
                &scan.source,
                format!(
                    "no counts in the first {} m of depth ({crop} bins)",
                    opts.depth_m
                ),
            )
        })?;
    let mut mask = Array3::<f64>::zeros((count_bins, rows, cols));
    mask.slice_mut(s![onset.., .., ..]).fill(1.0);
    // Transient elements that send less than SENSITIVITY_FLOOR of the
    // best-seen element's light into observed bins (the last bins when the
    // scan ends with the window, the widened edge) are left at zero: the
    // EM update would divide by almost nothing there.
    let mut sensitivity = blur.adjoint(&mask);
    let top = sensitivity.iter().fold(0.0f64, |m, &v| m.max(v));
    sensitivity.mapv_inplace(|v| if v >= SENSITIVITY_FLOOR * top { v } else { 0.0 });

    let (first, second) = halves(&counts, HALVES_SEED);
    let points = (rows * cols) as f64;
    let start = |half: &Array3<f64>| -> Estimate {
        // Flat transient and background sharing the half's counts evenly.
        let seen: f64 = half.slice(s![onset.., .., ..]).sum();
        let ones = sensitivity.mapv(|v| if v > 0.0 { 1.0 } else { 0.0 });
        let through = blur.forward(&ones).slice(s![onset.., .., ..]).sum();
        Estimate {
            tau: ones * (0.5 * seen / through.max(1e-300)),
            background: Array1::from_shape_fn(count_bins, |i| {
                if i >= onset {
                    (0.5 * half.index_axis(Axis(0), i).sum() / points).max(1e-9)
                } else {
                    0.0
                }
            }),
        }
    };
    let mut a = start(&first);
    let mut b = start(&second);
    let mut best = (f64::INFINITY, 0usize, a.clone(), b.clone());
    let mut trace = Vec::new();
    let with_background = |mut mu: Array3<f64>, e: &Estimate| {
        for (mut plane, &b) in mu.axis_iter_mut(Axis(0)).zip(e.background.iter()) {
            plane += b;
        }
        mu
    };
    for iteration in 0..=opts.max_iters {
        // Both halves through one transform each way (forward_pair).
        let (blur_a, blur_b) = blur.forward_pair(&a.tau, &b.tau);
        let (mu_a, mu_b) = (with_background(blur_a, &a), with_background(blur_b, &b));
        let score = volume_deviance(&second, &mu_a, onset) + volume_deviance(&first, &mu_b, onset);
        trace.push(PoissonTraceRow {
            iteration,
            wall_s: started.elapsed().as_secs_f64(),
            held_out_deviance: score,
        });
        if score < best.0 {
            best = (score, iteration, a.clone(), b.clone());
        }
        let patience = 25.max(best.1 / 4);
        if iteration >= best.1 + patience || iteration == opts.max_iters {
            break;
        }
        let (ratio_a, ratio_b) = (ratio(&first, &mu_a, onset), ratio(&second, &mu_b, onset));
        let (back_a, back_b) = blur.adjoint_pair(&ratio_a, &ratio_b);
        a = em_step(&a, &ratio_a, &back_a, &sensitivity, onset);
        b = em_step(&b, &ratio_b, &back_b, &sensitivity, onset);
    }
    let (_, chosen, a, b) = best;
    let reach = blur.reach;
    let tau = &a.tau + &b.tau;
    // Free space: the published migration of the transient on the scan
    // grid (its time axis spans 4 x the depth in the published unit).
    let mut padded = Array3::<f64>::zeros((2 * bins, 2 * rows, 2 * cols));
    padded
        .slice_mut(s![..bins, ..rows, ..cols])
        .assign(&tau.slice(s![.., reach..reach + rows, reach..reach + cols]));
    let migrated = stolt::migrate(&padded, scan.side_m, 4.0 * bins as f64 * step_m);
    let data = migrated.slice(s![..bins, ..rows, ..cols]).to_owned();
    let searched = trace.len() - 1;
    let notes = vec![
        format!(
            "poisson method: bins summed {group} at a time ({model_bin_ps:.0} ps, {:.2} mm of depth), {bins} bins to {} m; bins before {:.2} ns hold no counts at any point and are taken as gated off",
            step_m * 1000.0,
            opts.depth_m,
            onset as f64 * model_bin_ps * 1e-3
        ),
        format!(
            "model: counts ~ Poisson(K * tau + b), K the slab's in-and-out kernel from its diffusion transmittance ({}; lateral reach {reach} points beyond the scan's edge), b a background per bin shared by every point; tau then f-k migrated",
            optics.describe()
        ),
        format!(
            "stop: iteration {chosen} predicted the held-back halves best (searched to {searched} of at most {}); the transient is the sum of the two halves' there",
            opts.max_iters
        ),
    ];
    Ok((
        HiddenVolume {
            data,
            depth_step_m: step_m,
            first_depth_m: 0.5 * step_m,
            side_m: scan.side_m,
            notes,
        },
        trace,
    ))
}

/// The Poisson method with its settings ([`reconstruct_poisson`]).
#[derive(Debug, Clone, Copy)]
pub struct PoissonEm(pub PoissonOptions);

impl super::VolumeReconstructor for PoissonEm {
    fn reconstruct(
        &self,
        scan: &ConfocalScan,
        optics: &SlabOptics,
    ) -> Result<super::HiddenResult, ConfocalError> {
        let (volume, trace) = reconstruct_poisson(scan, optics, &self.0)?;
        Ok(super::HiddenResult {
            trace: Some(trace),
            ..super::HiddenResult::volume(volume)
        })
    }
}
