//! PicoQuant time-tagged files: PTU (any record type), legacy HT3/HT2 and
//! PT3/PT2.
//!
//! [`open`] reads the header into a [`FileInfo`] and returns a
//! [`RecordReader`] that streams the 32-bit records in fixed-size chunks
//! (constant memory for files larger than memory); [`crate::tags::bin_file`]
//! turns a T3 file into transient stacks.

pub mod legacy;
pub mod ptu;
pub mod records;
pub mod writer;

use std::fs::File;
use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use ptu::{HeaderTag, TagLookup};
use records::RecordType;

use crate::events::Imaging;

/// Why a file cannot be read; the file is named by [`FileError`].
#[derive(Debug, thiserror::Error)]
pub enum TtrError {
    /// Operating-system error.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// A header field is missing or wrong.
    #[error("header at byte {offset}: {reason}")]
    Header {
        /// Byte offset of the field.
        offset: u64,
        /// What is wrong, with the value.
        reason: String,
    },
    /// A valid file of a kind this reader does not handle.
    #[error("{0}")]
    Unsupported(String),
    /// The header holds no record count: its writer never finished
    /// (killed, crashed, out of disk), so the file may end anywhere.
    #[error(
        "its header holds no record count (TTResult_NumberOfRecords 0): the writer never finished (killed, crashed or out of disk), so the {present} records present may not be the whole recording; refused unless a truncated file is allowed"
    )]
    Unfinished {
        /// Complete records present.
        present: u64,
    },
    /// The file ends before the records the header announces.
    #[error(
        "file is cut: read {read} of {expected} records ({trailing} trailing bytes of a partial record)"
    )]
    Truncated {
        /// Complete records read.
        read: u64,
        /// Records the header announces.
        expected: u64,
        /// Bytes after the last complete record.
        trailing: u64,
    },
}

impl TtrError {
    pub(crate) fn header(offset: u64, reason: impl Into<String>) -> Self {
        TtrError::Header {
            offset,
            reason: reason.into(),
        }
    }
}

/// A [`TtrError`] with the file it concerns.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {error}")]
pub struct FileError {
    /// The file.
    pub path: PathBuf,
    /// What went wrong.
    pub error: TtrError,
}

/// Container format of a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Container {
    /// Tagged PTU header with its version string.
    Ptu(String),
    /// Legacy HydraHarp HT3/HT2 header with its format version.
    HydraHarpLegacy(String),
    /// Legacy PicoHarp PT3/PT2 header with its format version.
    PicoHarpLegacy(String),
}

/// Everything the header says, in one place.
#[derive(Debug, Clone)]
pub struct FileInfo {
    /// The file.
    pub path: PathBuf,
    /// Container format.
    pub container: Container,
    /// Record type.
    pub record_type: RecordType,
    /// Device name.
    pub device: String,
    /// Unit of micro times (T3) or of time tags (T2), seconds.
    pub resolution_s: f64,
    /// Unit of macro times: the sync period (T3) or the time-tag unit (T2), seconds.
    pub macro_unit_s: f64,
    /// Sync rate (Hz), when recorded.
    pub sync_rate_hz: Option<f64>,
    /// Records the header announces (0 in the header: taken from the size).
    pub records_announced: u64,
    /// The header held no record count (0) though records follow it: the
    /// writer never finished.
    pub count_missing: bool,
    /// Complete records present in the file.
    pub records_present: u64,
    /// Bytes after the last complete record.
    pub trailing_bytes: u64,
    /// Offset of the first record.
    pub data_offset: u64,
    /// `Measurement_SubMode` (3 = image).
    pub sub_mode: i64,
    /// Image scan description, for imaging files.
    pub imaging: Option<Imaging>,
    /// All PTU tags (empty for legacy files).
    pub tags: Vec<HeaderTag>,
}

/// Sides a scanned image's pixel can have (um): a tenth of a nanometre to
/// ten centimetres.
pub const PIXEL_UM: (f64, f64) = (1e-4, 1e5);

