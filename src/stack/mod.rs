//! The transient stack: K time bins of H x W images plus the metadata that
//! every later stage needs (binning, pixel pitch, physics, provenance).
//!
//! Its files are in [`crate::formats`], which sits above this module:
//! [`Stack::load`] and [`Stack::save`] ([`crate::formats::stack_file`])
//! dispatch to OpenEXR ([`crate::formats::exr`], one `f32` channel per bin)
//! and `.npy` with a JSON sidecar ([`crate::formats::npy`]); PNG contact
//! sheets for a quick look ([`crate::formats::png`]).

use std::path::{Path, PathBuf};

use ndarray::{Array3, ArrayView2, ArrayView3, Axis, s};
use scatterscope_physics::{Sampling, Setup};
use serde::{Deserialize, Serialize};

use crate::forward::Boundary;
use crate::poisson::counts::check_count;

/// Version of the metadata layout written to files.
pub const META_VERSION: u32 = 1;

/// What the stack's values are.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ValueKind {
    /// Measured or sampled photon counts (non-negative integers).
    Counts,
    /// Noise-free expected photon counts.
    ExpectedCounts,
    /// ST-PSF kernels: expected counts from a unit object pixel, centred.
    Kernel,
}

impl ValueKind {
    /// Name as stored in files.
    pub fn name(self) -> &'static str {
        match self {
            ValueKind::Counts => "counts",
            ValueKind::ExpectedCounts => "expected_counts",
            ValueKind::Kernel => "kernel",
        }
    }
}

/// A time bin left out of the stack, and why it was safe to leave out.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DroppedBin {
    /// Bin start (ps).
    pub start_ps: f64,
    /// Expected photons the ST-PSF puts in the bin (below the threshold).
    pub photons: f64,
}

/// Everything about a stack except its values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StackMeta {
    /// Layout version of this record.
    pub version: u32,
    /// What the values are.
    pub kind: ValueKind,
    /// Start of each bin in the stack (ps), one per bin, increasing.
    pub bin_starts_ps: Vec<f64>,
    /// Width of every bin (ps).
    pub bin_width_ps: f64,
    /// Side of a square pixel in the object plane (cm).
    pub pixel_pitch_cm: f64,
    /// Physics the stack was simulated with (or is to be reconstructed with).
    pub setup: Option<Setup>,
    /// How the ST-PSF was discretised, for simulated stacks.
    pub sampling: Option<Sampling>,
    /// Bins of the setup that are not in the stack.
    pub dropped_bins: Vec<DroppedBin>,
    /// Values that FFT round-off made negative and were set to 0.
    pub clamped_negative: u64,
    /// Seed of the Poisson sampler, for simulated counts.
    pub seed: Option<u64>,
    /// Where the stack came from (command, scene, file).
    pub source: String,
    /// How the sensor's edges were modelled when the stack was simulated;
    /// absent for measured stacks, whose sensor always has edges.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub boundary: Option<Boundary>,
    /// For measured stacks: the device, its configuration, the time window
    /// and the photon accounting of the acquisition.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acquisition: Option<serde_json::Value>,
    /// What the recording did not say, whose fields above hold
    /// placeholders: a file's writers and readers leave those out
    /// (an OME-TIFF gets no physical pixel size) and the reconstruction
    /// refuses a stack whose time unit is unknown.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unstated: Vec<Unstated>,
    /// The laser's repetition rate (Hz), where the recording states it
    /// (a PTU's sync rate, an `.sdt` block's sync rate): the phasors'
    /// fundamental frequency.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub laser_frequency_hz: Option<f64>,
    /// What the recording's statements of the laser's rate were found to
    /// be, where one was left out or overruled ([`crate::tags::laser`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub laser_notes: Vec<String>,
    /// The bins the instrument recorded whole, where the recording says
    /// (an `.sdt` block's TAC limits, a T3 file's sync period): bins
    /// outside it hold no photon, or a part of a bin's light.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recorded_bins: Option<RecordedBins>,
}

