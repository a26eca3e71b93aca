//! The project's tag file (`.sstags`): a lossless recording of a live
//! acquisition, event batches exactly as the device sent them.
//!
//! ```text
//! "SSTAGS01"                      8-byte magic
//! header length L                 u32 LE
//! header                          L bytes of JSON (TagFileHeader)
//! frames                          event batches exactly as on the wire
//!                                 (firmware-protocol frames of kind 03)
//! end frame                       a response frame Stopped(Totals), id
//!                                 0xFFFF (the run reached its planned
//!                                 end) or 0xFFFE (interrupted early)
//! ```
//!
//! Every batch is written and flushed as it arrives, so a crash loses at
//! most the batch being written; a reader recognises the cut (no end frame,
//! an incomplete last frame) and says so. The frames keep their CRCs, so a
//! damaged file is detected too.

use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use firmware_protocol::{
    Config, EventBatch, FrameDecoder, FrameKind, FromDevice, Identity, Response, ResponseFrame,
    Totals, encode_frame, to_payload,
};
use serde::{Deserialize, Serialize};

/// Id of the end frame of a run that reached its planned end.
pub const END_COMPLETE: u16 = 0xFFFF;
/// Id of the end frame of a run that was interrupted (Ctrl-C, SIGTERM).
pub const END_INTERRUPTED: u16 = 0xFFFE;

/// First bytes of every tag file.
pub const MAGIC: &[u8; 8] = b"SSTAGS01";
/// Bytes read per chunk (constant memory for any file size).
const CHUNK: usize = 1 << 20;
/// Largest header accepted when reading (a damaged length is not an
/// allocation request).
pub const MAX_HEADER: u32 = 1 << 20;

/// What the file's JSON header records.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TagFileHeader {
    /// Format version (1).
    pub format_version: u32,
    /// The link the data came from.
    pub link: String,
    /// Device model.
    pub model: String,
    /// Device serial number.
    pub serial: String,
    /// Sensor columns.
    pub pixels_x: u16,
    /// Sensor rows.
    pub pixels_y: u16,
    /// Micro-time unit of the records, femtoseconds.
    pub resolution_fs: u32,
    /// Laser sync period, femtoseconds.
    pub sync_period_fs: u64,
    /// Sync divider applied by the device.
    pub sync_divider: u16,
    /// Micro-time window applied by the device (0 = whole period).
    pub time_window: u32,
    /// Software that wrote the file.
    pub software: String,
}

impl TagFileHeader {
    /// The header of a recording from `identity` configured with `config`.
    pub fn new(link: &str, identity: &Identity, config: &Config, software: &str) -> Self {
        Self {
            format_version: 1,
            link: link.to_string(),
            model: identity.model.clone(),
            serial: identity.serial.clone(),
            pixels_x: identity.pixels_x,
            pixels_y: identity.pixels_y,
            resolution_fs: config.resolution_fs,
            sync_period_fs: identity.sync_period_fs * u64::from(config.sync_divider.max(1)),
            sync_divider: config.sync_divider,
            time_window: config.time_window,
            software: software.to_string(),
        }
    }
}

/// Errors of tag files, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum TagFileError {
    /// Operating-system error.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// Not a tag file, or a damaged header.
    #[error("{path}: {reason}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// Appends batches to a tag file, flushing after each. The file is
/// written under a temporary name and renamed into place by
/// [`TagFileWriter::finish`]; a writer that never finished (killed)
/// leaves it under that name, cut before its end frame, which readers flag.
pub struct TagFileWriter {
    path: PathBuf,
    out: BufWriter<crate::files::AtomicFile>,
    frame: Vec<u8>,
    /// First write error; later writes are skipped and the error reported
    /// at [`TagFileWriter::finish`].
    error: Option<std::io::Error>,
    batches: u64,
}