impl FileInfo {
    /// The side of a scanned image's pixel (cm), from `ImgHdr_PixResol`
    /// (PicoQuant's PTU tag, in micrometres), when the file is an image
    /// and states a size a scanned pixel can have ([`PIXEL_UM`]).
    pub fn pixel_size_cm(&self) -> Option<f64> {
        self.imaging?;
        let um = self.tags.float("ImgHdr_PixResol")?;
        (PIXEL_UM.0..=PIXEL_UM.1).contains(&um).then_some(um * 1e-4)
    }

    /// Why the image's stated pixel size was left out, when it was.
    pub fn pixel_size_left_out(&self) -> Option<String> {
        self.imaging?;
        let um = self.tags.float("ImgHdr_PixResol")?;
        self.pixel_size_cm().is_none().then(|| {
            format!(
                "ImgHdr_PixResol {um:e} um is no scanned pixel's size ({:e} to {:e} um): left out, the pixel size unstated",
                PIXEL_UM.0, PIXEL_UM.1
            )
        })
    }

    /// The header in words, one line each (what `info` prints first).
    pub fn describe(&self) -> Vec<String> {
        let container = match &self.container {
            Container::Ptu(v) => format!("PTU {v}"),
            Container::HydraHarpLegacy(v) => format!("HydraHarp HT3/HT2 {v}"),
            Container::PicoHarpLegacy(v) => format!("PicoHarp PT3/PT2 {v}"),
        };
        let mut lines = vec![
            format!("file: {}", self.path.display()),
            format!("container: {container}; device: {}", self.device),
            format!(
                "record type: {} (0x{:08X})",
                self.record_type.name(),
                self.record_type.code()
            ),
            format!(
                "resolution: {:.3} ps; macro unit: {:.6e} s{}",
                self.resolution_s * 1e12,
                self.macro_unit_s,
                self.sync_rate_hz
                    .map_or(String::new(), |r| format!("; sync rate {r} Hz"))
            ),
            format!(
                "records: {} announced, {} present{}",
                self.records_announced,
                self.records_present,
                if self.trailing_bytes > 0 {
                    format!(", {} trailing bytes", self.trailing_bytes)
                } else {
                    String::new()
                }
            ),
        ];
        if let Some(d) = self.acquisition_time_s() {
            lines.push(format!("acquisition time set: {d} s"));
        }
        if let Some(d) = self.stopped_after_s() {
            lines.push(format!("stopped after: {d} s"));
        }
        lines.push(format!("measurement sub mode: {}", self.sub_mode));
        if let Some(img) = &self.imaging {
            lines.push(format!(
                "image: {} x {} pixels, line start mask {}, line stop mask {}, frame mask {}, bidirectional {}",
                img.pixels_x, img.pixels_y, img.line_start, img.line_stop, img.frame, img.bidirectional
            ));
        }
        lines
    }

    /// Whole records in the file past the count its header announces
    /// (`TTResult_NumberOfRecords`), which are not read; `None` when the
    /// counts agree or the file is cut.
    pub fn unread_records(&self) -> Option<u64> {
        (self.records_present > self.records_announced)
            .then(|| self.records_present - self.records_announced)
    }

    /// What the header's record count leaves unread, in words.
    pub fn unread_note(&self) -> Option<String> {
        self.unread_records().map(|n| {
            format!(
                "the header announces {} records (TTResult_NumberOfRecords) but the file holds {}: the {n} after them are not read",
                self.records_announced, self.records_present
            )
        })
    }

    /// Whether the writer marked the file incomplete ([`writer::INCOMPLETE_TAG`]).
    pub fn marked_incomplete(&self) -> bool {
        self.tags
            .int(writer::INCOMPLETE_TAG)
            .is_some_and(|v| v != 0)
    }