/// The bins `[first, end)` of a stack whose whole time span the
/// instrument recorded, and what says so.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordedBins {
    /// The first bin recorded whole.
    pub first: usize,
    /// One past the last bin recorded whole.
    pub end: usize,
    /// The recorded span (ps after the sync), `[from, to)`.
    pub span_ps: (f64, f64),
    /// What states the span, in words.
    pub stated_by: String,
}

impl RecordedBins {
    /// The bins of `starts_ps` (each `width_ps` wide) that lie whole in
    /// `[from_ps, to_ps)` (a thousandth of a bin's tolerance for round
    /// off); `None` when every bin does, or none.
    pub fn within(
        starts_ps: &[f64],
        width_ps: f64,
        (from_ps, to_ps): (f64, f64),
        stated_by: String,
    ) -> Option<Self> {
        let slack = 1e-3 * width_ps;
        let whole = |t: f64| t >= from_ps - slack && t + width_ps <= to_ps + slack;
        let first = starts_ps.iter().position(|&t| whole(t))?;
        let end = first + starts_ps[first..].iter().take_while(|&&t| whole(t)).count();
        (first > 0 || end < starts_ps.len()).then_some(Self {
            first,
            end,
            span_ps: (from_ps, to_ps),
            stated_by,
        })
    }

    /// The bins in words, for the notes.
    pub fn describe(&self, bins: usize) -> String {
        format!(
            "bins {} to {} of {bins}: the instrument recorded {:.1} to {:.1} ps ({})",
            self.first,
            self.end - 1,
            self.span_ps.0,
            self.span_ps.1,
            self.stated_by
        )
    }
}

/// A quantity a recording did not state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Unstated {
    /// The pixel pitch: `pixel_pitch_cm` is a placeholder of 1.
    PixelPitch,
    /// The time unit: `bin_starts_ps` and `bin_width_ps` count micro-time
    /// channels (ADC channels), not picoseconds.
    TimeUnit,
}

/// A K x H x W stack of `f32` values with its metadata.
#[derive(Debug, Clone, PartialEq)]
pub struct Stack {
    /// Values, indexed (bin, row, column).
    pub data: Array3<f32>,
    /// Metadata travelling with the values.
    pub meta: StackMeta,
    /// The photon counts exactly, kept only when some exceed 2^24, above
    /// which `f32` (`data`) holds whole numbers rounded; the writers store
    /// these instead (32-bit unsigned channels), so no count is lost.
    pub exact_counts: Option<Array3<u32>>,
}

/// Largest count every `f32` holds exactly (2^24).
pub const F32_EXACT_COUNT: u32 = 1 << 24;

/// A copy of `counts` when some exceed 2^24, where `f32` rounds them;
/// `None` when `f32` holds them all.
pub fn exact_copy(counts: ArrayView3<u32>) -> Option<Array3<u32>> {
    // The largest count by a flat fold where the counts are one slice (the
    // compiler vectorises it; `any` over the array's iterator took 10-15
    // ms of a 256 x 256 x 256 stack's `bin`).
    let largest = match counts.as_slice_memory_order() {
        Some(flat) => flat.iter().fold(0, |a, &c| a.max(c)),
        None => counts.iter().fold(0, |a, &c| a.max(c)),
    };
    (largest > F32_EXACT_COUNT).then(|| counts.to_owned())
}

