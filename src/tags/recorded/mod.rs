//! Every recorded file the project reads, one format per file behind one
//! interface: a [`RecordedSource`] bins a file into stacks and hands each
//! on as soon as it is binned (a format binned whole in memory is one by
//! implementing [`BinsInMemory`]), surveys it for `info` and converts it
//! to PTU ([`RecordedFormat`]). [`source_of`] is the one table from a
//! detected [`Format`] to its source, so a new format is a new file here,
//! its line in [`Format::of_file`] and its line below.
//!
//! - [`picoquant`]: PicoQuant T3 files (PTU, PT3, HT3).
//! - [`spc`]: Becker & Hickl FIFO files (`.spc`).
//! - `t3`: the passes over T3 records those two share (window, margin,
//!   widening, parts on the cores).
//! - [`sdt`]: Becker & Hickl histogram files (`.sdt`), block by block.
//! - [`tag_file`]: the project's tag files (`.sstags`).

use std::path::Path;
use std::sync::atomic::AtomicBool;

use crate::formats::becker_hickl::spc::SpcOptions;
use crate::formats::detect::Format;
use crate::stack::CountsView;
use crate::tags::binned::{BinSpec, BinnedFile, CountStack, RecordedFileError, StackCounts};
use crate::tags::convert::{Conversion, ConvertError, check_output};
use crate::tags::survey::Survey;

pub mod picoquant;
pub mod sdt;
pub mod spc;
mod t3;
pub mod tag_file;

/// A recorded-file format, binned into stacks.
pub trait RecordedSource: Sync {
    /// Bins the file at `path` as `spec` asks, handing each stack to
    /// `each` in order as soon as it is binned; the result's stacks are
    /// `()`, one per stack handed.
    fn bin(
        &self,
        path: &Path,
        spec: &BinSpec,
        each: &mut dyn FnMut(Handed<'_>) -> Result<(), RecordedFileError>,
    ) -> Result<BinnedFile<()>, RecordedFileError>;
}

/// What else the commands that read recorded files ask of a format:
/// `info`'s survey and `convert`'s PTU.
pub trait RecordedFormat: RecordedSource {
    /// Surveys the file at `path` (a `.spc` read as `spc` says): its
    /// header and its records counted by kind.
    fn survey(&self, path: &Path, spc: &SpcOptions) -> Result<Survey, RecordedFileError>;

    /// Converts the file at `input` into the PTU file `output`, photon for
    /// photon, written whole or not at all; with `allow_truncated` a cut
    /// file's complete records; `stop` (Ctrl-C) ends it with nothing
    /// written.
    fn convert_to_ptu(
        &self,
        input: &Path,
        output: &Path,
        allow_truncated: bool,
        spc: &SpcOptions,
        stop: &AtomicBool,
    ) -> Result<Conversion, ConvertError>;
}

/// The source of a file of `format` (anything not recognised otherwise is
/// read as PicoQuant, whose reader names what it found).
pub fn source_of(format: Format) -> &'static dyn RecordedFormat {
    match format {
        Format::TagFile => &tag_file::TagFiles,
        Format::BeckerHicklFifo => &spc::SpcFiles,
        Format::BeckerHicklHistogram => &sdt::SdtFiles,
        _ => &picoquant::PicoQuantFiles,
    }
}

/// Surveys a recorded file through its format's source ([`source_of`]):
/// a tag file (recognised by its magic), a Becker & Hickl file (`.spc`
/// read as `spc` says, `.sdt`) or a PicoQuant file.
pub fn survey(path: &Path, spc: &SpcOptions) -> Result<Survey, RecordedFileError> {
    let format = Format::of_file(path);
    spc.check_applies(path, format)?;
    source_of(format).survey(path, spc)
}

/// Converts `input` (a PicoQuant file, a tag file or a Becker & Hickl
/// `.spc` file read as `spc` says) into the PTU file `output` through its
/// format's source ([`source_of`]), written whole or not at all; with
/// `allow_truncated`, a cut file's complete records (or those of a file
/// whose writer never finished) are converted, and the conversion says so,
/// instead of failing. `stop` (Ctrl-C) ends it with nothing written. The
/// output is never the input, however it is spelled ([`crate::files`]).
pub fn convert_to_ptu(
    input: &Path,
    output: &Path,
    allow_truncated: bool,
    spc: &SpcOptions,
    stop: &AtomicBool,
) -> Result<Conversion, ConvertError> {
    check_output(input, output)?;
    let format = Format::of_file(input);
    spc.check_applies(input, format)?;
    source_of(format).convert_to_ptu(input, output, allow_truncated, spc, stop)
}

/// A binned stack handed on by a source.
#[derive(Debug)]
pub enum Handed<'a> {
    /// Counts read in place, in the width the file holds them (a
    /// histogram block, whose memory the next block reuses).
    Lent(StackCounts<'a>),
    /// Counts binned in memory, given away.
    Given {
        /// The counts and their metadata (boxed: the metadata is large
        /// beside a lent view).
        stack: Box<CountStack>,
        /// Its place among the file's stacks (from 0).
        index: usize,
        /// How many stacks the file gives.
        of: usize,
    },
}

impl Handed<'_> {
    /// The stack, borrowed.
    pub fn view(&self) -> StackCounts<'_> {
        match self {
            // Views are invariant in their lifetime: reborrowed to `&self`'s.
            Handed::Lent(s) => StackCounts {
                counts: match &s.counts {
                    CountsView::U16(c) => CountsView::U16(c.view()),
                    CountsView::U32(c) => CountsView::U32(c.view()),
                },
                ..*s
            },
            Handed::Given { stack, index, of } => StackCounts {
                counts: CountsView::U32(stack.counts.view()),
                meta: &stack.meta,
                index: *index,
                of: *of,
            },
        }
    }

    /// The stack, owned (copied only when lent).
    pub fn into_owned(self) -> CountStack {
        match self {
            Handed::Lent(s) => s.to_owned(),
            Handed::Given { stack, .. } => *stack,
        }
    }
}

/// A format binned whole in memory, its stacks then given away in order:
/// a [`RecordedSource`] by that alone.
pub trait BinsInMemory: Sync {
    /// Bins the file at `path` as `spec` asks.
    fn bin_in_memory(
        &self,
        path: &Path,
        spec: &BinSpec,
    ) -> Result<BinnedFile<CountStack>, RecordedFileError>;
}

impl<T: BinsInMemory> RecordedSource for T {
    fn bin(
        &self,
        path: &Path,
        spec: &BinSpec,
        each: &mut dyn FnMut(Handed<'_>) -> Result<(), RecordedFileError>,
    ) -> Result<BinnedFile<()>, RecordedFileError> {
        hand_each(self.bin_in_memory(path, spec)?, each)
    }
}

/// Hands every stack of a file binned in memory to `each`, in order.
fn hand_each(
    binned: BinnedFile<CountStack>,
    each: &mut dyn FnMut(Handed<'_>) -> Result<(), RecordedFileError>,
) -> Result<BinnedFile<()>, RecordedFileError> {
    let of = binned.stacks.len();
    let mut index = 0;
    binned.try_map_stacks(|stack| {
        index += 1;
        each(Handed::Given {
            stack: Box::new(stack),
            index: index - 1,
            of,
        })
    })
}