    /// What the header says of the file's completeness, in words: `None`
    /// for a finished file of a complete run.
    pub fn completeness_note(&self) -> Option<String> {
        if self.count_missing {
            return Some(
                TtrError::Unfinished {
                    present: self.records_present,
                }
                .to_string(),
            );
        }
        self.marked_incomplete().then(|| {
            "the run that wrote it was interrupted before its planned end (its header says so); it holds every record that was read".to_string()
        })
    }

    /// Refuses a file whose writer never finished unless `allow_unfinished`.
    pub fn check_finished(&self, allow_unfinished: bool) -> Result<(), FileError> {
        if self.count_missing && !allow_unfinished {
            return Err(FileError {
                path: self.path.clone(),
                error: TtrError::Unfinished {
                    present: self.records_present,
                },
            });
        }
        Ok(())
    }

    /// Acquisition time set in the software (s), when recorded.
    pub fn acquisition_time_s(&self) -> Option<f64> {
        self.tags
            .float("MeasDesc_AcquisitionTime")
            .map(|ms| ms * 1e-3)
    }

    /// Time after which the measurement actually stopped (s), when recorded.
    pub fn stopped_after_s(&self) -> Option<f64> {
        self.tags.float("TTResult_StopAfter").map(|ms| ms * 1e-3)
    }
}

impl FileInfo {
    /// Records a reader returns: those present, up to the announced count.
    pub fn records_to_read(&self) -> u64 {
        self.records_present.min(self.records_announced)
    }

    /// Readers of `parts` consecutive ranges of the records [`open`] reads,
    /// each on the file opened anew, for decoding parts at once where no
    /// record depends on the state an earlier one left.
    pub fn split_records(&self, parts: usize) -> Result<Vec<RecordReader>, FileError> {
        (0..parts.max(1))
            .map(|i| self.records_part(i, parts))
            .collect()
    }

    /// A reader of the `part`-th of `parts` consecutive ranges of the
    /// records [`open`] reads, on the file opened anew. The last range
    /// ends as [`open`]'s reader does ([`TtrError::Truncated`] when
    /// records are missing).
    pub fn records_part(&self, part: usize, parts: usize) -> Result<RecordReader, FileError> {
        let (reader, first, end) = crate::formats::open_part(
            &self.path,
            self.data_offset,
            4,
            self.records_to_read(),
            part,
            parts,
        )
        .map_err(|error| FileError {
            path: self.path.clone(),
            error: error.into(),
        })?;
        Ok(RecordReader {
            reader,
            remaining: end - first,
            read: first,
            info_announced: if part + 1 == parts.max(1) {
                self.records_announced
            } else {
                end
            },
            trailing: self.trailing_bytes,
        })
    }
}

/// Streams records in chunks.
pub struct RecordReader {
    reader: BufReader<File>,
    remaining: u64,
    read: u64,
    info_announced: u64,
    trailing: u64,
}

/// Records per chunk (4 MiB).
pub const CHUNK_RECORDS: usize = 1 << 20;

impl RecordReader {
    /// Reads the next chunk of records into `out` (replacing its contents); returns
    /// false at the end. A file cut before the announced count ends with
    /// [`TtrError::Truncated`] after its last complete record was returned.
    pub fn next_chunk(&mut self, out: &mut Vec<u32>) -> Result<bool, TtrError> {
        if self.remaining == 0 {
            out.clear();
            if self.read < self.info_announced {
                return Err(TtrError::Truncated {
                    read: self.read,
                    expected: self.info_announced,
                    trailing: self.trailing,
                });
            }
            return Ok(false);
        }
        let n = (self.remaining as usize).min(CHUNK_RECORDS);
        crate::formats::read_records(&mut self.reader, out, n)?;
        crate::formats::u32_from_le(out);
        self.remaining -= n as u64;
        self.read += n as u64;
        Ok(true)
    }
}

/// Opens a PTU, HT3/HT2 or PT3/PT2 file: header parsed, reader at the first record.
pub fn open(path: &Path) -> Result<(FileInfo, RecordReader), FileError> {
    open_inner(path).map_err(|error| FileError {
        path: path.to_owned(),
        error,
    })
}

