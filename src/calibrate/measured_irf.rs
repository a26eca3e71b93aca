//! An instrument response measured without the medium (laser straight into
//! the detector), as a table on the recording's bins.
//!
//! From a reference histogram: the background is the median of the bins
//! before the peak (more than [`BACKGROUND_GAP`] bins before it), the response is the contiguous run of
//! bins around the peak whose excess over the background is significant
//! (every block of [`BLOCK_BINS`] bins inside holds more than
//! [`SIGNIFICANCE`] standard deviations of background noise), and the
//! excess there, clipped at zero, is scaled to unit sum. Zero delay is the
//! peak bin. Light later than the last significant block is left out; the
//! output says how many counts that was at most.
//!
//! A pulsed source's response also has slow parts that follow the light
//! but lie far from its peak: in the CDT reference (10 MHz, one 100 ns
//! period recorded) a pedestal of about 2 parts per million of the light
//! per 8 ps bin starts 12.5 ns before the peak and decays slowly through
//! the period, and every foam capture carries the same pedestal in the
//! same proportion (BENCHMARKS.md). [`MeasuredIrf::from_histogram_period`]
//! keeps them: the response over the reference's whole recorded period,
//! as excess over its lowest level.

use scatterscope_physics::{IrfTable, ParamError};

use super::CalibrateError;
use super::histogram::{DEFAULT_MAT_DATASET, TimeHistogram};

/// Width of the blocks whose summed excess decides the response's extent.
pub const BLOCK_BINS: usize = 8;

/// Standard deviations of background noise a block must exceed.
pub const SIGNIFICANCE: f64 = 3.0;

/// Bins just before the peak left out of the background estimate (the
/// response's own rise).
pub const BACKGROUND_GAP: usize = 2 * BLOCK_BINS;

/// Standard deviations of background noise the peak bin must exceed for
/// the reference to count as holding a response at all.
pub const PEAK_SIGNIFICANCE: f64 = 5.0;

/// Bins averaged (outside the peak's run) to smooth the slow parts of a
/// whole-period response: their Poisson noise falls eightfold, while the
/// pedestal's step (about 125 bins wide) blurs by half a nanosecond,
/// well inside the slab responses it is convolved with.
pub const PERIOD_SMOOTH_BINS: usize = 64;

/// Width of the blocks whose least mean is a whole-period response's
/// floor (the level no light raises).
pub const FLOOR_BLOCK_BINS: usize = 256;

/// A tabulated instrument response.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredIrf {
    /// Share of photons recorded with delay `(j - peak) * bin_width_ps`;
    /// sums to 1.
    pub weights: Vec<f64>,
    /// Index in `weights` of zero delay (the reference's peak).
    pub peak: usize,
    /// Indices in `weights` of the peak's run (all of them, unless the
    /// response also holds the slow parts of the period).
    pub peak_run: std::ops::Range<usize>,
    /// Bin width (ps), the reference's.
    pub bin_width_ps: f64,
    /// Background subtracted from every bin (counts).
    pub background_per_bin: f64,
    /// Counts above the background inside the response.
    pub signal_counts: f64,
    /// Time of the reference's peak bin start on its clock (ps).
    pub peak_time_ps: f64,
    /// The reference's origin.
    pub source: String,
}

/// Why a reference gives no response.
#[derive(Debug, thiserror::Error)]
#[error("{source_name}: {message}")]
pub struct IrfError {
    /// The reference's origin.
    pub source_name: String,
    /// What is wrong with it.
    pub message: String,
}