/// Photon counts as binned, in the width they were read in: a recorded
/// file's 16-bit histograms stay 16-bit on their way to a file.
#[derive(Debug, Clone, Copy)]
pub enum CountsView<'a> {
    /// 16-bit counts.
    U16(ArrayView3<'a, u16>),
    /// 32-bit counts.
    U32(ArrayView3<'a, u32>),
}

impl<'a> CountsView<'a> {
    /// The bins `[first, end)` alone.
    pub fn bins(&self, first: usize, end: usize) -> CountsView<'a> {
        use ndarray::s;
        match self {
            CountsView::U16(c) => CountsView::U16((*c).slice_move(s![first..end, .., ..])),
            CountsView::U32(c) => CountsView::U32((*c).slice_move(s![first..end, .., ..])),
        }
    }

    /// `(bins, rows, columns)`.
    pub fn dim(&self) -> (usize, usize, usize) {
        match self {
            CountsView::U16(c) => c.dim(),
            CountsView::U32(c) => c.dim(),
        }
    }

    /// The largest count (0 when empty).
    pub fn max(&self) -> u32 {
        fn top<T: Copy + Ord + Default + Into<u32>>(c: &ArrayView3<T>) -> u32 {
            let m = match c.as_slice_memory_order() {
                Some(flat) => flat.iter().fold(T::default(), |a, &v| a.max(v)),
                None => c.iter().fold(T::default(), |a, &v| a.max(v)),
            };
            m.into()
        }
        match self {
            CountsView::U16(c) => top(c),
            CountsView::U32(c) => top(c),
        }
    }

    /// Photons per bin, every pixel summed.
    pub fn bin_totals(&self) -> Vec<f64> {
        fn totals<T: Copy + Into<f64>>(c: &ArrayView3<T>) -> Vec<f64> {
            c.outer_iter()
                .map(|plane| plane.iter().map(|&v| v.into()).sum())
                .collect()
        }
        match self {
            CountsView::U16(c) => totals(c),
            CountsView::U32(c) => totals(c),
        }
    }

    /// The counts as `u32`, owned.
    pub fn to_u32(&self) -> Array3<u32> {
        match self {
            CountsView::U16(c) => c.mapv(u32::from),
            CountsView::U32(c) => c.to_owned(),
        }
    }
}

/// Counts as `f32` values, with their [`exact_copy`].
pub fn counts_as_f32(counts: ArrayView3<u32>) -> (Array3<f32>, Option<Array3<u32>>) {
    (counts.mapv(|c| c as f32), exact_copy(counts))
}

/// What a stack file holds, before validation.
#[derive(Debug, Clone)]
pub struct StackFile {
    /// The values.
    pub data: Array3<f32>,
    /// The metadata, when the file has it.
    pub meta: Option<StackMeta>,
    /// The counts exactly, when the file stores whole numbers some of
    /// which `data` cannot hold (above 2^24).
    pub exact_counts: Option<Array3<u32>>,
}

/// Errors reading or writing stack files.
#[derive(Debug, thiserror::Error)]
pub enum StackError {
    /// Operating-system level failure.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file would need more memory than the budget, or is a special
    /// file or too large to read whole.
    #[error(transparent)]
    Memory(#[from] crate::files::ReadError),
    /// The file is not a valid stack; says which field and value.
    #[error("{path}: {reason}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

impl StackError {
    pub(crate) fn format(path: &Path, reason: impl Into<String>) -> Self {
        StackError::Format {
            path: path.to_owned(),
            reason: reason.into(),
        }
    }

    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        StackError::Io {
            path: path.to_owned(),
            source,
        }
    }
}

impl Stack {
    /// Number of bins K.
    pub fn bins(&self) -> usize {
        self.data.shape()[0]
    }

    /// Image of bin `k`.
    pub fn bin(&self, k: usize) -> ArrayView2<'_, f32> {
        self.data.slice(s![k, .., ..])
    }

    /// Sum over all bins and pixels.
    pub fn total(&self) -> f64 {
        self.data.iter().map(|&v| f64::from(v)).sum()
    }

