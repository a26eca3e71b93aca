//! A recorded file -> transient stacks, in one call, for the `bin`
//! command, the decay maps, the benchmarks and the tests alike: what to
//! bin ([`BinSpec`]), what came out ([`BinnedFile`]) and where it is
//! written ([`BinOutputs`]). Each format's reading is its own source in
//! [`super::recorded`]; this module does not know them.
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

use ndarray::Array3;

use super::binning::{FrameSelect, MAX_BINS, PixelMap, TimeWindow, WindowError};
use super::counts::Counts;
use super::recorded::{self, Handed};
use crate::formats::becker_hickl::sdt::SdtError;
use crate::formats::becker_hickl::spc::{CardFlags, SpcFileError, SpcInfo, SpcOptions};
use crate::formats::detect::Format;
use crate::formats::picoquant::{FileError, FileInfo};
use crate::formats::png::{SheetScale, write_counts_sheet};
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
    fn with_stacks<B>(self, stacks: Vec<B>) -> BinnedFile<B> {
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
    bin_handed(path, spec, |h| Ok(h.into_owned()))
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
    bin_handed(path, spec, |h| each(h.view()))
}

/// The file's format detected, its source ([`recorded::source_of`]) binning
/// it and handing each stack to `each`, whose results become the stacks.
fn bin_handed<S>(
    path: &Path,
    spec: &BinSpec,
    mut each: impl FnMut(Handed<'_>) -> Result<S, RecordedFileError>,
) -> Result<BinnedFile<S>, RecordedFileError> {
    let format = Format::of_file(path);
    spec.spc.check_applies(path, format)?;
    let mut kept = Vec::new();
    let binned = recorded::source_of(format).bin(path, spec, &mut |h| {
        kept.push(each(h)?);
        Ok(())
    })?;
    Ok(binned.with_stacks(kept))
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
