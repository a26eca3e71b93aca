//! A recorded tag file -> transient stacks: the one place that reads,
//! decodes and bins a file, for the `bin` command, the benchmarks and the
//! tests alike. Two kinds of file: PicoQuant T3 files (PTU, PT3, HT3) and
//! the project's tag files (`.sstags`, from `acquire --tags`).
//!
//! The default window starts at `t_start_ps` and covers one sync period.
//! In PicoQuant files, photons whose micro times reach past it (a TAC
//! range longer than the period, a sync divider) are not dropped: the
//! window is widened to hold the largest micro time present and the file
//! binned again, and a note says so. A window the caller set is kept; a
//! note says how many photons fell past it and how many bins would hold
//! them. Tag files hold the device's whole sensor and micro times within
//! its sync period; they are binned onto the sensor in whole micro-time
//! steps.

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;

use crate::formats::becker_hickl::sdt::{self, BlockCounts, SdtError};
use crate::formats::becker_hickl::spc::{self, CardFlags, SpcFileError, SpcInfo, SpcOptions};
use crate::formats::detect::Format;
use crate::formats::sstags::{TagFile, TagFileError, TagFileSummary};
use ndarray::{Array3, s};

use super::binning::{
    Binner, FrameSelect, MAX_BINS, PastWindow, PixelMap, Region, TimeWindow, WindowError,
};
use super::counts::Counts;
use super::wire::bin_batch;
use crate::formats::picoquant::records::Decoder;
use crate::formats::picoquant::{FileError, FileInfo, RecordReader, TtrError, open};
use crate::formats::png::{SheetScale, write_counts_sheet};
use crate::stack::{CountsView, Stack, StackError, StackMeta, Unstated};

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
        self,
        f: impl FnMut(A) -> Result<B, E>,
    ) -> Result<BinnedFile<B>, E> {
        Ok(BinnedFile {
            stacks: self.stacks.into_iter().map(f).collect::<Result<_, _>>()?,
            recording: self.recording,
            shape: self.shape,
            counts: self.counts,
            window: self.window,
            resolution_ps: self.resolution_ps,
            records_per_s: self.records_per_s,
            notes: self.notes,
            truncated: self.truncated,
            time_unstated: self.time_unstated,
        })
    }
}

/// Which files [`bin_file_to`] writes of each stack, into `dir`:
/// `stack.exr` (or `stack.npy` with its JSON sidecar), with `stack.png`
/// and `stack.ome.tif` when asked; `stack_f000.exr`, ... when a file
/// gives several stacks (frames kept apart, `.sdt` blocks).
#[derive(Debug, Clone, PartialEq)]
pub struct BinOutputs {
    /// The folder (created if missing).
    pub dir: PathBuf,
    /// `.npy` (16- or 32-bit counts) with its JSON sidecar instead of EXR.
    pub npy: bool,
    /// A PNG contact sheet of each stack.
    pub previews: bool,
    /// Each stack also as OME-TIFF (Fiji, napari, FLIMfit).
    pub ome_tiff: bool,
}

impl BinOutputs {
    /// EXR stacks with their contact sheets into `dir` (the `bin`
    /// command's default).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            npy: false,
            previews: true,
            ome_tiff: false,
        }
    }

    /// The files of stack `s` (one of `of`), refused where one would be
    /// a file `input` reads (the input or its setup sidecar).
    fn paths(&self, s: &StackCounts<'_>, input: &Path) -> Result<Vec<PathBuf>, StackError> {
        let stem = if s.of > 1 {
            format!("stack_f{:03}", s.index)
        } else {
            "stack".into()
        };
        let main = self
            .dir
            .join(format!("{stem}.{}", if self.npy { "npy" } else { "exr" }));
        let mut files = vec![main.clone()];
        if self.npy {
            files.push(crate::formats::npy::sidecar_path(&main));
        }
        if self.previews {
            files.push(self.dir.join(format!("{stem}.png")));
        }
        if self.ome_tiff {
            files.push(self.dir.join(format!("{stem}.ome.tif")));
        }
        let read = [input.to_owned(), input.with_extension("set")];
        if let Some(f) = files
            .iter()
            .find(|f| read.iter().any(|r| crate::files::input::same_file(f, r)))
        {
            return Err(StackError::format(
                f,
                format!(
                    "is a file {} reads: writing it would destroy the recording; choose another --out",
                    input.display()
                ),
            ));
        }
        Ok(files)
    }

    /// Writes stack `s` of the file `input`; returns the files written
    /// (the stack's first).
    fn write(&self, s: StackCounts<'_>, input: &Path) -> Result<Vec<PathBuf>, StackError> {
        std::fs::create_dir_all(&self.dir).map_err(|e| StackError::io(&self.dir, e))?;
        let files = self.paths(&s, input)?;
        let stack = &files[0];
        // The stack and its sheet at once, on two threads.
        let (saved, sheet) = rayon::join(
            || crate::formats::stack_file::save_counts(s.counts, s.meta, stack),
            || {
                self.previews
                    .then(|| {
                        let png = stack.with_extension("png");
                        write_counts_sheet(s.counts, s.meta, SheetScale::Shared, &png)
                    })
                    .transpose()
            },
        );
        saved?;
        sheet?;
        if self.ome_tiff {
            let tif = files.last().expect("the OME-TIFF is listed last");
            crate::formats::stack_file::save_counts(s.counts, s.meta, tif)?;
        }
        Ok(files)
    }
}