    /// Checks that values and metadata agree and that every value is a
    /// finite non-negative number; the error names the bin and pixel.
    pub fn validate(&self, path: &Path) -> Result<(), StackError> {
        let k = self.bins();
        if self.meta.version != META_VERSION {
            return Err(StackError::format(
                path,
                format!(
                    "metadata version {} is not the version {META_VERSION} this program reads",
                    self.meta.version
                ),
            ));
        }
        let starts = &self.meta.bin_starts_ps;
        if let Some(i) = starts.iter().position(|t| !t.is_finite()) {
            return Err(StackError::format(
                path,
                format!("bin_starts_ps[{i}] = {} is not a finite time", starts[i]),
            ));
        }
        if let Some(i) = starts.windows(2).position(|w| w[1] <= w[0]) {
            return Err(StackError::format(
                path,
                format!(
                    "bin_starts_ps[{}] = {} ps does not come after bin_starts_ps[{i}] = {} ps: bins must start in increasing time",
                    i + 1,
                    starts[i + 1],
                    starts[i]
                ),
            ));
        }
        if self.meta.bin_starts_ps.len() != k {
            return Err(StackError::format(
                path,
                format!(
                    "bin_starts_ps has {} entries but the stack has {k} bins",
                    self.meta.bin_starts_ps.len()
                ),
            ));
        }
        if !(self.meta.bin_width_ps > 0.0 && self.meta.bin_width_ps.is_finite()) {
            return Err(StackError::format(
                path,
                format!("bin_width_ps = {} must be positive", self.meta.bin_width_ps),
            ));
        }
        if !(self.meta.pixel_pitch_cm > 0.0 && self.meta.pixel_pitch_cm.is_finite()) {
            return Err(StackError::format(
                path,
                format!(
                    "pixel_pitch_cm = {} must be positive",
                    self.meta.pixel_pitch_cm
                ),
            ));
        }
        // A stack's setup states the pitch a second time: the two must be
        // one (the reconstruction reads the setup, the writers the pitch).
        if let Some(setup) = &self.meta.setup {
            let from_setup = setup.sensor.fov_cm / setup.sensor.width_px as f64;
            let pitch = self.meta.pixel_pitch_cm;
            if (from_setup - pitch).abs() > 1e-6 * pitch {
                return Err(StackError::format(
                    path,
                    format!(
                        "pixel_pitch_cm = {pitch} contradicts setup.sensor (fov_cm {} over width_px {} = {from_setup} cm): correct one of them",
                        setup.sensor.fov_cm, setup.sensor.width_px
                    ),
                ));
            }
        }
        for (b, img) in self.data.axis_iter(Axis(0)).enumerate() {
            for ((r, c), &v) in img.indexed_iter() {
                check_count(f64::from(v), || format!("bin {b}, row {r}, column {c}"))
                    .map_err(|e| StackError::format(path, e.to_string()))?;
            }
        }
        Ok(())
    }

    /// A stack of `values` (no exact counts kept).
    pub fn new(data: Array3<f32>, meta: StackMeta) -> Self {
        Self {
            data,
            meta,
            exact_counts: None,
        }
    }

    /// A stack of photon counts: their `f32` values, and the counts
    /// themselves when some exceed 2^24.
    pub fn from_counts(counts: ArrayView3<u32>, meta: StackMeta) -> Self {
        let (data, exact_counts) = counts_as_f32(counts);
        Self {
            data,
            meta,
            exact_counts,
        }
    }

    /// [`Stack::from_counts`] that turns the counts into their values in
    /// their own memory: binning a 3 MB FLIM file makes a 32 MB stack, and
    /// touching that much fresh memory for the values cost a tenth of the
    /// `bin` command's time.
    pub fn from_owned_counts(counts: Array3<u32>, meta: StackMeta) -> Self {
        if !counts.is_standard_layout() {
            return Self::from_counts(counts.view(), meta);
        }
        let exact_counts = exact_copy(counts.view());
        let (dim, n) = (counts.dim(), counts.len());
        // Standard layout: the elements in order from the offset on.
        let (mut raw, offset) = counts.into_raw_vec_and_offset();
        let start = offset.unwrap_or(0);
        raw.truncate(start + n);
        raw.drain(..start);
        // Same size and alignment: the collect reuses the allocation.
        let values: Vec<f32> = raw.into_iter().map(|c| c as f32).collect();
        Self {
            data: Array3::from_shape_vec(dim, values).expect("one value per count"),
            meta,
            exact_counts,
        }
    }

    /// A stack from values and metadata, validated ([`Stack::validate`]);
    /// `path` names the source in errors.
    pub fn from_parts(data: Array3<f32>, meta: StackMeta, path: &Path) -> Result<Self, StackError> {
        let stack = Stack::new(data, meta);
        stack.validate(path)?;
        Ok(stack)
    }
}

