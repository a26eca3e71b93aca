//! What binning a recorded file is asked and gives, whatever its
//! format: the request ([`BinSpec`], [`Pixels`]), its window and pixel
//! map ([`window_and_map`]), the stacks and what the file said
//! ([`BinnedFile`], [`CountStack`], [`StackCounts`], [`Recording`]), and
//! why it could not be binned ([`RecordedFileError`]). The formats'
//! sources ([`super::recorded`]) make these; [`super::bin_file`] hands
//! them to callers.

use std::path::Path;

use ndarray::Array3;

use super::binning::{FrameSelect, MAX_BINS, PixelMap, TimeWindow, WindowError};
use super::counts::Counts;
use crate::formats::becker_hickl::sdt::SdtError;
use crate::formats::becker_hickl::spc::{CardFlags, SpcFileError, SpcInfo, SpcOptions};
use crate::formats::picoquant::{FileError, FileInfo};
use crate::formats::sstags::{TagFileError, TagFileSummary};
use crate::stack::{CountsView, Stack, StackError, StackMeta};

/// How input channels and markers become pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Pixels {
    /// The scanned image for imaging files, else one pixel.
    #[default]
    Auto,
    /// One pixel: every photon in one time histogram.
    Single,
    /// One pixel per input channel (SPAD arrays), trimmed to the highest
    /// channel that saw a photon.
    Channel,
}

crate::named::named!(Pixels {
    Auto => "auto",
    Single => "single",
    Channel => "channel",
});

/// What to bin: the time window and the pixel and frame mapping. The
/// `bin` command's flags are these fields (their docs are the flags' help).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct BinSpec {
    /// Bin width (default unit ps; default: the file's TCSPC resolution).
    #[cfg_attr(feature = "cli", arg(long = "bin-width", value_name = "BIN_WIDTH", value_parser = crate::units::parse_ps))]
    pub bin_width_ps: Option<f64>,
    /// Start of the first bin after the sync (default unit ps).
    #[cfg_attr(feature = "cli", arg(long = "t-start", value_name = "T_START", default_value = "0", value_parser = crate::units::parse_ps))]
    pub t_start_ps: f64,
    /// Number of bins (default: enough to cover one sync period).
    #[cfg_attr(feature = "cli", arg(long))]
    pub bins: Option<usize>,
    /// Keep only photons of this input channel (as numbered in the records).
    #[cfg_attr(feature = "cli", arg(long))]
    pub channel: Option<u16>,
    /// Pixel mapping: auto (image for imaging files, else single), single, channel.
    #[cfg_attr(feature = "cli", arg(long, value_parser = crate::named::choice::<Pixels>(), default_value = crate::Named::name(Pixels::default())))]
    pub pixels: Pixels,
    /// Frames of imaging files: sum, all (one stack per frame) or a frame number.
    #[cfg_attr(feature = "cli", arg(long, default_value = "sum"))]
    pub frames: FrameSelect,
    /// Bin the complete records of a cut file instead of failing.
    #[cfg_attr(feature = "cli", arg(long))]
    pub allow_truncated: bool,
    /// What a Becker & Hickl `.spc` file does not record (its module and
    /// micro-time unit); refused for other files, whose headers say.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub spc: SpcOptions,
}

impl Default for BinSpec {
    fn default() -> Self {
        Self {
            bin_width_ps: None,
            t_start_ps: 0.0,
            bins: None,
            channel: None,
            pixels: Pixels::Auto,
            frames: FrameSelect::Sum,
            allow_truncated: false,
            spc: SpcOptions::default(),
        }
    }
}

/// The stacks of one file, with everything a user needs to trust them:
/// float32 [`Stack`]s ([`bin_file`]) or the counts as binned
/// ([`bin_file_counts`]).
#[derive(Debug)]
pub struct BinnedFile<S = Stack> {
    /// The file and what its header says.
    pub recording: Recording,
    /// One stack per kept frame (one when frames are summed), counts with
    /// their metadata.
    pub stacks: Vec<S>,
    /// Each stack's bins, rows and columns.
    pub shape: (usize, usize, usize),
    /// Where the records and photons of the (last) pass went: they balance.
    pub counts: Counts,
    /// The window binned.
    pub window: TimeWindow,
    /// Micro-time resolution (ps): the window's unit.
    pub resolution_ps: f64,
    /// Records decoded per second in the (last) pass.
    pub records_per_s: f64,
    /// What was widened or fell outside, in words.
    pub notes: Vec<String>,
    /// Why the file ended early, when a cut file was binned.
    pub truncated: Option<String>,
    /// Whether the recording does not state the window's time unit (its
    /// bins are then micro-time channels or curve points).
    pub time_unstated: bool,
}