/// Bins the recorded file `path` as `spec` says ([`bin_file_each`]) and
/// writes each stack as `outputs` says as soon as it is binned: what the
/// `bin` command runs. No output may be a file the binning reads. The
/// result's stacks are the files written for each.
pub fn bin_file_to(
    path: &Path,
    spec: &BinSpec,
    outputs: &BinOutputs,
) -> Result<BinnedFile<Vec<PathBuf>>, RecordedFileError> {
    // Bins an EXR cannot hold are refused before the file is read.
    if let Some(bins) = spec
        .bins
        .filter(|&b| !outputs.npy && b > crate::formats::exr::MAX_CHANNELS)
    {
        return Err(spec_error(
            path,
            format!(
                "{bins} bins: an OpenEXR stack holds at most {} (OpenEXR's library opens no more); write .npy (--npy) or bin fewer",
                crate::formats::exr::MAX_CHANNELS
            ),
        ));
    }
    bin_file_each(path, spec, |s| Ok(outputs.write(s, path)?))
}

impl<S> BinnedFile<S> {
    /// What makes the stacks less than a whole recording's, or empty, in
    /// words: the input cut, never finished or interrupted, or no photon
    /// binned. A command ends with a warning status when there are any.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        match &self.recording {
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

/// Bins a recorded file into transient stacks: a project tag file
/// (recognised by its magic), a PicoQuant T3 file (PTU, PT3, HT3) or a
/// Becker & Hickl file (`.spc` photons, `.sdt` histograms).
pub fn bin_file(path: &Path, spec: &BinSpec) -> Result<BinnedFile, RecordedFileError> {
    bin_file_counts(path, spec).map(BinnedFile::into_stacks)
}

/// [`bin_file`] with the counts as binned (`u32`), for a caller that
/// wants them in another type or as they are.
pub fn bin_file_counts(
    path: &Path,
    spec: &BinSpec,
) -> Result<BinnedFile<CountStack>, RecordedFileError> {
    let format = Format::of_file(path);
    spec.spc.check_applies(path, format)?;
    match format {
        Format::TagFile => bin_tag_file(path, spec),
        Format::BeckerHicklFifo => bin_spc(path, spec),
        Format::BeckerHicklHistogram => bin_sdt(path, spec, &mut |s| Ok(s.to_owned())),
        _ => bin_picoquant(path, spec),
    }
}

/// Bins a recorded file as [`bin_file_counts`] does, handing each stack to
/// `each` as soon as it is binned: for a histogram file (`.sdt`) before
/// the next block is read, so that a file of many large blocks needs the
/// memory of one, and in the width the file stored (16-bit histograms
/// stay 16-bit). What `each` returns (the files it wrote, say) are the
/// result's stacks.
pub fn bin_file_each<S>(
    path: &Path,
    spec: &BinSpec,
    mut each: impl FnMut(StackCounts<'_>) -> Result<S, RecordedFileError>,
) -> Result<BinnedFile<S>, RecordedFileError> {
    let format = Format::of_file(path);
    spec.spc.check_applies(path, format)?;
    let binned = match format {
        Format::BeckerHicklHistogram => return bin_sdt(path, spec, &mut each),
        Format::TagFile => bin_tag_file(path, spec)?,
        Format::BeckerHicklFifo => bin_spc(path, spec)?,
        _ => bin_picoquant(path, spec)?,
    };
    let of = binned.stacks.len();
    let mut index = 0;
    binned.try_map_stacks(|s| {
        index += 1;
        each(StackCounts {
            counts: CountsView::U32(s.counts.view()),
            meta: &s.meta,
            index: index - 1,
            of,
        })
    })
}

/// Checks one stack of `window` over `map` (its counts and their float32
/// copy) against the memory budget.
fn check_stack_memory(
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

/// A file of T3 records binned in passes: PicoQuant or Becker & Hickl.
enum T3File {
    PicoQuant(FileInfo),
    Spc(SpcInfo),
}

impl T3File {
    /// Records to bin.
    fn records(&self) -> u64 {
        match self {
            T3File::PicoQuant(info) => info.records_to_read(),
            T3File::Spc(info) => info.records_present,
        }
    }

    /// Bins the `part`-th of `parts` consecutive ranges of the records
    /// with `binner`; the text of a truncation when the part ends early
    /// and `allow_truncated` lets it, and what the records flagged.
    fn bin_part(
        &self,
        path: &Path,
        part: usize,
        parts: usize,
        binner: Binner,
        allow_truncated: bool,
    ) -> Result<(Binner, Option<String>, CardFlags), RecordedFileError> {
        match self {
            T3File::PicoQuant(info) => {
                let reader = info.records_part(part, parts)?;
                let (binner, cut) = bin_records(path, info, reader, binner, allow_truncated)?;
                Ok((binner, cut, CardFlags::default()))
            }
            T3File::Spc(info) => bin_spc_records(info, part, parts, binner),
        }
    }
}

/// A PicoQuant T3 file.
fn bin_picoquant(path: &Path, spec: &BinSpec) -> Result<BinnedFile<CountStack>, RecordedFileError> {
    let (info, _) = open(path)?;
    info.check_finished(spec.allow_truncated)?;
    if !info.record_type.is_t3() {
        return Err(spec_error(
            path,
            format!(
                "{} records carry no micro time; binning needs a T3 file",
                info.record_type.name()
            ),
        ));
    }
    let res_ps = info.resolution_s * 1e12;
    let period_ps = info.macro_unit_s * 1e12;
    let imaging = info.imaging;
    let pixel_cm = info.pixel_size_cm();
    // The laser's rate: the file's measured sync rate, else the T3 sync
    // period's.
    let laser_hz = info
        .sync_rate_hz
        .filter(|r| r.is_finite() && *r > 0.0)
        .unwrap_or(1.0 / info.macro_unit_s);
    let notes = info.unread_note().into_iter().collect();
    let source = format!(
        "{} ({}, {})",
        path.display(),
        info.device,
        info.record_type.name()
    );
    let mut binned = bin_t3(
        path,
        spec,
        T3File::PicoQuant(info),
        (res_ps, period_ps),
        imaging,
        source,
        notes,
    )?;
    // The image's pixel size, when the stacks are the scanned image.
    let scanned = imaging.is_some_and(|img| {
        let (_, h, w) = binned.shape;
        (h, w) == (img.pixels_y, img.pixels_x) && spec.pixels == Pixels::Auto
    });
    for s in &mut binned.stacks {
        if let (Some(cm), true) = (pixel_cm, scanned) {
            s.meta.set_pixel_pitch(cm);
        }
        s.meta.laser_frequency_hz = Some(laser_hz).filter(|r| r.is_finite() && *r > 0.0);
    }
    Ok(binned)
}

/// A Becker & Hickl FIFO file: its micro times cover the ADC's channels.
fn bin_spc(path: &Path, spec: &BinSpec) -> Result<BinnedFile<CountStack>, RecordedFileError> {
    let info = spc::open(path, &spec.spc)?;
    info.check_whole(spec.allow_truncated)?;
    // Without its unit the file bins by ADC channel: one bin per channel
    // (a "ps" below is then a channel), every stack marked so.
    let channels = info.micro_unit_s.is_none();
    if channels && (spec.bin_width_ps.is_some() || spec.t_start_ps != 0.0) {
        return Err(spec_error(
            path,
            format!(
                "--bin-width and --t-start are times, and this file's micro-time unit is unknown ({}): give it with --micro-unit (ps: TAC range / TAC gain / {} ADC channels), or bin by ADC channel without them",
                info.micro_unit_from,
                info.module.adc_channels()
            ),
        ));
    }
    let res_ps = info.micro_unit_s.map_or(1.0, |s| s * 1e12);
    let period_ps = f64::from(info.module.adc_channels()) * res_ps;
    let mut notes = vec![match channels {
        false => format!("micro-time unit {res_ps:.6} ps ({})", info.micro_unit_from),
        true => format!(
            "binned by ADC channel, one bin per channel: the micro-time unit is unknown ({})",
            info.micro_unit_from
        ),
    }];
    if info.module_assumed {
        notes.push(format!(
            "records read as {}: a .spc file does not record its module (an SPC-600/630 file needs --spc-module)",
            info.module.cards()
        ));
    }
    let source = format!(
        "{} (Becker & Hickl {})",
        path.display(),
        info.module.cards()
    );
    let mut binned = bin_t3(
        path,
        spec,
        T3File::Spc(info),
        (res_ps, period_ps),
        None,
        source,
        notes,
    )?;
    if channels {
        for s in &mut binned.stacks {
            s.meta.unstated.push(Unstated::TimeUnit);
        }
    }
    Ok(binned)
}

/// Bins a part of a `.spc` file's records (see [`T3File::bin_part`]).
fn bin_spc_records(
    info: &SpcInfo,
    part: usize,
    parts: usize,
    mut binner: Binner,
) -> Result<(Binner, Option<String>, CardFlags), RecordedFileError> {
    let spc_err = |error| SpcFileError {
        path: info.path.clone(),
        error,
    };
    let mut reader = info.records_part(part, parts)?;
    let flags = if info.module == spc::SpcModule::Spc600Channels4096 {
        let mut decoder = spc::Spc48Decoder(info.decoder());
        let mut chunk = Vec::new();
        while reader.next_chunk48(&mut chunk).map_err(spc_err)? {
            binner.bin_chunk(&mut decoder, &chunk);
        }
        decoder.0.flags
    } else {
        let mut decoder = info.decoder();
        let mut chunk = Vec::new();
        while reader.next_chunk32(&mut chunk).map_err(spc_err)? {
            binner.bin_chunk(&mut decoder, &chunk);
        }
        decoder.flags
    };
    // The cut tail (refused earlier unless allowed) ends the last part.
    let cut = (part + 1 == parts && info.trailing_bytes > 0).then(|| info.cut().to_string());
    Ok((binner, cut, flags))
}

/// Bins a T3 file of `(micro-time unit, sync period)` in ps, whose default
/// window is one period, widened to every micro time present.
fn bin_t3(
    path: &Path,
    spec: &BinSpec,
    file: T3File,
    (res_ps, period_ps): (f64, f64),
    imaging: Option<crate::events::Imaging>,
    source: String,
    mut notes: Vec<String>,
) -> Result<BinnedFile<CountStack>, RecordedFileError> {
    let spec_err = |reason| spec_error(path, reason);
    let (window, map) =
        window_and_map(spec, res_ps, period_ps, imaging).map_err(|e| spec_err(e.to_string()))?;
    // A default window gets a margin past the sync period, so that micro
    // times just past it (a TAC range a little longer than the period, the
    // last step of a period) bin in one pass instead of two.
    let margin = if spec.bins.is_none() {
        (window.bins / 64 + 8).min(MAX_BINS.saturating_sub(window.bins))
    } else {
        0
    };
    let with_margin = TimeWindow {
        bins: window.bins + margin,
        ..window
    };
    let first = if margin > 0 && with_margin.check_stack(&map).is_ok() {
        with_margin
    } else {
        window
    };
    check_stack_memory(path, &first, &map)?;
    let mut pass = run_pass(path, &file, first, map, spec)?;
    // Photons past the period: in the margin (binned) and past it.
    let (in_margin, last_bin) = photons_from(&pass.stacks, window.bins);
    let past_photons = pass.past.photons + in_margin;
    if past_photons > 0 {
        let max_micro = if pass.past.photons > 0 {
            pass.past.max_micro
        } else {
            let k = last_bin.expect("photons in the margin have a bin") as f64;
            ((window.start + (k + 1.0) * window.width).ceil() - 1.0) as u32
        };
        let needed = window.bins_to_hold(max_micro);
        let where_ = format!(
            "{past_photons} photon(s) had micro times past the window's end ({:.6} ps), up to {max_micro} ({:.6} ps)",
            (window.start + window.width * window.bins as f64) * res_ps,
            f64::from(max_micro) * res_ps
        );
        let wider = TimeWindow {
            bins: needed,
            ..window
        };
        let fits = needed <= MAX_BINS && wider.check_stack(&map).is_ok();
        if spec.bins.is_none() && fits {
            // The default window holds every micro time present.
            if needed <= pass.window.bins {
                trim(&mut pass, needed);
            } else {
                pass = run_pass(path, &file, wider, map, spec)?;
            }
            notes.push(format!(
                "{where_}: the default window (one sync period, {} bins) was widened to {needed} bins to hold them",
                window.bins
            ));
        } else {
            if pass.window.bins != window.bins {
                // Count the margin's photons outside, as the window says.
                pass = run_pass(path, &file, window, map, spec)?;
            }
            notes.push(if spec.bins.is_none() {
                format!(
                    "{where_}: holding them would take {needed} bins, more than {MAX_BINS} or a stack of more than 2^30 counts; they are counted outside the window"
                )
            } else {
                format!("{where_}: they are counted outside the window; {needed} bins would hold them")
            });
        }
    } else if pass.window.bins != window.bins {
        trim(&mut pass, window.bins);
    }
    let Pass {
        stacks,
        counts: tally,
        window,
        records_per_s,
        truncated,
        flags,
        ..
    } = pass;
    if tally.over_budget > 0 {
        notes.push(format!(
            "{} photon(s) of frames past the first {} were not kept: the memory budget holds {} stacks of {} bins of {} x {} pixels (bin the frames summed, or one at a time)",
            tally.over_budget,
            stacks.len(),
            stacks.len(),
            window.bins,
            map.image_size().1,
            map.image_size().0,
        ));
    }
    let stacks = if let PixelMap::Channel { .. } = map {
        // Trim the channel row to the highest channel that saw a photon in
        // any kept frame (rows scanned contiguously: a column-wise scan of
        // the empty channels cost a sixth of the binning on small files).
        let width = stacks[0].dim().2;
        let mut seen = vec![0u32; width];
        for row in stacks.iter().flat_map(|s| {
            s.as_slice()
                .expect("the binner's stacks are contiguous")
                .chunks_exact(width)
        }) {
            seen.iter_mut().zip(row).for_each(|(a, &v)| *a |= v);
        }
        let used = seen.iter().rposition(|&v| v > 0).map_or(1, |p| p + 1);
        stacks
            .iter()
            .map(|s| s.slice(s![.., .., ..used]).to_owned())
            .collect()
    } else {
        stacks
    };
    let shape = stacks[0].dim();
    let stacks = stacks
        .into_iter()
        .map(|counts| CountStack {
            counts,
            meta: StackMeta::measured(
                window.start_ps(res_ps),
                window.width_ps(res_ps),
                window.bins,
                source.clone(),
                None,
            ),
        })
        .collect();
    let (recording, time_unstated) = match file {
        T3File::PicoQuant(info) => (Recording::PicoQuant(info), false),
        T3File::Spc(info) => {
            let unstated = info.micro_unit_s.is_none();
            (Recording::BeckerHicklFifo { info, flags }, unstated)
        }
    };
    Ok(BinnedFile {
        recording,
        stacks,
        shape,
        counts: tally,
        window,
        resolution_ps: res_ps,
        records_per_s,
        notes,
        truncated,
        time_unstated,
    })
}

/// Photons in bins `from` and later of every stack, and the last such bin
/// that holds any.
fn photons_from(stacks: &[Array3<u32>], from: usize) -> (u64, Option<usize>) {
    let mut total = 0u64;
    let mut last = None;
    for s in stacks {
        for (k, plane) in s.outer_iter().enumerate().skip(from) {
            let n: u64 = plane.iter().map(|&v| u64::from(v)).sum();
            if n > 0 {
                total += n;
                last = last.max(Some(k));
            }
        }
    }
    (total, last)
}

/// Keeps the first `bins` bins of a pass (the rest are empty).
fn trim(pass: &mut Pass, bins: usize) {
    for s in &mut pass.stacks {
        // In place: the first bins of a standard-layout array stay
        // contiguous, and nothing is copied.
        s.slice_collapse(s![..bins, .., ..]);
    }
    pass.window.bins = bins;
}

/// Records of the smallest part of a file binned on a core of its own.
const PART_RECORDS: u64 = 1 << 22;

/// One read -> decode -> bin pass over the records.
struct Pass {
    stacks: Vec<Array3<u32>>,
    counts: Counts,
    past: PastWindow,
    window: TimeWindow,
    records_per_s: f64,
    truncated: Option<String>,
    flags: CardFlags,
}

fn run_pass(
    path: &Path,
    file: &T3File,
    window: TimeWindow,
    map: PixelMap,
    spec: &BinSpec,
) -> Result<Pass, RecordedFileError> {
    let start = Instant::now();
    let binner = Binner::new(window, map, spec.channel, spec.frames);
    let records = file.records();
    // Parts of the file binned on the cores at once, where no photon's
    // pixel depends on an earlier record (every map but a scanned image's),
    // each part at least `PART_RECORDS` long and its stack within the
    // memory budget; the counts are sums, equal to one pass's.
    let parts = if binner.order_free() {
        rayon::current_num_threads()
            .min(usize::try_from(records / PART_RECORDS).unwrap_or(usize::MAX))
            .min(binner.max_stacks())
            .max(1)
    } else {
        1
    };
    let (binner, truncated, flags) = if parts > 1 {
        let done: Vec<_> = (0..parts)
            .into_par_iter()
            .map(|i| file.bin_part(path, i, parts, binner.clone(), spec.allow_truncated))
            .collect();
        let mut merged = binner;
        let mut truncated = None;
        let mut flags = CardFlags::default();
        for part in done {
            let (b, t, f) = part?;
            merged.absorb(b);
            truncated = truncated.or(t);
            flags += f;
        }
        (merged, truncated, flags)
    } else {
        file.bin_part(path, 0, 1, binner, spec.allow_truncated)?
    };
    let seconds = start.elapsed().as_secs_f64();
    let past = binner.past_window();
    let (stacks, tally) = binner.finish();
    Ok(Pass {
        records_per_s: tally.records as f64 / seconds.max(1e-9),
        stacks,
        counts: tally,
        past,
        window,
        truncated,
        flags,
    })
}

/// Reads, decodes and bins `reader`'s records with `binner`; the text of
/// a truncation when `allow_truncated` lets the records end early.
fn bin_records(
    path: &Path,
    info: &FileInfo,
    mut reader: RecordReader,
    mut binner: Binner,
    allow_truncated: bool,
) -> Result<(Binner, Option<String>), RecordedFileError> {
    let mut decoder = Decoder::new(info.record_type);
    let mut chunk = Vec::new();
    loop {
        match reader.next_chunk(&mut chunk) {
            Ok(true) => binner.bin_chunk(&mut decoder, &chunk),
            Ok(false) => return Ok((binner, None)),
            Err(e @ TtrError::Truncated { .. }) if allow_truncated => {
                return Ok((binner, Some(e.to_string())));
            }
            Err(error) => {
                return Err(FileError {
                    path: path.to_owned(),
                    error,
                }
                .into());
            }
        }
    }
}

/// A tag file: the device's whole sensor, micro time from the sync.
fn bin_tag_file(path: &Path, spec: &BinSpec) -> Result<BinnedFile<CountStack>, RecordedFileError> {
    let spec_err = |reason| spec_error(path, reason);
    if !matches!(spec.pixels, Pixels::Auto) || spec.frames != FrameSelect::Sum {
        return Err(spec_err(
            "a tag file is binned onto its sensor with every frame summed; pixel and frame mappings do not apply".into(),
        ));
    }
    let raw = TagFile::open(path)?;
    let header = raw.header.clone();
    let res_ps = f64::from(header.resolution_fs) / 1000.0;
    let width_ps = spec.bin_width_ps.unwrap_or(res_ps);
    let bins = spec.bins.unwrap_or_else(|| {
        TimeWindow::period_bins(
            header.sync_period_fs as f64 / 1000.0,
            spec.t_start_ps,
            width_ps,
        )
        .min(MAX_BINS)
    });
    let (w, h) = (usize::from(header.pixels_x), usize::from(header.pixels_y));
    if w == 0 || h == 0 {
        return Err(spec_err(format!("header sensor size {w} x {h} is empty")));
    }
    let window = TimeWindow::from_ps(spec.t_start_ps, width_ps, bins, res_ps)
        .and_then(|win| win.whole_steps(res_ps))
        .map_err(|e| spec_err(e.to_string()))?;
    let map = PixelMap::Sensor {
        sensor_width: w,
        region: Region {
            x: 0,
            y: 0,
            width: w,
            height: h,
        },
    };
    window
        .check_stack(&map)
        .map_err(|e| spec_err(e.to_string()))?;
    check_stack_memory(path, &window, &map)?;
    let mut binner = Binner::new(window, map, spec.channel, FrameSelect::Sum);
    let start = Instant::now();
    let summary = raw.read(|batch| bin_batch(batch, &mut binner))?;
    let seconds = start.elapsed().as_secs_f64();
    let (mut stacks, tally) = binner.finish();
    let counts_binned = stacks.swap_remove(0);
    let source = format!("{} ({} {})", path.display(), header.model, header.serial);
    let record = TagFileRecord {
        tag_file_header: header,
        totals_in_file: summary.totals.is_some(),
    };
    let shape = counts_binned.dim();
    // The device's sync is the laser's pulse train.
    let laser_hz = 1e15 / record.tag_file_header.sync_period_fs as f64;
    let mut meta = StackMeta::measured(
        window.start_ps(res_ps),
        window.width_ps(res_ps),
        window.bins,
        source,
        Some(serde_json::to_value(&record).expect("the record serialises")),
    );
    meta.laser_frequency_hz = Some(laser_hz).filter(|r| r.is_finite() && *r > 0.0);
    let stack = CountStack {
        counts: counts_binned,
        meta,
    };
    let truncated = summary
        .totals
        .is_none()
        .then(|| "no end frame: the recording was cut (crash or disconnect)".to_string());
    Ok(BinnedFile {
        recording: Recording::TagFile { summary },
        stacks: vec![stack],
        shape,
        counts: tally,
        window,
        resolution_ps: res_ps,
        records_per_s: tally.records as f64 / seconds.max(1e-9),
        notes: Vec::new(),
        truncated,
        time_unstated: false,
    })
}

/// What a stack binned from a tag file records about its source.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TagFileRecord {
    /// The file's header.
    pub tag_file_header: crate::formats::sstags::TagFileHeader,
    /// Whether the file ends with the device's totals (else it was cut).
    pub totals_in_file: bool,
}

/// A Becker & Hickl histogram file: each decay block becomes a stack in
/// its own size and time unit, its curve points summed into the window's
/// bins (whole points only), and is handed to `each` before the next block
/// is read (one block in memory, its memory reused for the next); blocks
/// that are not decay curves are left out, by name. A block whose
/// measurement states no time unit is binned by curve point, marked so.
fn bin_sdt<S>(
    path: &Path,
    spec: &BinSpec,
    each: &mut dyn FnMut(StackCounts<'_>) -> Result<S, RecordedFileError>,
) -> Result<BinnedFile<S>, RecordedFileError> {
    let spec_err = |reason: &str| spec_error(path, reason.to_string());
    if spec.channel.is_some() {
        return Err(spec_err(
            "an .sdt file holds histograms, one data block per routing channel, and no photon's channel: --channel does not apply (each block becomes a stack)",
        ));
    }
    if spec.frames != FrameSelect::Sum {
        return Err(spec_err(
            "an .sdt file's decay blocks each become a stack (stack_f000, ...); --frames applies to scanned PicoQuant files",
        ));
    }
    if spec.pixels == Pixels::Channel {
        return Err(spec_err(
            "an .sdt file's curves are placed as its measurement description says (an image or a row of curves); --pixels channel does not apply (auto or single)",
        ));
    }
    let start = Instant::now();
    let mut reader = sdt::open(path)?;
    let mut tally = Counts::default();
    let mut stacks = Vec::new();
    // The first block's window and unit stand for the file's; every
    // block's shape and bins, to say when they differ.
    struct First {
        window: TimeWindow,
        unit_ps: f64,
        time_unstated: bool,
        shape: (usize, usize, usize),
    }
    let mut first: Option<First> = None;
    let mut shapes = Vec::new();
    let mut unstated = Vec::new();
    let mut spare = None;
    let mut misfits = Vec::new();
    while let Some(b) = reader.next_block(spare.take())? {
        // A window that is no whole number of this block's points leaves
        // the block out, by name (a file of two TAC settings may fit one).
        let (window, unit_ps) = match sdt_window(path, spec, &b)? {
            Ok(w) => w,
            Err(reason) => {
                misfits.push(reason);
                spare = Some(b.counts);
                continue;
            }
        };
        if let Err(why) = &b.micro_unit_s {
            unstated.push(format!("data block {}: {why}", b.index));
        }
        let (binned, meta) = sdt_stack(path, spec, &b, window, unit_ps, &mut tally)?;
        let counts = match (&binned, &b.counts) {
            (Some(c), _) => CountsView::U32(c.view()),
            (None, BlockCounts::U16(c)) => CountsView::U16(c.view()),
            (None, BlockCounts::U32(c)) => CountsView::U32(c.view()),
        };
        first.get_or_insert(First {
            window,
            unit_ps,
            time_unstated: b.micro_unit_s.is_err(),
            shape: counts.dim(),
        });
        shapes.push(format!(
            "{} x {} x {} of {} {} bins",
            counts.dim().0,
            counts.dim().1,
            counts.dim().2,
            meta.bin_width_ps,
            if b.micro_unit_s.is_ok() {
                "ps"
            } else {
                "point"
            }
        ));
        stacks.push(each(StackCounts {
            counts,
            meta: &meta,
            index: stacks.len(),
            of: reader.decay_blocks,
        })?);
        spare = Some(b.counts);
    }
    let left_out = std::mem::take(&mut reader.left_out);
    let Some(First {
        window,
        unit_ps,
        time_unstated,
        shape,
    }) = first
    else {
        let why: Vec<_> = left_out.iter().chain(&misfits).cloned().collect();
        return Err(spec_err(&format!(
            "no block of decay curves to bin ({})",
            if why.is_empty() {
                "the file holds no data blocks".to_string()
            } else {
                why.join("; ")
            }
        )));
    };
    let seconds = start.elapsed().as_secs_f64();
    let mut notes: Vec<String> = left_out.iter().map(|l| format!("left out: {l}")).collect();
    if spec.pixels == Pixels::Single {
        notes.push("every curve of a block summed into one pixel (--pixels single)".into());
    }
    if shapes.iter().any(|s| *s != shapes[0]) {
        notes.push(format!(
            "the blocks differ in size or time unit, each its own stack: {}",
            shapes.join(", ")
        ));
    }
    Ok(BinnedFile {
        recording: Recording::BeckerHicklHistogram {
            id: format!("{}, module {}", reader.id, reader.module),
            left_out,
            unstated,
            misfits,
        },
        stacks,
        shape,
        counts: tally,
        window,
        resolution_ps: unit_ps,
        records_per_s: tally.records as f64 / seconds.max(1e-9),
        notes,
        truncated: None,
        time_unstated,
    })
}

/// The window `spec` asks of block `b`, in whole curve points of its own
/// time unit, and that unit (ps; 1 when the block states none, whose
/// window must then be the default); `Ok(Err(why))` when the window does
/// not fit this block (its points or its unknown unit), which is then
/// left out.
fn sdt_window(
    path: &Path,
    spec: &BinSpec,
    b: &sdt::SdtBlock,
) -> Result<Result<(TimeWindow, f64), String>, RecordedFileError> {
    let points = b.counts.dim().0;
    let unit_ps = match &b.micro_unit_s {
        Ok(s) => s * 1e12,
        Err(why) if spec.bin_width_ps.is_some() || spec.t_start_ps != 0.0 => {
            return Ok(Err(format!(
                "data block {}: --bin-width and --t-start are times, and its time unit is unknown ({why}): bin it by curve point without them",
                b.index
            )));
        }
        Err(_) => 1.0,
    };
    let whole = |ps: f64, what: &str| -> Result<usize, String> {
        let n = (ps / unit_ps).round();
        if (n * unit_ps - ps).abs() > 1e-6 * unit_ps.max(ps.abs()) || n < 0.0 {
            return Err(format!(
                "data block {}: {what} {ps} ps is not a whole number of its curve points ({unit_ps:.6} ps each): histograms are binned in whole points",
                b.index
            ));
        }
        Ok(n as usize)
    };
    let width = match spec
        .bin_width_ps
        .map(|w| whole(w, "the bin width"))
        .transpose()
    {
        Ok(width) => width.unwrap_or(1).max(1),
        Err(why) => return Ok(Err(why)),
    };
    let offset = match whole(spec.t_start_ps, "the window start") {
        Ok(offset) => offset,
        Err(why) => return Ok(Err(why)),
    };
    let bins = spec
        .bins
        .unwrap_or_else(|| points.saturating_sub(offset).div_ceil(width).max(1));
    if bins == 0 || bins > MAX_BINS {
        return Err(spec_error(
            path,
            format!("{bins} bins: give 1 to {MAX_BINS}"),
        ));
    }
    Ok(Ok((
        TimeWindow {
            start: offset as f64,
            width: width as f64,
            bins,
        },
        unit_ps,
    )))
}

/// Block `b`'s curve points summed into `window`'s bins (whole points) of
/// `unit_ps` points, counted into `tally`: `None` when the window is the
/// block itself (its counts are the stack's), and the stack's metadata.
fn sdt_stack(
    path: &Path,
    spec: &BinSpec,
    b: &sdt::SdtBlock,
    window: TimeWindow,
    unit_ps: f64,
    tally: &mut Counts,
) -> Result<(Option<Array3<u32>>, StackMeta), RecordedFileError> {
    let (points, h, w) = b.counts.dim();
    let (offset, width, bins) = (window.start as usize, window.width as usize, window.bins);
    let mut meta = StackMeta::measured(
        window.start_ps(unit_ps),
        window.width_ps(unit_ps),
        bins,
        sdt_source(path, b),
        None,
    );
    if b.micro_unit_s.is_err() {
        meta.unstated.push(Unstated::TimeUnit);
    }
    meta.laser_frequency_hz = b.sync_rate_hz;
    if offset == 0 && width == 1 && bins == points && spec.pixels != Pixels::Single {
        let sum = b.counts.total();
        tally.records += (points * h * w) as u64;
        tally.photons += sum;
        tally.binned += sum;
        return Ok((None, meta));
    }
    let (h, w) = if spec.pixels == Pixels::Single {
        (1, 1)
    } else {
        (h, w)
    };
    check_stack_memory(path, &window, &PixelMap::Channel { width: h * w })?;
    let mut counts = Array3::<u32>::zeros((bins, h, w));
    match &b.counts {
        BlockCounts::U16(c) => rebin(c, &mut counts, (offset, width), spec.pixels, tally),
        BlockCounts::U32(c) => rebin(c, &mut counts, (offset, width), spec.pixels, tally),
    }
    Ok((Some(counts), meta))
}

/// Sums the points of `block` from `offset` in groups of `width` into
/// `counts`' bins (every curve into one pixel for [`Pixels::Single`]),
/// counting where each point's photons went.
fn rebin<T: Copy + Into<u32>>(
    block: &Array3<T>,
    counts: &mut Array3<u32>,
    (offset, width): (usize, usize),
    pixels: Pixels,
    tally: &mut Counts,
) {
    let bins = counts.dim().0;
    for (point, plane) in block.outer_iter().enumerate() {
        let sum: u64 = plane.iter().map(|&c| u64::from(c.into())).sum();
        tally.records += plane.len() as u64;
        tally.photons += sum;
        let bin = point
            .checked_sub(offset)
            .map(|p| p / width)
            .filter(|&j| j < bins);
        let Some(bin) = bin else {
            tally.outside_window += sum;
            continue;
        };
        tally.binned += sum;
        let mut target = counts.index_axis_mut(ndarray::Axis(0), bin);
        if pixels == Pixels::Single {
            // Counts of a bin past u32 saturate; an .sdt point holds
            // at most 2^32 - 1 and a stack bin sums `width` planes.
            target[[0, 0]] = target[[0, 0]].saturating_add(u32::try_from(sum).unwrap_or(u32::MAX));
        } else {
            target.zip_mut_with(&plane, |t, &c| *t = t.saturating_add(c.into()));
        }
    }
}

/// Where a stack binned from an `.sdt` block came from, in words.
fn sdt_source(path: &Path, b: &sdt::SdtBlock) -> String {
    format!(
        "{} (Becker & Hickl {} block {}, module {})",
        path.display(),
        b.contents,
        b.index,
        b.module
    )
}