impl StackMeta {
    /// The bins `[first, end)` a fit or map keeps by default: those the
    /// instrument recorded whole; `None` when the recording states none or
    /// `all_bins` asks for every bin.
    pub fn recorded_window(&self, all_bins: bool) -> Option<(usize, usize)> {
        self.recorded_bins
            .as_ref()
            .filter(|_| !all_bins)
            .map(|r| (r.first, r.end))
    }

    /// Metadata of data produced from `kernels` (simulated counts, expected
    /// counts, the kernels themselves): the kept bins, the physics, the
    /// sampling and the bins left out with their light.
    pub fn simulated(
        kernels: &scatterscope_physics::KernelStack,
        kind: ValueKind,
        source: String,
    ) -> Self {
        StackMeta {
            version: META_VERSION,
            kind,
            bin_starts_ps: kernels.kept_bins().map(|b| b.start_ps).collect(),
            bin_width_ps: kernels.setup.bins.width_ps,
            pixel_pitch_cm: kernels.setup.sensor.pixel_pitch_cm(),
            setup: Some(kernels.setup.clone()),
            sampling: Some(kernels.sampling),
            dropped_bins: kernels
                .dropped_bins()
                .map(|b| DroppedBin {
                    start_ps: b.start_ps,
                    photons: b.photons,
                })
                .collect(),
            clamped_negative: 0,
            seed: None,
            source,
            boundary: None,
            acquisition: None,
            unstated: Vec::new(),
            laser_frequency_hz: None,
            laser_notes: Vec::new(),
            recorded_bins: None,
        }
    }

    /// Whether the recording left `what` unstated.
    pub fn is_unstated(&self, what: Unstated) -> bool {
        self.unstated.contains(&what)
    }

    /// Sets the pixel pitch (cm), which is then stated.
    pub fn set_pixel_pitch(&mut self, cm: f64) {
        self.pixel_pitch_cm = cm;
        self.unstated.retain(|&u| u != Unstated::PixelPitch);
    }

    /// Metadata of measured photon counts: `bins` bins of `width_ps` from
    /// `start_ps` after the sync, no physics (the reconstruction takes it
    /// from the user), a pixel pitch unstated (a placeholder of 1 cm until
    /// [`StackMeta::set_pixel_pitch`]), and the acquisition record when
    /// the stack comes from a live acquisition.
    pub fn measured(
        start_ps: f64,
        width_ps: f64,
        bins: usize,
        source: String,
        acquisition: Option<serde_json::Value>,
    ) -> Self {
        StackMeta {
            version: META_VERSION,
            kind: ValueKind::Counts,
            bin_starts_ps: (0..bins).map(|k| start_ps + k as f64 * width_ps).collect(),
            bin_width_ps: width_ps,
            pixel_pitch_cm: 1.0,
            setup: None,
            sampling: None,
            dropped_bins: Vec::new(),
            clamped_negative: 0,
            seed: None,
            source,
            boundary: None,
            acquisition,
            unstated: vec![Unstated::PixelPitch],
            laser_frequency_hz: None,
            laser_notes: Vec::new(),
            recorded_bins: None,
        }
    }

    /// Metadata of a stack of `bins` bins, one after another from
    /// `setup`'s first bin, on `setup`'s sensor: what a file without
    /// metadata is taken to hold. The physics' time window becomes the
    /// file's (`bins` bins), so its photon budget is the recorded light.
    pub fn consecutive(
        setup: &Setup,
        bins: usize,
        kind: ValueKind,
        source: String,
    ) -> Result<Self, scatterscope_physics::ParamError> {
        let mut setup = setup.clone();
        setup.bins.count = bins;
        setup.validate()?;
        let mut meta =
            StackMeta::measured(setup.bins.start_ps, setup.bins.width_ps, bins, source, None);
        meta.set_pixel_pitch(setup.sensor.pixel_pitch_cm());
        meta.kind = kind;
        meta.setup = Some(setup);
        Ok(meta)
    }
}