fn open_inner(path: &Path) -> Result<(FileInfo, RecordReader), TtrError> {
    let (mut file, meta) = crate::files::open_regular(path, "recording")?;
    let size = meta.len();
    let mut magic = [0u8; 16];
    let got = file.read(&mut magic)?;
    file.seek(SeekFrom::Start(0))?;
    let mut reader = BufReader::with_capacity(1 << 20, file);
    let mut info = if got >= 8 && &magic[..8] == ptu::MAGIC {
        from_ptu(path, &mut reader)?
    } else if magic.starts_with(b"HydraHarp") {
        from_legacy(path, legacy::parse_hydraharp(&mut reader)?)
    } else if magic.starts_with(b"PicoHarp 300") {
        from_legacy(path, legacy::parse_picoharp(&mut reader)?)
    } else if magic.starts_with(b"TimeHarp") {
        return Err(TtrError::Unsupported(
            "legacy TimeHarp files (THD/T3R) are not supported; export the data as PTU".into(),
        ));
    } else {
        return Err(TtrError::header(
            0,
            "not a PicoQuant file: no PQTTTR or HydraHarp magic",
        ));
    };
    // A second header where the records should start (a file written
    // twice, or two files joined) would decode as hundreds of bogus
    // records: refused, not binned.
    if reader.fill_buf()?.starts_with(ptu::MAGIC) {
        return Err(TtrError::header(
            info.data_offset,
            "a second PTU header starts where the records should (a file written twice or two files joined); split the file at this byte",
        ));
    }
    let body = size.saturating_sub(info.data_offset);
    info.records_present = body / 4;
    info.trailing_bytes = body % 4;
    if info.records_announced == 0 {
        info.records_announced = info.records_present;
        info.count_missing = info.records_present > 0;
    }
    let records = info.records_to_read();
    let rr = RecordReader {
        reader,
        remaining: records,
        read: 0,
        info_announced: info.records_announced,
        trailing: info.trailing_bytes,
    };
    Ok((info, rr))
}

