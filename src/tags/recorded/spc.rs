//! Becker & Hickl FIFO files (`.spc`): records read, decoded and binned
//! in passes ([`super::t3`]); their micro times cover the ADC's channels,
//! by channel when the unit is unknown.

use std::path::Path;

use super::BinsInMemory;
use super::RecordedFormat;
use super::t3::{self, T3Records};
use crate::formats::becker_hickl::spc::SpcOptions;
use crate::formats::becker_hickl::spc::{self, CardFlags, SpcFileError, SpcInfo};
use crate::stack::Unstated;
use crate::tags::binned::{
    BinSpec, BinnedFile, CountStack, RecordedFileError, Recording, spec_error,
};
use crate::tags::binning::Binner;
use crate::tags::convert::{Conversion, ConvertError, from_spc};
use crate::tags::survey::{Survey, survey_spc};
use std::sync::atomic::AtomicBool;

/// Becker & Hickl's FIFO files.
pub struct SpcFiles;

impl BinsInMemory for SpcFiles {
    /// Bins a Becker & Hickl FIFO file in memory.
    fn bin_in_memory(
        &self,
        path: &Path,
        spec: &BinSpec,
    ) -> Result<BinnedFile<CountStack>, RecordedFileError> {
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
        let mut binned = t3::bin(path, spec, info, (res_ps, period_ps), None, source, notes)?;
        if channels {
            for s in &mut binned.stacks {
                s.meta.unstated.push(Unstated::TimeUnit);
            }
        }
        Ok(binned)
    }
}

impl RecordedFormat for SpcFiles {
    fn survey(&self, path: &Path, spc: &SpcOptions) -> Result<Survey, RecordedFileError> {
        let (info, s) = survey_spc(path, spc)?;
        Ok(Survey::BeckerHicklFifo(Box::new(info), s))
    }

    fn convert_to_ptu(
        &self,
        input: &Path,
        output: &Path,
        allow_truncated: bool,
        spc: &SpcOptions,
        stop: &AtomicBool,
    ) -> Result<Conversion, ConvertError> {
        from_spc(input, output, allow_truncated, spc, stop)
    }
}

/// Bins a part of a `.spc` file's records (see [`T3Records::bin_part`]).
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

impl T3Records for SpcInfo {
    fn records(&self) -> u64 {
        self.records_present
    }

    fn bin_part(
        &self,
        _path: &Path,
        part: usize,
        parts: usize,
        binner: Binner,
        _allow_truncated: bool,
    ) -> Result<(Binner, Option<String>, CardFlags), RecordedFileError> {
        bin_spc_records(self, part, parts, binner)
    }

    fn into_recording(self, flags: CardFlags) -> (Recording, bool) {
        let unstated = self.micro_unit_s.is_none();
        (Recording::BeckerHicklFifo { info: self, flags }, unstated)
    }
}