impl TagFileWriter {
    /// Creates the file and writes the header.
    pub fn create(path: &Path, header: &TagFileHeader) -> Result<Self, TagFileError> {
        let io = |source| TagFileError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = crate::files::AtomicFile::create_recording(path).map_err(io)?;
        let mut out = BufWriter::with_capacity(1 << 17, file);
        let json = serde_json::to_vec(header).expect("header serialises");
        out.write_all(MAGIC).map_err(io)?;
        out.write_all(&(json.len() as u32).to_le_bytes())
            .map_err(io)?;
        out.write_all(&json).map_err(io)?;
        out.flush().map_err(io)?;
        Ok(Self {
            path: path.to_path_buf(),
            out,
            frame: Vec::new(),
            error: None,
            batches: 0,
        })
    }

    /// Appends one batch payload as a frame and flushes it.
    pub fn write_batch(&mut self, payload: &[u8]) {
        if self.error.is_some() {
            return;
        }
        self.frame.clear();
        encode_frame(FrameKind::Events, payload, &mut self.frame)
            .expect("batch payloads fit a frame");
        let r = self
            .out
            .write_all(&self.frame)
            .and_then(|()| self.out.flush());
        match r {
            Ok(()) => self.batches += 1,
            Err(e) => self.error = Some(e),
        }
    }

    /// Batches written.
    pub fn batches(&self) -> u64 {
        self.batches
    }

    /// Writes the end frame (the device's totals when known, and whether
    /// the run reached its planned end) and renames the file into place.
    pub fn finish(
        mut self,
        totals: Option<Totals>,
        completion: crate::files::Completion,
    ) -> Result<PathBuf, TagFileError> {
        if let Some(e) = self.error.take() {
            return Err(TagFileError::Io {
                path: self.path,
                source: e,
            });
        }
        let io = |path: &Path, source| TagFileError::Io {
            path: path.to_path_buf(),
            source,
        };
        if let Some(t) = totals {
            let payload = to_payload(&ResponseFrame {
                id: match completion {
                    crate::files::Completion::Complete => END_COMPLETE,
                    crate::files::Completion::Interrupted => END_INTERRUPTED,
                },
                response: Response::Stopped(t),
            })
            .expect("totals encode");
            self.frame.clear();
            encode_frame(FrameKind::Response, &payload, &mut self.frame).expect("small frame");
            self.out
                .write_all(&self.frame)
                .map_err(|e| io(&self.path, e))?;
        }
        crate::files::AtomicFile::commit_buffered(self.out).map_err(|e| io(&self.path, e))
    }
}

/// Reads the magic and header of a tag file; the reader is left at
/// the first frame.
pub fn read_header(
    path: &Path,
    input: &mut impl Read,
) -> Result<(TagFileHeader, u64), TagFileError> {
    let fmt = |reason: String| TagFileError::Format {
        path: path.to_path_buf(),
        reason,
    };
    let mut magic = [0u8; 8];
    input
        .read_exact(&mut magic)
        .map_err(|_| fmt("shorter than the 8-byte magic; not a scatterscope tag file".into()))?;
    if &magic != MAGIC {
        return Err(fmt(format!(
            "magic {:?} is not {:?}; not a scatterscope tag file",
            String::from_utf8_lossy(&magic),
            String::from_utf8_lossy(MAGIC)
        )));
    }
    let mut len = [0u8; 4];
    input
        .read_exact(&mut len)
        .map_err(|_| fmt("file ends inside the header length".into()))?;
    let len = u32::from_le_bytes(len);
    if len > MAX_HEADER {
        return Err(fmt(format!(
            "header length {len} bytes at byte 8 exceeds {MAX_HEADER}"
        )));
    }
    let mut json = vec![0u8; len as usize];
    input
        .read_exact(&mut json)
        .map_err(|_| fmt(format!("file ends inside the {len}-byte header")))?;
    let header: TagFileHeader =
        serde_json::from_slice(&json).map_err(|e| fmt(format!("header JSON: {e}")))?;
    if header.format_version != 1 {
        return Err(fmt(format!(
            "format_version {} is not 1",
            header.format_version
        )));
    }
    Ok((header, 12 + u64::from(len)))
}