fn from_ptu(path: &Path, r: &mut impl Read) -> Result<FileInfo, TtrError> {
    let (version, tags, offset) = ptu::parse(r)?;
    let code = tags.int("TTResultFormat_TTTRRecType").ok_or_else(|| {
        TtrError::header(
            offset,
            "no TTResultFormat_TTTRRecType tag (not a TTTR file)",
        )
    })?;
    let record_type = RecordType::from_code(code as u32).ok_or_else(|| {
        TtrError::Unsupported(format!(
            "record type 0x{code:08X} is not a supported TTTR format"
        ))
    })?;
    let positive = |name: &str| {
        tags.float(name)
            .filter(|v| *v > 0.0 && v.is_finite())
            .ok_or_else(|| {
                TtrError::header(offset, format!("tag {name} is missing or not positive"))
            })
    };
    // PicoQuant software stores the resolution from a 32-bit float
    // (64 ps arrives as 6.3999999744e-11 s): keep the 7 significant digits
    // a float carries, so bin widths and starts come out as round numbers.
    // A resolution stored as a double (9.696969697e-11 s) is kept whole:
    // rounded, the phase of a 130th bin would move by 4e-4 ps.
    let resolution_s = float32_digits(positive("MeasDesc_Resolution")?);
    let sync_rate = tags.float("TTResult_SyncRate").filter(|v| *v > 0.0);
    let macro_unit_s = if record_type.is_t3() {
        match tags.float("MeasDesc_GlobalResolution").filter(|v| *v > 0.0) {
            Some(g) => g,
            None => {
                1.0 / sync_rate.ok_or_else(|| {
                    TtrError::header(
                        offset,
                        "T3 file without MeasDesc_GlobalResolution or TTResult_SyncRate",
                    )
                })?
            }
        }
    } else {
        tags.float("MeasDesc_GlobalResolution")
            .filter(|v| *v > 0.0)
            .unwrap_or(resolution_s)
    };
    let announced = tags.int("TTResult_NumberOfRecords").unwrap_or(0);
    let sub_mode = tags.int("Measurement_SubMode").unwrap_or(0);
    let imaging = if sub_mode == 3 {
        let int = |n: &str| {
            tags.int(n)
                .ok_or_else(|| TtrError::header(offset, format!("imaging file without tag {n}")))
        };
        let mask = |n: &str| -> Result<u8, TtrError> {
            let bit = int(n)?;
            if !(1..=4).contains(&bit) {
                return Err(TtrError::header(
                    offset,
                    format!("tag {n} = {bit}: marker bits are 1 to 4"),
                ));
            }
            Ok(1u8 << (bit - 1))
        };
        let size = |n: &str| -> Result<usize, TtrError> {
            let v = int(n)?;
            usize::try_from(v)
                .ok()
                .filter(|&v| (1..=1 << 16).contains(&v))
                .ok_or_else(|| {
                    TtrError::header(
                        offset,
                        format!("tag {n} = {v} is not a plausible image size"),
                    )
                })
        };
        let (line_start, line_stop) = (mask("ImgHdr_LineStart")?, mask("ImgHdr_LineStop")?);
        if line_start == line_stop {
            return Err(TtrError::header(
                offset,
                format!(
                    "ImgHdr_LineStart and ImgHdr_LineStop are both marker {}: a line's start cannot be told from its stop, so no photon has a pixel",
                    line_start.trailing_zeros() + 1
                ),
            ));
        }
        Some(Imaging {
            pixels_x: size("ImgHdr_PixX")?,
            pixels_y: size("ImgHdr_PixY")?,
            line_start,
            line_stop,
            frame: if tags.value("ImgHdr_Frame").is_some() {
                mask("ImgHdr_Frame")?
            } else {
                0
            },
            bidirectional: tags.int("ImgHdr_BiDirect").unwrap_or(0) != 0,
        })
    } else {
        None
    };
    Ok(FileInfo {
        path: path.to_owned(),
        container: Container::Ptu(version),
        record_type,
        device: tags.text("HW_Type").unwrap_or("unknown").to_string(),
        resolution_s,
        macro_unit_s,
        sync_rate_hz: sync_rate,
        records_announced: u64::try_from(announced).unwrap_or(0),
        count_missing: false,
        records_present: 0,
        trailing_bytes: 0,
        data_offset: offset,
        sub_mode,
        imaging,
        tags,
    })
}

/// `v` rounded to 7 significant digits when it is a 32-bit float's value
/// (the digits the float carries), else `v`.
fn float32_digits(v: f64) -> f64 {
    if f64::from(v as f32) != v {
        return v;
    }
    format!("{v:.6e}").parse().unwrap_or(v)
}

fn from_legacy(path: &Path, h: legacy::LegacyHeader) -> FileInfo {
    let t3 = h.record_type.is_t3();
    let container = match h.record_type {
        RecordType::PicoHarpT3 | RecordType::PicoHarpT2 => Container::PicoHarpLegacy(h.version),
        _ => Container::HydraHarpLegacy(h.version),
    };
    FileInfo {
        path: path.to_owned(),
        container,
        record_type: h.record_type,
        device: h.hardware,
        resolution_s: if t3 {
            h.resolution_ps
        } else {
            h.base_resolution_ps
        } * 1e-12,
        macro_unit_s: if t3 && h.sync_rate_hz > 0.0 {
            1.0 / h.sync_rate_hz
        } else {
            h.base_resolution_ps * 1e-12
        },
        sync_rate_hz: (h.sync_rate_hz > 0.0).then_some(h.sync_rate_hz),
        records_announced: h.records,
        count_missing: false,
        records_present: 0,
        trailing_bytes: 0,
        data_offset: h.data_offset,
        sub_mode: 0,
        imaging: None,
        tags: Vec::new(),
    }
}