impl MeasuredIrf {
    /// The response in `reference` (see the module's documentation).
    pub fn from_histogram(reference: &TimeHistogram) -> Result<Self, IrfError> {
        let fail = |message: String| IrfError {
            source_name: reference.source.clone(),
            message,
        };
        let n = reference.counts.len();
        if n < 4 * BLOCK_BINS {
            return Err(fail(format!(
                "{n} bins are too few to tell the response from its background (need {})",
                4 * BLOCK_BINS
            )));
        }
        let peak = reference.peak_index();
        // A reference whose fullest bin does not stand out of the rest
        // (an empty or flat one) holds no response at all.
        let mut sorted = reference.counts.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[n / 2];
        if reference.counts[peak] - median <= PEAK_SIGNIFICANCE * median.max(1.0).sqrt() {
            return Err(fail(format!(
                "no instrument response: the fullest bin ({peak}) holds {} counts, the median bin {median}",
                reference.counts[peak]
            )));
        }
        let (background, _) = reference
            .background_before(peak, BACKGROUND_GAP)
            .ok_or_else(|| {
                fail(format!(
                    "the peak (bin {peak}) leaves fewer than {} bins before it to measure the background",
                    super::histogram::MIN_BACKGROUND_BINS
                ))
            })?;
        let excess: Vec<f64> = reference.counts.iter().map(|c| c - background).collect();
        let noise = background.max(1.0).sqrt();
        if excess[peak] <= PEAK_SIGNIFICANCE * noise {
            return Err(fail(format!(
                "no instrument response: the fullest bin ({peak}) holds {} counts over a background of {background} per bin, under {PEAK_SIGNIFICANCE} standard deviations",
                excess[peak]
            )));
        }
        let threshold = SIGNIFICANCE * noise * (BLOCK_BINS as f64).sqrt();
        let block = |from: usize| excess[from..from + BLOCK_BINS].iter().sum::<f64>();
        let mut end = peak + 1;
        while end + BLOCK_BINS <= n && block(end) > threshold {
            end += 1;
        }
        let mut start = peak;
        while start >= BLOCK_BINS && block(start - BLOCK_BINS) > threshold {
            start -= 1;
        }
        let weights: Vec<f64> = excess[start..end].iter().map(|e| e.max(0.0)).collect();
        let signal: f64 = weights.iter().sum();
        Ok(Self {
            peak_run: 0..weights.len(),
            weights: weights.iter().map(|w| w / signal).collect(),
            peak: peak - start,
            bin_width_ps: reference.bin_width_ps,
            background_per_bin: background,
            signal_counts: signal,
            peak_time_ps: reference.start_ps + peak as f64 * reference.bin_width_ps,
            source: reference.source.clone(),
        })
    }

    /// The response over the reference's whole recorded period: the peak's
    /// run as in [`Self::from_histogram`], and every other bin of the
    /// recorded range as the mean of the [`PERIOD_SMOOTH_BINS`] bins
    /// around it (outside the peak's run); both as excess over the floor,
    /// the least mean of [`FLOOR_BLOCK_BINS`]-bin blocks, clipped at zero.
    /// The recorded range is [`recorded_range`]'s (a TCSPC range longer
    /// than the laser's period ends in empty bins). A capture's constant
    /// background then holds only what the floor holds: dark counts and
    /// the light's level there.
    pub fn from_histogram_period(reference: &TimeHistogram) -> Result<Self, IrfError> {
        let core = Self::from_histogram(reference)?;
        let counts = &reference.counts;
        let peak = reference.peak_index();
        let (core_start, core_end) = (peak - core.peak, peak - core.peak + core.weights.len());
        let (first, end) = recorded_range(counts);
        let (first, end) = (first.min(core_start), end.max(core_end));
        let range = &counts[first..end];
        let floor = range
            .chunks_exact(FLOOR_BLOCK_BINS)
            .map(|b| b.iter().sum::<f64>() / FLOOR_BLOCK_BINS as f64)
            .fold(f64::INFINITY, f64::min);
        if !floor.is_finite() {
            return Err(IrfError {
                source_name: reference.source.clone(),
                message: format!(
                    "the recorded period ({} bins) is shorter than one block of {FLOOR_BLOCK_BINS} bins to measure its floor",
                    range.len()
                ),
            });
        }
        let half = PERIOD_SMOOTH_BINS / 2;
        let outside = |j: usize| !(core_start..core_end).contains(&j);
        let excess: Vec<f64> = (first..end)
            .map(|j| {
                let level = if outside(j) {
                    let (sum, k) = (j.saturating_sub(half).max(first)..(j + half).min(end))
                        .filter(|&i| outside(i))
                        .fold((0.0, 0.0), |(s, k), i| (s + counts[i], k + 1.0));
                    sum / k
                } else {
                    counts[j]
                };
                (level - floor).max(0.0)
            })
            .collect();
        let signal: f64 = excess.iter().sum();
        Ok(Self {
            weights: excess.iter().map(|e| e / signal).collect(),
            peak: peak - first,
            peak_run: core_start - first..core_end - first,
            background_per_bin: floor,
            signal_counts: signal,
            ..core
        })
    }

    /// What the response spans, for the output: "whole recorded period"
    /// The response in words: its source and extent, bins, width, delay,
    /// the background subtracted, and how much lies far from the peak.
    pub fn describe(&self) -> String {
        format!(
            "instrument response from {} ({}): {} bins of {} ps, FWHM {:.1} ps, mean delay after the peak {:.1} ps, {:.2} counts per bin subtracted; {:.2} % of it lies more than 1 ns before or 3 ns after the peak",
            self.source,
            self.extent_name(),
            self.weights.len(),
            self.bin_width_ps,
            self.fwhm_ps(),
            self.mean_delay_ps(),
            self.background_per_bin,
            100.0 * self.share_outside(1000.0, 3000.0)
        )
    }