/// One binned stack lent to the caller of [`bin_file_each`]: its counts
/// in the width the file held them, and their metadata.
#[derive(Debug, Clone, Copy)]
pub struct StackCounts<'a> {
    /// Photons per bin, row and column.
    pub counts: CountsView<'a>,
    /// What the counts are.
    pub meta: &'a StackMeta,
    /// Its place among the file's stacks (from 0).
    pub index: usize,
    /// How many stacks the file gives.
    pub of: usize,
}

impl StackCounts<'_> {
    /// An owned copy, counts as `u32`.
    pub fn to_owned(&self) -> CountStack {
        CountStack {
            counts: self.counts.to_u32(),
            meta: self.meta.clone(),
        }
    }
}

/// One kept frame's photon counts as binned, with their metadata: a
/// [`Stack`] before its values become float32.
#[derive(Debug)]
pub struct CountStack {
    /// Photons per bin, row and column.
    pub counts: Array3<u32>,
    /// What the counts are.
    pub meta: StackMeta,
}

impl CountStack {
    /// The counts as `T` (such as `u16`); `Err` holds the largest count
    /// when it does not fit.
    pub fn narrowed<T: TryFrom<u32> + Copy + Default>(&self) -> Result<Array3<T>, u32> {
        // Two flat passes the compiler vectorises (a max, then a conversion
        // without a failing branch): 12 -> 6 ms on a 256 x 256 x 134 FLIM
        // stack against one `mapv` with a checked conversion.
        let counts = self.counts.as_standard_layout();
        let flat = counts
            .as_slice()
            .expect("a standard-layout array is one slice");
        let largest = flat.iter().fold(0, |a, &c| a.max(c));
        T::try_from(largest).map_err(|_| largest)?;
        // Every count is at most the largest, which fits: no default is used.
        let values = flat
            .iter()
            .map(|&c| T::try_from(c).unwrap_or_default())
            .collect();
        Ok(Array3::from_shape_vec(self.counts.dim(), values).expect("as many values as counts"))
    }
}

/// The file a [`BinnedFile`] came from.
#[derive(Debug)]
pub enum Recording {
    /// A file of a format without a variant of its own, as its source
    /// describes it: a new format's source needs no change here.
    Described(Box<dyn DescribedRecording>),
    /// A PicoQuant file and its header.
    PicoQuant(FileInfo),
    /// A Becker & Hickl FIFO file (`.spc`): its header, and what its
    /// records flagged.
    BeckerHicklFifo {
        /// What the header record says.
        info: SpcInfo,
        /// GAP, INVALID and overflow flags counted.
        flags: CardFlags,
    },
    /// A Becker & Hickl histogram file (`.sdt`): one stack per decay block.
    BeckerHicklHistogram {
        /// The file's identification and module.
        id: String,
        /// Blocks not binned, in words.
        left_out: Vec<String>,
        /// Blocks binned by curve point, their time unit unstated, and why.
        unstated: Vec<String>,
        /// Decay blocks the asked window does not fit, left out, and why.
        misfits: Vec<String>,
    },
    /// A tag file (`.sstags`): its header and frames, and the records'
    /// own counts.
    TagFile {
        /// What the file holds.
        summary: TagFileSummary,
    },
}

/// What the source of a format without its own [`Recording`] variant
/// says of a file it binned.
pub trait DescribedRecording: std::fmt::Debug + Send + Sync {
    /// The summary's first line: the file, and where its records went
    /// (`counts`, decoded at `records_per_s`).
    fn summary(&self, counts: &Counts, records_per_s: f64) -> String;

    /// What makes its stacks less than a whole recording's, in words.
    fn warnings(&self) -> Vec<String>;
}

impl BinnedFile<CountStack> {
    /// The stacks as float32 [`Stack`]s, each frame's counts dropped once
    /// converted.
    pub fn into_stacks(self) -> BinnedFile<Stack> {
        self.try_map_stacks(|s| {
            Ok::<_, std::convert::Infallible>(Stack::from_owned_counts(s.counts, s.meta))
        })
        .unwrap_or_else(|e| match e {})
    }
}

