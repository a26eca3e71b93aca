//! Recorded tags -> PTU, photon for photon: PicoQuant files of any
//! supported type (PTU, PT3, HT3; T2 and T3) keep their record type, and
//! the project's own tag files (`.sstags`) become Generic T3 records with
//! the sensor pixel as the input channel (a T3 record has room for 63
//! channels, so larger sensors are refused with a message). Every photon,
//! marker and sync keeps its channel, macro time and micro time; overflow
//! records are re-made by the writer.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use firmware_protocol::Event;

use crate::events::Tag;
use crate::files::Completion;
use crate::formats::becker_hickl::spc::{self, SpcFileError, SpcOptions};
use crate::formats::picoquant::records::{Decoder, RecordType};
use crate::formats::picoquant::writer::{HeaderEntry, PtuWriter, WriterHeader};
use crate::formats::picoquant::{FileError, TtrError, open};
use crate::formats::sstags::{TagFile, TagFileError};

/// The header tag that says where a converted file came from.
pub const PROVENANCE_TAG: &str = "Scatterscope_ConvertedFrom";

/// Channels a Generic T3 record can name (63 marks an overflow).
pub const MAX_T3_CHANNELS: usize = 63;

/// What a conversion did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Conversion {
    /// Records read.
    pub records_in: u64,
    /// Photons carried over.
    pub photons: u64,
    /// Markers carried over.
    pub markers: u64,
    /// Sync events carried over (T2).
    pub syncs: u64,
    /// Records written (overflows re-made).
    pub records_out: u64,
    /// Photons the recording device reported lost (a tag file's FIFO
    /// overflows): absent from the source, so from the PTU too.
    pub lost_in_device: u64,
    /// The record type written.
    pub record_type: String,
    /// Why the input ended early, when a cut file's complete records were
    /// converted.
    pub truncated: Option<String>,
    /// What makes the input, and so the output, less than a whole
    /// recording (records past the announced count left out, a recording
    /// that was interrupted or never finished), in words. The output's
    /// header carries the incomplete mark when any applies.
    pub warnings: Vec<String>,
}