/// What a tag file holds, from one pass.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TagFileSummary {
    /// The file.
    pub path: PathBuf,
    /// Its header.
    pub header: TagFileHeader,
    /// Event batches.
    pub batches: u64,
    /// The device's totals from the end frame; `None` if the recording was
    /// cut (crash, disconnect) before it.
    pub totals: Option<Totals>,
    /// The end frame says the run was interrupted before its planned end.
    pub interrupted: bool,
    /// Bytes that did not form valid frames (damage, or a last batch cut
    /// mid-write).
    pub bytes_skipped: u64,
    /// Batches whose payload did not parse.
    pub malformed_batches: u64,
}

/// An opened tag file: its header read, positioned at the first frame.
pub struct TagFile {
    path: PathBuf,
    file: File,
    /// The file's header.
    pub header: TagFileHeader,
}

impl TagFile {
    /// Opens `path` and reads its magic and header.
    pub fn open(path: &Path) -> Result<Self, TagFileError> {
        let (mut file, _) =
            crate::files::open_regular(path, "tag file").map_err(|source| TagFileError::Io {
                path: path.to_path_buf(),
                source,
            })?;
        let (header, _) = read_header(path, &mut file)?;
        Ok(Self {
            path: path.to_path_buf(),
            file,
            header,
        })
    }

    /// Reads every frame, feeding each event batch to `on_batch`, in
    /// constant memory.
    pub fn read(
        self,
        mut on_batch: impl FnMut(&EventBatch<'_>),
    ) -> Result<TagFileSummary, TagFileError> {
        self.read_payloads(|_, batch| on_batch(batch))
    }

    /// [`Self::read`] with each batch's payload as recorded, byte for byte.
    pub fn read_payloads(
        self,
        mut on_batch: impl FnMut(&[u8], &EventBatch<'_>),
    ) -> Result<TagFileSummary, TagFileError> {
        let Self {
            path,
            mut file,
            header,
        } = self;
        let io = |source| TagFileError::Io {
            path: path.clone(),
            source,
        };
        let mut decoder = FrameDecoder::new();
        // Small files get a small buffer.
        let size = file.metadata().map_err(io)?.len();
        let mut buf = vec![0u8; CHUNK.min(usize::try_from(size).unwrap_or(CHUNK)).max(1)];
        let mut summary = TagFileSummary {
            path: path.clone(),
            header,
            batches: 0,
            totals: None,
            interrupted: false,
            bytes_skipped: 0,
            malformed_batches: 0,
        };
        loop {
            let n = file.read(&mut buf).map_err(io)?;
            if n == 0 {
                decoder.end_stream();
            }
            decoder.push_with(&buf[..n], |frame| match FromDevice::parse(frame) {
                FromDevice::Events(b) => {
                    summary.batches += 1;
                    on_batch(frame.payload, &b);
                }
                FromDevice::Response(ResponseFrame {
                    id,
                    response: Response::Stopped(t),
                }) => {
                    summary.totals = Some(t);
                    summary.interrupted = id == END_INTERRUPTED;
                }
                FromDevice::MalformedBatch(_) => summary.malformed_batches += 1,
                FromDevice::Response(_) | FromDevice::Stray => {}
            });
            if n == 0 {
                break;
            }
        }
        summary.bytes_skipped = decoder.stats().bytes_skipped;
        Ok(summary)
    }
}

/// Reads a tag file, feeding every event batch to `on_batch`, in
/// constant memory ([`TagFile::open`] then [`TagFile::read`]).
pub fn read_tag_file(
    path: &Path,
    on_batch: impl FnMut(&EventBatch<'_>),
) -> Result<TagFileSummary, TagFileError> {
    TagFile::open(path)?.read(on_batch)
}
