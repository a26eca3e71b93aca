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

use super::binned::spec_error;
pub use super::binned::{
    BinSpec, BinnedFile, CountStack, Pixels, RecordedFileError, Recording, StackCounts,
    window_and_map,
};
use super::recorded::{self, Handed};
use crate::formats::detect::Format;
use crate::formats::png::{SheetScale, write_counts_sheet};
use crate::stack::StackError;

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