/// Why a conversion failed.
#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    /// The PicoQuant input cannot be read.
    #[error(transparent)]
    Input(#[from] FileError),
    /// The tag file cannot be read.
    #[error(transparent)]
    TagFile(#[from] TagFileError),
    /// The Becker & Hickl FIFO file cannot be read.
    #[error(transparent)]
    Spc(#[from] SpcFileError),
    /// The input holds what PTU cannot, or is out of order.
    #[error("{path}: {reason}")]
    Unsupported {
        /// The input.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// Ctrl-C or SIGTERM: the partial output was removed.
    #[error("{path}: the conversion was interrupted; nothing was written")]
    Interrupted {
        /// The output that was not written.
        path: PathBuf,
    },
    /// The output cannot be written.
    #[error("{path}: {source}")]
    Output {
        /// The output.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

fn out_err(path: &Path) -> impl Fn(std::io::Error) -> ConvertError + '_ {
    move |source| ConvertError::Output {
        path: path.to_owned(),
        source,
    }
}

/// Refuses a conversion that would write over its own input (however
/// it is spelled: [`crate::files`]).
pub fn check_output(input: &Path, output: &Path) -> Result<(), ConvertError> {
    if crate::files::input::same_file(input, output) {
        return Err(ConvertError::Unsupported {
            path: input.to_owned(),
            reason: format!(
                "the output {} is this same file (another spelling or a link): converting would destroy the recording",
                output.display()
            ),
        });
    }
    Ok(())
}

/// A Becker & Hickl FIFO file as Generic T3: the routing channel is the
/// input channel and the macro-time clock the sync; GAP flags (photons
/// lost in the card) make the output incomplete, said in its warnings.
pub fn from_spc(
    input: &Path,
    output: &Path,
    allow_truncated: bool,
    options: &SpcOptions,
    stop: &AtomicBool,
) -> Result<Conversion, ConvertError> {
    let info = spc::open(input, options)?;
    info.check_whole(allow_truncated)?;
    let header = WriterHeader {
        resolution_s: info.micro_unit()?,
        sync_rate_hz: 1.0 / info.macro_clock_s,
        device: format!("Becker & Hickl {}", info.module.cards()),
        imaging: None,
        extra: vec![(
            PROVENANCE_TAG.into(),
            HeaderEntry::Text(format!(
                "converted from {}: input channel = routing channel, sync = the {:.3} ns macro-time clock, micro-time unit {}",
                input.display(),
                info.macro_clock_s * 1e9,
                info.micro_unit_from
            )),
        )],
    };
    let record_type = RecordType::GenericT3;
    // One pass over the records first (fast, nothing written): an input
    // of overflow counts can span more time than any disk holds overflow
    // records for, and is refused before the output grows.
    let mut last = 0u64;
    spc::decode_each(&info, info.records_part(0, 1)?, |tag| {
        if let Some(t) = tag {
            last = last.max(t.macro_time());
        }
        Ok::<(), ConvertError>(())
    })?;
    let needed = info
        .records_present
        .saturating_add(PtuWriter::overflow_records_for(record_type, last));
    let room = disk_records(output);
    if needed > room {
        return Err(ConvertError::Unsupported {
            path: input.to_owned(),
            reason: format!(
                "its records span {:.3e} s of macro time (the last event at clock {last}), which a PTU holds as {needed} records ({} bytes) of overflows and events; the output's disk has room for {room}: refused before writing",
                last as f64 * info.macro_clock_s,
                needed.saturating_mul(4)
            ),
        });
    }
    let mut w = PtuWriter::create(output, record_type, &header).map_err(out_err(output))?;
    w.limit_records(room);
    let mut c = Conversion {
        record_type: record_type.name().into(),
        ..Conversion::default()
    };
    if info.module_assumed {
        c.warnings.push(format!(
            "records read as {}: a .spc file does not record its module (an SPC-600/630 file needs --spc-module)",
            info.module.cards()
        ));
    }
    let reader = info.records_part(0, 1)?;
    let flags = spc::decode_each(&info, reader, |tag| {
        // Every record: one overflow count can stand for a million
        // output records.
        if stop.load(Ordering::Relaxed) {
            return Err(ConvertError::Interrupted {
                path: output.to_owned(),
            });
        }
        c.records_in += 1;
        if let Some(tag) = tag {
            count(&mut c, &tag);
            w.write_tag_until(tag, stop)
                .map_err(|e| write_error(input, output, format!("record {}", c.records_in), e))?;
        }
        Ok(())
    })?;
    if flags.gaps > 0 {
        c.warnings.push(format!(
            "{} record(s) carry the GAP flag: the card's FIFO was full and photons before each were lost in the card",
            flags.gaps
        ));
    }
    if info.trailing_bytes > 0 {
        c.truncated = Some(info.cut().to_string());
        c.warnings.push(format!("the input is cut: {}", info.cut()));
    }
    close(c, w, output, |w| !w.starts_with("records read as"))
}

/// Closes the PTU `w`: marked interrupted when a warning `against` the
/// input was said, else complete.
fn close(
    mut c: Conversion,
    w: PtuWriter,
    output: &Path,
    against: fn(&str) -> bool,
) -> Result<Conversion, ConvertError> {
    let completion = if c.warnings.iter().any(|w| against(w)) {
        Completion::Interrupted
    } else {
        Completion::Complete
    };
    c.records_out = w.finish_as(completion).map_err(out_err(output))?;
    Ok(c)
}

/// Records (4 bytes each) the disk of `output` has room for; no limit
/// where the system does not say.
fn disk_records(output: &Path) -> u64 {
    crate::files::free_bytes(output).map_or(u64::MAX, |b| b / 4)
}

/// A writer's error on a tag from the input: the input's fault when the
/// tag cannot be written (`InvalidInput`: out of order, out of range;
/// `StorageFull`: a time jump whose overflow records the disk cannot
/// hold), else the output's.
fn write_error(input: &Path, output: &Path, at: String, e: std::io::Error) -> ConvertError {
    match e.kind() {
        std::io::ErrorKind::Interrupted => ConvertError::Interrupted {
            path: output.to_owned(),
        },
        std::io::ErrorKind::InvalidInput | std::io::ErrorKind::StorageFull => {
            ConvertError::Unsupported {
                path: input.to_owned(),
                reason: format!("{at}: {e}"),
            }
        }
        _ => out_err(output)(e),
    }
}

fn count(c: &mut Conversion, tag: &Tag) {
    match tag {
        Tag::Photon { .. } => c.photons += 1,
        Tag::Marker { .. } => c.markers += 1,
        Tag::Sync { .. } => c.syncs += 1,
    }
}

/// A PicoQuant file (PTU, PT3, HT3; T2 or T3) as a PTU of its own record
/// type, photon for photon (see the module's doc).
pub fn from_picoquant(
    input: &Path,
    output: &Path,
    allow_truncated: bool,
    stop: &AtomicBool,
) -> Result<Conversion, ConvertError> {
    let (info, mut reader) = open(input)?;
    info.check_finished(allow_truncated)?;
    let header = WriterHeader {
        resolution_s: info.resolution_s,
        sync_rate_hz: if info.record_type.is_t3() {
            1.0 / info.macro_unit_s
        } else {
            info.sync_rate_hz.unwrap_or(0.0)
        },
        device: info.device.clone(),
        imaging: info.imaging,
        extra: vec![(
            PROVENANCE_TAG.into(),
            HeaderEntry::Text(format!("converted from {}", input.display())),
        )],
    };
    // A PTU input's header is kept tag for tag, at full precision (an
    // earlier conversion's provenance gives way to this one's).
    let copied: Vec<_> = info
        .tags
        .iter()
        .filter(|t| t.ident != PROVENANCE_TAG)
        .cloned()
        .collect();
    let mut w = PtuWriter::create_copying(output, info.record_type, &header, &copied)
        .map_err(out_err(output))?;
    let mut decoder = Decoder::new(info.record_type);
    let mut c = Conversion {
        record_type: info.record_type.name().into(),
        warnings: info
            .unread_note()
            .into_iter()
            .chain(info.completeness_note())
            .collect(),
        ..Conversion::default()
    };
    let mut chunk = Vec::new();
    loop {
        if stop.load(Ordering::Relaxed) {
            return Err(ConvertError::Interrupted {
                path: output.to_owned(),
            });
        }
        match reader.next_chunk(&mut chunk) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e @ TtrError::Truncated { .. }) if allow_truncated => {
                c.truncated = Some(e.to_string());
                break;
            }
            Err(error) => {
                return Err(FileError {
                    path: input.to_owned(),
                    error,
                }
                .into());
            }
        }
        for &rec in &chunk {
            c.records_in += 1;
            if let Some(tag) = decoder.decode(rec) {
                count(&mut c, &tag);
                w.write_tag_until(tag, stop).map_err(|e| {
                    write_error(
                        input,
                        output,
                        format!("record {} (0x{rec:08X})", c.records_in - 1),
                        e,
                    )
                })?;
            }
        }
    }
    if let Some(t) = &c.truncated {
        c.warnings.push(format!("the input is cut: {t}"));
    }
    close(c, w, output, |_| true)
}

/// A tag file (`.sstags`) as Generic T3, the sensor pixel the input
/// channel (see the module's doc).
pub fn from_tag_file(
    input: &Path,
    output: &Path,
    stop: &AtomicBool,
) -> Result<Conversion, ConvertError> {
    let file = TagFile::open(input)?;
    let h = file.header.clone();
    let pixels = usize::from(h.pixels_x) * usize::from(h.pixels_y);
    let unsupported = |reason: String| ConvertError::Unsupported {
        path: input.to_owned(),
        reason,
    };
    if pixels > MAX_T3_CHANNELS {
        return Err(unsupported(format!(
            "its sensor has {} x {} = {pixels} pixels; a PTU T3 record names at most {MAX_T3_CHANNELS} input channels, so the pixel of each photon cannot be kept (bin the file with `bin`, or record a sensor of at most {MAX_T3_CHANNELS} pixels)",
            h.pixels_x, h.pixels_y
        )));
    }
    let header = WriterHeader {
        resolution_s: f64::from(h.resolution_fs) * 1e-15,
        sync_rate_hz: 1e15 / h.sync_period_fs as f64,
        device: format!("{} {}", h.model, h.serial),
        imaging: None,
        extra: vec![
            (
                PROVENANCE_TAG.into(),
                HeaderEntry::Text(format!(
                    "converted from {}: input channel = sensor pixel (row-major, {} x {})",
                    input.display(),
                    h.pixels_x,
                    h.pixels_y
                )),
            ),
            (
                "HWSync_Divider".into(),
                HeaderEntry::Int(i64::from(h.sync_divider)),
            ),
        ],
    };
    let record_type = RecordType::GenericT3;
    let mut w = PtuWriter::create(output, record_type, &header).map_err(out_err(output))?;
    w.limit_records(disk_records(output));
    let mut c = Conversion {
        record_type: record_type.name().into(),
        ..Conversion::default()
    };
    let mut failure: Option<ConvertError> = None;
    let summary = file.read(|batch| {
        if failure.is_some() {
            return;
        }
        if stop.load(Ordering::Relaxed) {
            failure = Some(ConvertError::Interrupted {
                path: output.to_owned(),
            });
            return;
        }
        for event in batch.events() {
            c.records_in += 1;
            let event = match event {
                Ok(event) => event,
                Err(e) => {
                    failure = Some(unsupported(format!(
                        "record {:#018x} of batch {} does not decode",
                        e.raw, batch.header.seq
                    )));
                    return;
                }
            };
            let tag = match Tag::from_wire(event) {
                Some(Tag::Photon { micro_time, .. }) if micro_time > 0x7FFF => {
                    failure = Some(unsupported(format!(
                        "micro time {micro_time} of batch {} exceeds the 15 bits of a T3 record",
                        batch.header.seq
                    )));
                    return;
                }
                Some(tag) => tag,
                None => {
                    if let Event::Lost { count } = event {
                        c.lost_in_device += count;
                    }
                    continue;
                }
            };
            count(&mut c, &tag);
            if let Err(e) = w.write_tag_until(tag, stop) {
                let at = format!(
                    "batch {} (out of order in the recording?)",
                    batch.header.seq
                );
                failure = Some(write_error(input, output, at, e));
                return;
            }
        }
    })?;
    if let Some(f) = failure {
        return Err(f);
    }
    if summary.totals.is_none() {
        c.warnings.push(
            "the recording has no end frame: it was cut (a crash or a disconnect) and may not hold the whole run".into(),
        );
    } else if summary.interrupted {
        c.warnings.push(
            "the run that wrote it was interrupted before its planned end (its end frame says so)"
                .into(),
        );
    }
    close(c, w, output, |_| true)
}

impl Conversion {
    /// One line for the terminal.
    pub fn summary(&self, output: &Path) -> String {
        let mut s = format!(
            "{}: {} records in, {} photons, {} markers, {} syncs -> {} {} records",
            output.display(),
            self.records_in,
            self.photons,
            self.markers,
            self.syncs,
            self.records_out,
            self.record_type
        );
        if let Some(t) = &self.truncated {
            s.push_str(&format!(
                "; the input was cut ({t}): its complete records were converted"
            ));
        }
        if self.lost_in_device > 0 {
            s.push_str(&format!(
                "; {} photons the device reported lost are not in the source either",
                self.lost_in_device
            ));
        }
        for w in &self.warnings {
            s.push_str(&format!("\nwarning: {w}"));
        }
        s
    }
}