    /// ([`Self::from_histogram_period`]) or "the peak's run".
    pub fn extent_name(&self) -> &'static str {
        if self.peak_run == (0..self.weights.len()) {
            "the peak's run"
        } else {
            "whole recorded period"
        }
    }

    /// Share of the response outside `[-before_ps, after_ps]` around its
    /// peak.
    pub fn share_outside(&self, before_ps: f64, after_ps: f64) -> f64 {
        let w = self.bin_width_ps;
        self.weights
            .iter()
            .enumerate()
            .filter(|(j, _)| {
                let d = (*j as f64 - self.peak as f64) * w;
                d < -before_ps || d > after_ps
            })
            // A fold from +0, not `sum` (which starts at -0 and prints an
            // empty share as "-0.00").
            .fold(0.0, |acc, (_, v)| acc + v)
    }

    /// Full width at half maximum (ps), by linear interpolation between
    /// bin centres.
    pub fn fwhm_ps(&self) -> f64 {
        let half = 0.5 * self.weights[self.peak];
        let crossing = |range: &mut dyn Iterator<Item = usize>, step: isize| -> f64 {
            for j in range {
                let k = (j as isize + step) as usize;
                if self.weights[k] < half {
                    let (a, b) = (self.weights[j], self.weights[k]);
                    return j as f64 + step as f64 * (a - half) / (a - b);
                }
            }
            if step < 0 {
                -0.5
            } else {
                self.weights.len() as f64 - 0.5
            }
        };
        let right = crossing(&mut (self.peak..self.weights.len() - 1), 1);
        let left = crossing(&mut (1..=self.peak).rev(), -1);
        (right - left) * self.bin_width_ps
    }

    /// The response as the physics' table: entry `j` covers delays
    /// `[(j - peak - 1/2) w, (j - peak + 1/2) w)`, so time zero is the
    /// centre of the reference's peak bin ([`Self::zero_time_ps`]).
    pub fn table(&self) -> Result<IrfTable, ParamError> {
        IrfTable::new(
            self.bin_width_ps,
            -(self.peak as f64 + 0.5) * self.bin_width_ps,
            self.weights.clone(),
        )
    }

    /// Time zero of [`Self::table`] on the reference's clock (ps): the
    /// centre of its peak bin.
    pub fn zero_time_ps(&self) -> f64 {
        self.peak_time_ps + 0.5 * self.bin_width_ps
    }

    /// Mean delay after the peak (ps): the response's centroid against
    /// its zero.
    pub fn mean_delay_ps(&self) -> f64 {
        self.weights
            .iter()
            .enumerate()
            .map(|(j, w)| w * (j as f64 - self.peak as f64))
            .sum::<f64>()
            * self.bin_width_ps
    }
}

/// The bins `first..end` a histogram recorded: without its leading and
/// trailing empty bins, nor the partial bins at either edge, those
/// holding less than half the median of the [`FLOOR_BLOCK_BINS`] bins
/// next to them (the bins the laser's period cuts through).
pub fn recorded_range(counts: &[f64]) -> (usize, usize) {
    let (Some(first), Some(last)) = (
        counts.iter().position(|&c| c > 0.0),
        counts.iter().rposition(|&c| c > 0.0),
    ) else {
        return (0, 0);
    };
    let half_median = |bins: &[f64]| {
        let mut sorted = bins.to_vec();
        sorted.sort_by(f64::total_cmp);
        0.5 * sorted[sorted.len() / 2]
    };
    let inner = (last + 1 - first).min(FLOOR_BLOCK_BINS);
    let low_end = half_median(&counts[last + 1 - inner..=last]);
    let end = counts[first..=last]
        .iter()
        .rposition(|&c| c >= low_end)
        .map_or(last + 1, |i| first + i + 1);
    let low_start = half_median(&counts[first..first + inner]);
    let first = counts[first..end]
        .iter()
        .position(|&c| c >= low_start)
        .map_or(first, |i| first + i);
    (first, end)
}

/// The measured response of the reference recording at `path` (a tag
/// file, a stack or a MATLAB file; see [`TimeHistogram::read`]; `bin_ps`
/// for a file that does not record its bin width) and its table for the
/// kernels.
pub fn measured_irf_from_reference(
    path: &std::path::Path,
    bin_ps: Option<f64>,
) -> Result<(MeasuredIrf, IrfTable), CalibrateError> {
    let histogram = TimeHistogram::read(path, DEFAULT_MAT_DATASET, bin_ps)?;
    let measured = MeasuredIrf::from_histogram(&histogram)
        .map_err(|e| CalibrateError::Invalid(e.to_string()))?;
    let table = measured.table().map_err(|e| {
        CalibrateError::Invalid(format!("the response measured in {}: {e}", path.display()))
    })?;
    Ok((measured, table))
}
