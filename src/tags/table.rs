//! Every tag of a recorded file as columns (for array front ends: the
//! Python package's `read_tags`): photons' channel, macro and micro time,
//! markers' bits and time, T2 syncs' time. PicoQuant files decode with
//! their overflow rules; the project's tag files give the sensor pixel as
//! the channel.

use std::path::Path;

use crate::events::Tag;
use crate::formats::detect::is_tag_file;
use crate::formats::picoquant::records::Decoder;
use crate::formats::picoquant::{FileError, open};
use crate::formats::sstags::{TagFile, TagFileError};

/// The columns of a file's tags, in file order within each kind.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TagTable {
    /// Photon input channel (tag files: the pixel, row-major).
    pub channel: Vec<u16>,
    /// Photon macro time (sync count in T3; time unit count in T2).
    pub macro_time: Vec<u64>,
    /// Photon micro time (T3; 0 in T2).
    pub micro_time: Vec<u32>,
    /// Marker bits.
    pub marker_bits: Vec<u8>,
    /// Marker macro time.
    pub marker_time: Vec<u64>,
    /// Sync events' time (T2 files only).
    pub sync_time: Vec<u64>,
    /// Micro-time unit (s).
    pub resolution_s: f64,
    /// Macro-time unit (s).
    pub macro_unit_s: f64,
    /// The header in words, one line each.
    pub header: Vec<String>,
}

/// Why a file's tags cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    /// The PicoQuant file cannot be read.
    #[error(transparent)]
    File(#[from] FileError),
    /// The tag file cannot be read.
    #[error(transparent)]
    TagFile(#[from] TagFileError),
    /// More memory than the budget.
    #[error(transparent)]
    Memory(#[from] crate::memory::MemoryError),
    /// A record that does not decode.
    #[error("{0}")]
    Record(String),
}

/// Bytes per photon row.
const ROW_BYTES: u64 = 14;

impl TagTable {
    fn push(&mut self, tag: Tag) {
        match tag {
            Tag::Photon {
                channel,
                macro_time,
                micro_time,
            } => {
                self.channel.push(channel);
                self.macro_time.push(macro_time);
                self.micro_time.push(micro_time);
            }
            Tag::Marker { bits, macro_time } => {
                self.marker_bits.push(bits);
                self.marker_time.push(macro_time);
            }
            Tag::Sync { macro_time } => self.sync_time.push(macro_time),
        }
    }
}

/// Reads every tag of `path` (a PicoQuant file or a tag file).
pub fn read_tags(path: &Path) -> Result<TagTable, TableError> {
    let budget = |records: u64| {
        crate::memory::check(records.saturating_mul(ROW_BYTES), || {
            format!("the tags of {} as columns", path.display())
        })
    };
    if is_tag_file(path) {
        let file = TagFile::open(path)?;
        let h = file.header.clone();
        budget(std::fs::metadata(path).map_or(0, |m| m.len()) / 8)?;
        let mut table = TagTable {
            resolution_s: f64::from(h.resolution_fs) * 1e-15,
            macro_unit_s: h.sync_period_fs as f64 * 1e-15,
            header: vec![format!(
                "{} {} ({} x {} pixels; channel = pixel, row-major)",
                h.model, h.serial, h.pixels_x, h.pixels_y
            )],
            ..TagTable::default()
        };
        let mut bad = None;
        file.read(|batch| {
            for e in batch.events() {
                match e {
                    Ok(event) => {
                        if let Some(tag) = Tag::from_wire(event) {
                            table.push(tag);
                        }
                    }
                    Err(e) => {
                        bad.get_or_insert(format!(
                            "{}: record {:#018x} of batch {} does not decode",
                            path.display(),
                            e.raw,
                            batch.header.seq
                        ));
                    }
                }
            }
        })?;
        return match bad {
            Some(b) => Err(TableError::Record(b)),
            None => Ok(table),
        };
    }
    let (info, mut reader) = open(path)?;
    budget(info.records_present)?;
    let mut table = TagTable {
        resolution_s: info.resolution_s,
        macro_unit_s: info.macro_unit_s,
        header: info.describe(),
        ..TagTable::default()
    };
    let mut decoder = Decoder::new(info.record_type);
    let mut chunk = Vec::new();
    while reader.next_chunk(&mut chunk).map_err(|error| FileError {
        path: path.to_owned(),
        error,
    })? {
        for &rec in &chunk {
            if let Some(tag) = decoder.decode(rec) {
                table.push(tag);
            }
        }
    }
    Ok(table)
}
