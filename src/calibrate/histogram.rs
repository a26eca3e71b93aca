//! One detector's measured time histogram: photon counts in consecutive
//! bins of equal width, as a TCSPC module accumulates them.
//!
//! Sources: MATLAB v7.3 files (HDF5 inside; read with the pure-Rust
//! `hdf5-reader`, so no system HDF5 library is needed), our own stacks
//! (the counts summed over the sensor per bin) and tag files (every photon
//! at the file's resolution).

use std::path::{Path, PathBuf};

use crate::formats::detect::Format;
use crate::poisson::counts::check_counts;
use crate::stack::Stack;

/// Most bins before the light whose median is the background.
pub const BACKGROUND_BINS: usize = 1000;

/// The dataset read from MATLAB histograms unless another is named (the
/// one the confocal diffuse tomography captures use).
pub const DEFAULT_MAT_DATASET: &str = "out";

/// The cell array of per-part histograms read from MATLAB captures unless
/// another is named (the confocal diffuse tomography captures' one
/// histogram per second, which `out` sums).
pub const DEFAULT_MAT_PARTS: &str = "accum";

/// Fewest bins before the light that give a background.
pub const MIN_BACKGROUND_BINS: usize = 8;

/// Counts per bin of one detector, bins `[k w, (k + 1) w)` of the
/// recording's own clock.
#[derive(Debug, Clone, PartialEq)]
pub struct TimeHistogram {
    /// Counts per bin (non-negative, finite).
    pub counts: Vec<f64>,
    /// Width of every bin (ps).
    pub bin_width_ps: f64,
    /// Time of the first bin's start on the recording's clock (ps).
    pub start_ps: f64,
    /// Where the histogram came from, for messages.
    pub source: String,
}

/// Why a histogram cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum HistogramError {
    /// The file cannot be opened or decoded.
    #[error("{path}: {message}")]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// A file that does not record its bin width was given none.
    #[error("{path}: a MATLAB file does not record its bin width: give it")]
    BinWidthUnknown {
        /// The file.
        path: PathBuf,
    },
}

/// Opens a MATLAB v7.3 file, the error naming it.
fn open_mat(path: &Path) -> Result<crate::formats::mat::MatFile, HistogramError> {
    crate::formats::mat::open(path).map_err(|m| file_error(path, m))
}

/// The numbers of a one-dimensional dataset, named `name` in errors.
fn vector(
    path: &Path,
    file: &crate::formats::mat::MatFile,
    name: &str,
    ds: &hdf5_reader::Dataset,
) -> Result<Vec<f64>, HistogramError> {
    let shape = ds.shape().to_vec();
    if shape.iter().filter(|&&d| d > 1).count() > 1 {
        return Err(file_error(
            path,
            format!("dataset `{name}` has shape {shape:?}: a histogram is one vector"),
        ));
    }
    crate::formats::mat::numbers(file, ds).map_err(|e| {
        file_error(
            path,
            format!("dataset `{name}` cannot be read as numbers: {e}"),
        )
    })
}

