//! A confocal scan: photon counts per scan point and time bin, with the
//! bin width, the scanned area and where time zero sits.

use std::path::Path;

use ndarray::Array3;

use super::ConfocalError;
use crate::formats::detect::Format;
use crate::poisson::counts::check_counts;
use crate::stack::Stack;

/// The MATLAB dataset read unless another is named (the confocal diffuse
/// tomography scans' one).
pub const DEFAULT_MAT_DATASET: &str = "meas";

/// Fewest scan points per side and bins a scan may have.
pub const MIN_SIDE: usize = 2;

/// Counts of a square-grid confocal scan of a slab's near face.
#[derive(Debug, Clone)]
pub struct ConfocalScan {
    /// Counts, indexed (bin, row, column); rows and columns are scan points
    /// spaced evenly over the scanned side.
    pub counts: Array3<f64>,
    /// Width of every time bin (ps).
    pub bin_width_ps: f64,
    /// Start of bin 0 after the pulse reaches the slab's near face (ps);
    /// the published scans start there (0).
    pub start_ps: f64,
    /// Side of the square area the scan points cover on the near face (m),
    /// from the first to the last point.
    pub side_m: f64,
    /// Where the counts came from, for messages.
    pub source: String,
}

impl ConfocalScan {
    /// The scan in words: where it came from, its points over its side (in
    /// cm), its bins and its counts.
    pub fn describe(&self) -> String {
        let (rows, cols, bins) = self.dim();
        format!(
            "{} ({rows} x {cols} points over {:.1} cm, {bins} bins of {} ps, {:.0} counts)",
            self.source,
            self.side_m * crate::units::CM_PER_M,
            self.bin_width_ps,
            self.total()
        )
    }

    /// Checks the counts and settings: photon counts
    /// ([`check_counts`]: finite, non-negative, at most 2^53, at least one
    /// photon in all), at least [`MIN_SIDE`] points per side and bins, a positive bin
    /// width and scanned side. Errors name `source`, the setting or the
    /// first bad count.
    pub fn new(
        counts: Array3<f64>,
        bin_width_ps: f64,
        start_ps: f64,
        side_m: f64,
        source: &str,
    ) -> Result<Self, ConfocalError> {
        let fail = |m: String| ConfocalError::input(source, m);
        let (bins, rows, cols) = counts.dim();
        if bins < MIN_SIDE || rows < MIN_SIDE || cols < MIN_SIDE {
            return Err(fail(format!(
                "a scan of {rows} x {cols} points and {bins} bins: at least {MIN_SIDE} of each are needed"
            )));
        }
        if !(bin_width_ps.is_finite() && bin_width_ps > 0.0) {
            return Err(fail(format!(
                "bin width {bin_width_ps} ps must be positive and finite"
            )));
        }
        if !start_ps.is_finite() {
            return Err(fail(format!("time zero {start_ps} ps must be finite")));
        }
        if !(side_m.is_finite() && side_m > 0.0) {
            return Err(ConfocalError::setting(
                "side_m",
                format!("{source}: scanned side {side_m} m must be positive and finite"),
            ));
        }
        check_counts(counts.iter().copied(), |i| {
            let (k, rest) = (i / (rows * cols), i % (rows * cols));
            format!(
                "scan point (row {}, column {}) bin {k}",
                rest / cols,
                rest % cols
            )
        })
        .map_err(|e| fail(e.to_string()))?;
        Ok(Self {
            counts,
            bin_width_ps,
            start_ps,
            side_m,
            source: source.to_string(),
        })
    }

    /// Opens a scan by its format ([`Format::of_file`]): a MATLAB v7.3 file (`.mat`, dataset
    /// `dataset`, bin width `bin_width_ps` required) or a project stack
    /// (`.exr`, `.npy`, whose metadata carries its bin width).
    pub fn open(
        path: &Path,
        dataset: &str,
        bin_width_ps: Option<f64>,
        side_m: f64,
    ) -> Result<Self, ConfocalError> {
        let name = path.display().to_string();
        match Format::of_file(path) {
            Format::Mat => {
                let width = bin_width_ps.ok_or_else(|| {
                    ConfocalError::setting(
                        "bin_width_ps",
                        format!("{name}: a MATLAB file does not record its bin width: give it"),
                    )
                })?;
                Self::read_mat(path, dataset, width, side_m)
            }
            Format::Exr | Format::Npy => {
                let stack =
                    Stack::load(path).map_err(|e| ConfocalError::input(&name, e.to_string()))?;
                Self::from_stack(&stack, side_m, &name)
            }
            _ => Err(ConfocalError::input(
                &name,
                "not a scan: neither its first bytes nor its extension say MATLAB .mat or a stack (.exr, .npy)",
            )),
        }
    }