impl<A> BinnedFile<A> {
    /// The same file with each stack through `f`, in order, each dropped
    /// once mapped; the first error ends it.
    pub fn try_map_stacks<B, E>(
        mut self,
        f: impl FnMut(A) -> Result<B, E>,
    ) -> Result<BinnedFile<B>, E> {
        let stacks = std::mem::take(&mut self.stacks)
            .into_iter()
            .map(f)
            .collect::<Result<_, _>>()?;
        Ok(self.with_stacks(stacks))
    }

    /// The same file holding `stacks` (one per stack it had) instead.
    pub(crate) fn with_stacks<B>(self, stacks: Vec<B>) -> BinnedFile<B> {
        BinnedFile {
            stacks,
            recording: self.recording,
            shape: self.shape,
            counts: self.counts,
            window: self.window,
            resolution_ps: self.resolution_ps,
            records_per_s: self.records_per_s,
            notes: self.notes,
            truncated: self.truncated,
            time_unstated: self.time_unstated,
        }
    }
}

impl<S> BinnedFile<S> {
    /// What makes the stacks less than a whole recording's, or empty, in
    /// words: the input cut, never finished or interrupted, or no photon
    /// binned. A command ends with a warning status when there are any.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        match &self.recording {
            Recording::Described(d) => w.extend(d.warnings()),
            Recording::PicoQuant(info) => w.extend(info.completeness_note()),
            Recording::TagFile { summary, .. } if summary.interrupted => w.push(
                "the run that wrote it was interrupted before its planned end (its end frame says so)"
                    .into(),
            ),
            Recording::BeckerHicklHistogram {
                unstated, misfits, ..
            } => {
                w.extend(unstated.iter().map(|u| {
                    format!("{u}: the block's time unit is unknown, so its stack's bins are curve points, marked so in every output")
                }));
                w.extend(misfits.iter().map(|m| format!("left out {m}")));
            }
            Recording::TagFile { .. } => {}
            Recording::BeckerHicklFifo { flags, .. } if flags.gaps > 0 => w.push(format!(
                "{} record(s) carry the GAP flag: the card's FIFO was full and photons before each were lost in the card, so the stack holds fewer than were detected",
                flags.gaps
            )),
            Recording::BeckerHicklFifo { .. } => {}
        }
        if let Recording::BeckerHicklFifo { info, .. } = &self.recording
            && info.micro_unit_s.is_none()
        {
            w.push(format!(
                "the micro-time unit is unknown ({}): the stacks' bins are ADC channels, marked so in every output (give --micro-unit, ps: TAC range / TAC gain / {} ADC channels, to bin by time)",
                info.micro_unit_from,
                info.module.adc_channels()
            ));
        }
        w.extend(self.truncated.iter().cloned());
        let acc = self.counts;
        if acc.binned == 0 {
            let end = self.window.start_ps(self.resolution_ps)
                + self.window.width_ps(self.resolution_ps) * self.window.bins as f64;
            w.push(format!(
                "the stack is empty: none of the {} photons was binned ({} outside the time window {} to {end} ps, {} on other channels, {} outside the image or its kept frames, {} of frames past the memory budget)",
                acc.photons,
                acc.outside_window,
                self.window.start_ps(self.resolution_ps),
                acc.other_channel,
                acc.outside_region,
                acc.over_budget,
            ));
        }
        w
    }

    /// Where every record went, the notes and the window, one line each.
    pub fn summary(&self) -> Vec<String> {
        let acc = self.counts;
        let mut lines = vec![match &self.recording {
            Recording::Described(d) => d.summary(&acc, self.records_per_s),
            Recording::PicoQuant(_) => format!(
                "{} records ({:.0} M records/s): {} photons, {} binned, {} outside the time window, {} on other channels, {} outside the image; {} markers, {} frames",
                acc.records,
                self.records_per_s / 1e6,
                acc.photons,
                acc.binned,
                acc.outside_window,
                acc.other_channel,
                acc.outside_region,
                acc.markers,
                acc.frames
            ),
            Recording::BeckerHicklFifo { info, flags } => format!(
                "{} records ({:.0} M records/s, {}): {} photons, {} binned, {} outside the time window, {} on other channels; {} markers; {} INVALID records dropped, {} overflow count records ({} macro-time overflows), {} GAP flags",
                acc.records,
                self.records_per_s / 1e6,
                info.module.cards(),
                acc.photons,
                acc.binned,
                acc.outside_window,
                acc.other_channel,
                acc.markers,
                flags.invalid,
                flags.overflow_entries,
                flags.overflows,
                flags.gaps
            ),
            Recording::BeckerHicklHistogram { id, .. } => format!(
                "{} curve points of {} stack(s) ({id}): {} photons, {} binned, {} outside the time window",
                acc.records,
                self.stacks.len(),
                acc.photons,
                acc.binned,
                acc.outside_window,
            ),
            Recording::TagFile { .. } => format!(
                "{} records ({:.0} M records/s): {} photons, {} binned, {} outside the window, {} lost in the device, {} invalid",
                acc.records,
                self.records_per_s / 1e6,
                acc.photons,
                acc.binned,
                acc.outside_window,
                acc.lost_in_device,
                acc.invalid_records
            ),
        }];
        lines.extend(self.notes.iter().map(|n| format!("note: {n}")));
        lines.extend(self.warnings().iter().map(|w| format!("warning: {w}")));
        let (k, h, w) = self.shape;
        let (width, start) = (
            self.window.width_ps(self.resolution_ps),
            self.window.start_ps(self.resolution_ps),
        );
        let bins = match self.time_unstated {
            true => format!("{width}-channel bins from channel {start}; time unit unknown"),
            false => format!("{width} ps bins from {start} ps"),
        };
        lines.push(format!(
            "{} stack(s) of {k} x {h} x {w} ({bins})",
            self.stacks.len()
        ));
        lines
    }
}