fn file_error(path: &Path, message: impl Into<String>) -> HistogramError {
    HistogramError::File {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

impl TimeHistogram {
    /// Checks the counts and the bin width; `source` names the origin in
    /// the error.
    pub fn new(
        counts: Vec<f64>,
        bin_width_ps: f64,
        start_ps: f64,
        source: &Path,
    ) -> Result<Self, HistogramError> {
        if !(bin_width_ps.is_finite() && bin_width_ps > 0.0) {
            return Err(file_error(
                source,
                format!("bin width {bin_width_ps} ps must be positive and finite"),
            ));
        }
        if counts.is_empty() {
            return Err(file_error(source, "the histogram has no bins"));
        }
        check_counts(counts.iter().copied(), |i| format!("bin {i}"))
            .map_err(|e| file_error(source, e.to_string()))?;
        Ok(Self {
            counts,
            bin_width_ps,
            start_ps,
            source: source.display().to_string(),
        })
    }

    /// Reads dataset `dataset` (a vector of counts, e.g. `out` in the
    /// confocal-diffuse-tomography captures) of a MATLAB v7.3 file. MATLAB
    /// files do not say the bin width, so the caller gives it.
    pub fn read_mat(path: &Path, dataset: &str, bin_width_ps: f64) -> Result<Self, HistogramError> {
        let file = open_mat(path)?;
        let ds = crate::formats::mat::dataset(&file, dataset).map_err(|m| file_error(path, m))?;
        let counts = vector(path, &file, dataset, &ds)?;
        Self::new(counts, bin_width_ps, 0.0, path)
    }

    /// The histograms of a MATLAB v7.3 cell array `dataset` of count
    /// vectors (e.g. `accum` in the confocal-diffuse-tomography captures:
    /// one histogram per second of acquisition, which `out` sums), in the
    /// cell array's order; `None` when the file holds no such dataset.
    pub fn read_mat_parts(
        path: &Path,
        dataset: &str,
        bin_width_ps: f64,
    ) -> Result<Option<Vec<Self>>, HistogramError> {
        let file = open_mat(path)?;
        let Ok(cells) = file.dataset(&format!("/{dataset}")) else {
            return Ok(None);
        };
        let fail = |m: String| file_error(path, format!("cell array `{dataset}`: {m}"));
        let raw = cells
            .read_raw_bytes()
            .map_err(|e| fail(format!("cannot be read: {e}")))?;
        let offset_size = file.superblock().offset_size;
        let addresses = hdf5_reader::reference::read_object_references(&raw, offset_size)
            .map_err(|e| fail(format!("not a cell array of references: {e}")))?;
        // MATLAB keeps a cell array's contents in the group `#refs#`.
        let targets = file
            .group("/#refs#")
            .and_then(|g| g.datasets())
            .map_err(|e| fail(format!("its contents (group `#refs#`) cannot be read: {e}")))?;
        addresses
            .iter()
            .enumerate()
            .map(|(i, &address)| {
                let ds = targets
                    .iter()
                    .find(|d| d.address() == address)
                    .ok_or_else(|| fail(format!("cell {i} refers to no dataset of `#refs#`")))?;
                let counts = vector(path, &file, &format!("{dataset}{{{i}}}"), ds)?;
                let source = format!("{} ({dataset} part {i})", path.display());
                Self::new(counts, bin_width_ps, 0.0, Path::new(&source))
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Some)
    }

    /// The counts of `stack` summed over the sensor per bin; its bins must
    /// follow one another.
    pub fn from_stack(stack: &Stack, path: &Path) -> Result<Self, HistogramError> {
        let (start, counts) =
            super::time_profile(stack).map_err(|e| file_error(path, e.to_string()))?;
        Self::new(counts, stack.meta.bin_width_ps, start, path)
    }

    /// Every photon of a tag file (PicoQuant or our raw records) in one
    /// histogram over one sync period at the file's resolution.
    pub fn from_tags(path: &Path) -> Result<Self, HistogramError> {
        let spec = crate::BinSpec {
            pixels: crate::tags::bin_file::Pixels::Single,
            ..crate::BinSpec::default()
        };
        let binned = crate::bin_file(path, &spec).map_err(|e| file_error(path, e.to_string()))?;
        let first = binned
            .stacks
            .first()
            .ok_or_else(|| file_error(path, "the file holds no histogram"))?;
        let mut counts = vec![0.0; first.bins()];
        for stack in &binned.stacks {
            for (c, img) in counts.iter_mut().zip(stack.data.outer_iter()) {
                *c += img.iter().map(|&v| f64::from(v)).sum::<f64>();
            }
        }
        let start = first.meta.bin_starts_ps.first().copied().unwrap_or(0.0);
        Self::new(counts, first.meta.bin_width_ps, start, path)
    }

    /// Reads a histogram file by its format ([`Format::of_file`]): `.mat` (dataset `dataset`,
    /// bins of `bin_width_ps`), a stack (`.exr`, `.npy`: summed over the
    /// sensor, bins from its metadata), or a tag file (`.ptu`, `.pt3`,
    /// `.ht3`, `.sstags`: every photon, the file's resolution).
    pub fn read(
        path: &Path,
        dataset: &str,
        bin_width_ps: Option<f64>,
    ) -> Result<Self, HistogramError> {
        match Format::of_file(path) {
            Format::Mat => {
                let width = bin_width_ps.ok_or_else(|| HistogramError::BinWidthUnknown {
                    path: path.to_path_buf(),
                })?;
                Self::read_mat(path, dataset, width)
            }
            Format::Exr | Format::Npy => {
                let stack = Stack::load(path).map_err(|e| file_error(path, e.to_string()))?;
                Self::from_stack(&stack, path)
            }
            Format::Ptu | Format::PicoQuantLegacy | Format::TagFile => Self::from_tags(path),
            _ => Err(file_error(
                path,
                "not a histogram: neither its first bytes nor its extension say MATLAB v7.3 (.mat), a stack (.exr, .npy) or a tag file (.ptu, .pt3, .ht3, .sstags)",
            )),
        }
    }

    /// Total counts.
    pub fn total(&self) -> f64 {
        self.counts.iter().sum()
    }

    /// Index of the fullest bin (the first of equals).
    pub fn peak_index(&self) -> usize {
        self.counts
            .iter()
            .enumerate()
            .fold((0, f64::NEG_INFINITY), |best, (i, &c)| {
                if c > best.1 { (i, c) } else { best }
            })
            .0
    }

    /// Background counts per bin before the light: the median of the
    /// bins from [`BACKGROUND_BINS`] + `gap` bins before `peak` to `gap`
    /// bins before it, and how many bins that was; `None` when fewer than
    /// [`MIN_BACKGROUND_BINS`] precede the peak. (Not the whole histogram's
    /// median: TCSPC histograms often end in a run of empty bins past the
    /// laser period, and the background need not be flat over all of it.)
    pub fn background_before(&self, peak: usize, gap: usize) -> Option<(f64, usize)> {
        let end = peak.checked_sub(gap)?;
        let start = end.saturating_sub(BACKGROUND_BINS);
        let n = end - start;
        if n < MIN_BACKGROUND_BINS {
            return None;
        }
        let mut sorted = self.counts[start..end].to_vec();
        sorted.sort_by(f64::total_cmp);
        let median = if n % 2 == 1 {
            sorted[n / 2]
        } else {
            0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
        };
        Some((median, n))
    }
}
