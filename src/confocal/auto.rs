//! The default hidden-volume reconstruction: the published method,
//! smoothed as much as the scan's own noise asks, chosen without the truth.
//!
//! The counts are thinned into two halves (each photon to either with
//! probability 1/2, seeded, as the Poisson method's stop does); each half
//! is reconstructed by the published method. Their noise is independent,
//! so a blur of one half that correlates best with the other half is, in
//! expectation, the blur that correlates best with the noise-free volume.
//! The score of a blur width is the 3-D correlation of each half, blurred,
//! with the other, summed over both ways. The halves hold half the counts
//! each, and a smoother's best width shrinks as the data grow, as `n^(-1/7)`
//! for a three-dimensional kernel estimate; the width chosen on the halves
//! is scaled by `2^(-1/7)` for the whole scan. Neither the candidates, the
//! depth-to-across ratio nor the scaling were chosen per scan; the rule is
//! written down in docs/journal/2026-11-26-twenty-fourth-session.md with
//! its tuning and report sets.

use ndarray::Array3;

use super::published::{PublishedOptions, reconstruct_published};
use super::slab_kernel::SlabOptics;
use super::volume::{HiddenVolume, pearson};
use super::{ConfocalError, ConfocalScan};
use crate::poisson::thinning::halves;

/// Seed of the halves' thinning.
pub const AUTO_SEED: u64 = 0x5ca7_2049;

/// Blur widths across (voxels, standard deviation) the choice searches;
/// 0 is the published method itself.
pub const ACROSS_CANDIDATES: [f64; 9] = [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0];

/// Depth width per unit of across width: the ratio of the fixed blur
/// baseline chosen on the shared scans (1.5 across, 3 in depth).
pub const DEPTH_PER_ACROSS: f64 = 2.0;

/// The scaling from half the counts to all of them: `2^(-1/7)`, the ratio
/// of best kernel widths for a 3-D density estimate from `n` and `2n`
/// samples.
pub fn half_to_whole() -> f64 {
    2f64.powf(-1.0 / 7.0)
}

/// What the choice saw and chose.
#[derive(Debug, Clone, PartialEq)]
pub struct AutoChoice {
    /// Score (summed cross-correlation of the halves) per across width
    /// tried, in [`ACROSS_CANDIDATES`] order.
    pub scores: Vec<(f64, f64)>,
    /// The best across width on the halves.
    pub half_across: f64,
    /// The blur applied to the whole scan's volume: (across, depth) voxels.
    pub blur: (f64, f64),
}

/// Reconstructs `scan` by the published method with `options`, then
/// blurs it by the width its thinned halves choose. A scan whose counts
/// are not whole numbers cannot be split into photons: it gets the
/// published method alone, and the notes say so.
pub fn reconstruct_auto(
    scan: &ConfocalScan,
    optics: &SlabOptics,
    options: &PublishedOptions,
) -> Result<(HiddenVolume, Option<AutoChoice>), ConfocalError> {
    let mut whole = reconstruct_published(scan, optics, options)?;
    if scan.counts.iter().any(|v| v.fract() != 0.0) {
        whole.notes.push(
            "auto: the counts are not whole numbers, so they cannot be split into halves: the published method's volume, unsmoothed".into(),
        );
        return Ok((whole, None));
    }
    let (first, second) = halves(&scan.counts, AUTO_SEED);
    let half = |counts: Array3<f64>, name: &str| {
        let s = ConfocalScan::new(
            counts,
            scan.bin_width_ps,
            scan.start_ps,
            scan.side_m,
            &format!("{} ({name} half)", scan.source),
        )?;
        reconstruct_published(&s, optics, options)
    };
    let (a, b) = (half(first, "first")?, half(second, "second")?);
    let scores: Vec<(f64, f64)> = ACROSS_CANDIDATES
        .iter()
        .map(|&across| {
            let depth = DEPTH_PER_ACROSS * across;
            let score = match (
                pearson(&a.blurred(across, depth).data, &b.data),
                pearson(&b.blurred(across, depth).data, &a.data),
            ) {
                (Some(ab), Some(ba)) => ab + ba,
                _ => f64::NAN,
            };
            (across, score)
        })
        .collect();
    // A NaN score (a half with nothing in it) is left out; with none left
    // the volume is not blurred.
    let half_across = scores
        .iter()
        .filter(|s| !s.1.is_nan())
        .max_by(|x, y| x.1.total_cmp(&y.1))
        .map_or(0.0, |s| s.0);
    let across = half_across * half_to_whole();
    let blur = (across, DEPTH_PER_ACROSS * across);
    let mut volume = if across > 0.0 {
        whole.blurred(blur.0, blur.1)
    } else {
        whole
    };
    volume.notes.push(format!(
        "auto: blur chosen on two thinned halves of the scan (best {half_across} voxels across on the halves, scaled by 2^(-1/7) for the whole): {:.2} across, {:.2} in depth; scores {}",
        blur.0,
        blur.1,
        scores
            .iter()
            .map(|(w, s)| format!("{w}:{s:.4}"))
            .collect::<Vec<_>>()
            .join(" ")
    ));
    Ok((
        volume,
        Some(AutoChoice {
            scores,
            half_across,
            blur,
        }),
    ))
}

/// The default: the published method blurred by a width its thinned
/// halves choose ([`reconstruct_auto`]).
#[derive(Debug, Clone, Copy)]
pub struct AutoBlur(pub PublishedOptions);

impl super::VolumeReconstructor for AutoBlur {
    fn reconstruct(
        &self,
        scan: &ConfocalScan,
        optics: &SlabOptics,
    ) -> Result<super::HiddenResult, ConfocalError> {
        let (volume, choice) = reconstruct_auto(scan, optics, &self.0)?;
        Ok(super::HiddenResult {
            choice,
            ..super::HiddenResult::volume(volume)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    /// A scan whose halves reconstruct to nothing (a slab that lets no
    /// light through) is not blurred, and nothing in it turns NaN.
    #[test]
    fn an_empty_volume_is_left_unblurred() {
        let mut counts = Array3::<f64>::zeros((600, 4, 4));
        counts.slice_mut(ndarray::s![100..400, .., ..]).fill(1.0);
        let scan = ConfocalScan::new(counts, 16.0, 0.0, 0.5, "dark").unwrap();
        let optics = SlabOptics::for_slab(None, 100_000.0).unwrap();
        let (volume, choice) =
            reconstruct_auto(&scan, &optics, &PublishedOptions::default()).unwrap();
        assert!(volume.data.iter().all(|v| v.is_finite()));
        assert_eq!(choice.unwrap().blur, (0.0, 0.0));
    }

    #[test]
    fn half_to_whole_is_the_kernel_rate() {
        assert!((half_to_whole().powi(7) - 0.5).abs() < 1e-12);
    }
}