/// Why a recorded file cannot be binned or surveyed.
#[derive(Debug, thiserror::Error)]
pub enum RecordedFileError {
    /// The PicoQuant file cannot be read.
    #[error(transparent)]
    File(#[from] FileError),
    /// The tag file cannot be read.
    #[error(transparent)]
    TagFile(#[from] TagFileError),
    /// The Becker & Hickl FIFO file cannot be read.
    #[error(transparent)]
    Spc(#[from] SpcFileError),
    /// The Becker & Hickl histogram file cannot be read.
    #[error(transparent)]
    Sdt(#[from] SdtError),
    /// More memory than the budget.
    #[error(transparent)]
    Memory(#[from] crate::memory::MemoryError),
    /// A stack could not be written.
    #[error(transparent)]
    Output(#[from] StackError),
    /// The request (its window, pixels, channel or `.spc` reading) does
    /// not fit the file.
    #[error("{path}: {reason}")]
    Spec {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// Checks one stack of `window` over `map` (its counts and their float32
/// copy) against the memory budget.
pub(crate) fn check_stack_memory(
    path: &Path,
    window: &TimeWindow,
    map: &PixelMap,
) -> Result<(), RecordedFileError> {
    let (h, w) = map.image_size();
    crate::memory::check(crate::memory::bytes_of([window.bins, h, w], 8), || {
        format!(
            "a stack of {} bins of {w} x {h} pixels from {}",
            window.bins,
            path.display()
        )
    })?;
    Ok(())
}

/// The request does not fit the file at `path`, for `reason`.
pub(crate) fn spec_error(path: &Path, reason: String) -> RecordedFileError {
    RecordedFileError::Spec {
        path: path.to_owned(),
        reason,
    }
}

/// The time window and pixel map `spec` asks for, on T3 records of
/// `resolution_ps` micro-time unit and `period_ps` sync period, scanned as
/// `imaging` describes (if at all): the defaults of [`BinSpec`] resolved.
pub fn window_and_map(
    spec: &BinSpec,
    resolution_ps: f64,
    period_ps: f64,
    imaging: Option<crate::events::Imaging>,
) -> Result<(TimeWindow, PixelMap), WindowError> {
    let width_ps = spec.bin_width_ps.unwrap_or(resolution_ps);
    let bins = spec.bins.unwrap_or_else(|| {
        TimeWindow::period_bins(period_ps, spec.t_start_ps, width_ps).min(MAX_BINS)
    });
    let window = TimeWindow::from_ps(spec.t_start_ps, width_ps, bins, resolution_ps)?;
    let map = match (spec.pixels, imaging) {
        (Pixels::Auto, Some(img)) => PixelMap::Scan(img),
        (Pixels::Auto | Pixels::Single, _) => PixelMap::Single,
        (Pixels::Channel, _) => PixelMap::Channel { width: 64 },
    };
    window.check_stack(&map)?;
    Ok((window, map))
}