    /// Reads dataset `dataset` of a MATLAB v7.3 file: three axes as HDF5
    /// stores them (column, row, time), time last, as the confocal diffuse
    /// tomography scans hold them. MATLAB files record neither the bin width
    /// nor the scanned side, so the caller gives both; bin 0 is time zero.
    pub fn read_mat(
        path: &Path,
        dataset: &str,
        bin_width_ps: f64,
        side_m: f64,
    ) -> Result<Self, ConfocalError> {
        let name = path.display().to_string();
        let fail = |m: String| ConfocalError::input(&name, m);
        let file = crate::formats::mat::open(path).map_err(&fail)?;
        let ds = crate::formats::mat::dataset(&file, dataset).map_err(&fail)?;
        let shape: Vec<usize> = ds.shape().iter().map(|&d| d as usize).collect();
        let [cols, rows, bins] = shape[..] else {
            return Err(fail(format!(
                "dataset `{dataset}` has shape {shape:?}: a confocal scan has three axes (column, row, time)"
            )));
        };
        let values = crate::formats::mat::numbers(&file, &ds).map_err(|e| {
            fail(format!(
                "dataset `{dataset}` cannot be read as numbers: {e}"
            ))
        })?;
        let stored = Array3::from_shape_vec((cols, rows, bins), values)
            .map_err(|e| fail(format!("dataset `{dataset}`: {e}")))?;
        let counts = stored
            .permuted_axes([2, 1, 0])
            .as_standard_layout()
            .to_owned();
        Self::new(counts, bin_width_ps, 0.0, side_m, &name)
    }

    /// A project stack whose pixels are scan points (e.g. a galvo-scanned
    /// PTU binned with `scatterscope bin`): its bins must follow one
    /// another; the first bin's start is taken as time zero's offset.
    pub fn from_stack(stack: &Stack, side_m: f64, source: &str) -> Result<Self, ConfocalError> {
        let meta = &stack.meta;
        let starts = &meta.bin_starts_ps;
        if let Some(k) = (1..starts.len()).find(|&k| {
            ((starts[k] - starts[k - 1]) - meta.bin_width_ps).abs() > 1e-6 * meta.bin_width_ps
        }) {
            return Err(ConfocalError::input(
                source,
                format!(
                    "bins {} and {k} start {} ps apart, not one bin width ({} ps): a scan's bins must follow one another",
                    k - 1,
                    starts[k] - starts[k - 1],
                    meta.bin_width_ps
                ),
            ));
        }
        Self::new(
            stack.data.mapv(f64::from),
            meta.bin_width_ps,
            starts.first().copied().unwrap_or(0.0),
            side_m,
            source,
        )
    }

    /// Scan points per row and column, and bins: (rows, columns, bins).
    pub fn dim(&self) -> (usize, usize, usize) {
        let (bins, rows, cols) = self.counts.dim();
        (rows, cols, bins)
    }

    /// All counts.
    pub fn total(&self) -> f64 {
        self.counts.sum()
    }

    /// Index of the bin that starts at time zero (negative when the scan
    /// starts later), to the nearest bin.
    pub fn zero_bin(&self) -> i64 {
        (-self.start_ps / self.bin_width_ps).round() as i64
    }

    /// Bin `k` after time zero as an index of `counts`, if the scan has it.
    pub fn bin_after_zero(&self, k: usize) -> Option<usize> {
        let i = self.zero_bin() + k as i64;
        (i >= 0 && (i as usize) < self.counts.dim().0).then_some(i as usize)
    }

    /// Every count kept with probability `fraction` (binomial thinning,
    /// seeded): the same scan at a `fraction` of the exposure. Counts must
    /// be whole numbers.
    pub fn thinned(&self, fraction: f64, seed: u64) -> Result<Self, ConfocalError> {
        if !(fraction > 0.0 && fraction <= 1.0) {
            return Err(ConfocalError::input(
                &self.source,
                format!("thinning fraction {fraction} must lie in (0, 1]"),
            ));
        }
        if let Some(v) = self
            .counts
            .iter()
            .find(|v| v.fract() != 0.0 || **v > u64::MAX as f64)
        {
            return Err(ConfocalError::input(
                &self.source,
                format!("count {v} is not a whole number: only photon counts can be thinned"),
            ));
        }
        Self::new(
            crate::poisson::thinning::keep_photons(&self.counts, fraction, seed),
            self.bin_width_ps,
            self.start_ps,
            self.side_m,
            &format!("{} thinned to {fraction} (seed {seed})", self.source),
        )
    }
}
