//! PicoQuant T3 files (PTU, PT3, HT3): records read, decoded and binned
//! in passes ([`super::t3`]); a scanned image's pixel size and the
//! file's sync rate go into every stack.

use std::path::Path;

use super::BinsInMemory;
use super::RecordedFormat;
use super::t3::{self, T3Records};
use crate::formats::becker_hickl::spc::CardFlags;
use crate::formats::becker_hickl::spc::SpcOptions;
use crate::formats::picoquant::ptu::TagLookup;
use crate::formats::picoquant::records::Decoder;
use crate::formats::picoquant::{FileError, FileInfo, RecordReader, TtrError, open};
use crate::tags::binned::{
    BinSpec, BinnedFile, CountStack, Pixels, RecordedFileError, Recording, spec_error,
};
use crate::tags::binning::Binner;
use crate::tags::convert::{Conversion, ConvertError, from_picoquant};
use crate::tags::survey::{Survey, survey_picoquant};
use std::sync::atomic::AtomicBool;

/// PicoQuant's T3 files.
pub struct PicoQuantFiles;

impl BinsInMemory for PicoQuantFiles {
    /// Bins a PicoQuant T3 file in memory.
    fn bin_in_memory(
        &self,
        path: &Path,
        spec: &BinSpec,
    ) -> Result<BinnedFile<CountStack>, RecordedFileError> {
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
        // The laser's rate: the period that times the T3 records (its
        // sync divider times the rate of the sync counter), checked
        // against the rate meter's reading.
        let divider = info
            .tags
            .int("HWSync_Divider")
            .filter(|&d| d > 0)
            .unwrap_or(1);
        let laser = crate::tags::laser::stated(&[
            (
                "T3 sync period (MeasDesc_GlobalResolution, HWSync_Divider)",
                Some(divider as f64 / info.macro_unit_s),
            ),
            ("TTResult_SyncRate", info.sync_rate_hz),
        ]);
        let notes = info
            .unread_note()
            .into_iter()
            .chain(info.pixel_size_left_out())
            .collect();
        let source = format!(
            "{} ({}, {})",
            path.display(),
            info.device,
            info.record_type.name()
        );
        let mut binned = t3::bin(
            path,
            spec,
            info,
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
            s.meta.laser_frequency_hz = laser.hz;
            s.meta.laser_notes.clone_from(&laser.notes);
        }
        Ok(binned)
    }
}

impl RecordedFormat for PicoQuantFiles {
    fn survey(&self, path: &Path, _spc: &SpcOptions) -> Result<Survey, RecordedFileError> {
        let (info, s) = survey_picoquant(path)?;
        Ok(Survey::PicoQuant(Box::new(info), s))
    }

    fn convert_to_ptu(
        &self,
        input: &Path,
        output: &Path,
        allow_truncated: bool,
        _spc: &SpcOptions,
        stop: &AtomicBool,
    ) -> Result<Conversion, ConvertError> {
        from_picoquant(input, output, allow_truncated, stop)
    }
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

impl T3Records for FileInfo {
    fn records(&self) -> u64 {
        self.records_to_read()
    }

    fn bin_part(
        &self,
        path: &Path,
        part: usize,
        parts: usize,
        binner: Binner,
        allow_truncated: bool,
    ) -> Result<(Binner, Option<String>, CardFlags), RecordedFileError> {
        let reader = self.records_part(part, parts)?;
        let (binner, cut) = bin_records(path, self, reader, binner, allow_truncated)?;
        Ok((binner, cut, CardFlags::default()))
    }

    fn into_recording(self, _flags: CardFlags) -> (Recording, bool) {
        (Recording::PicoQuant(self), false)
    }
}
