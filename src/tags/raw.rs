//! The project's own raw tag files (written by `scatterscope acquire
//! --raw`): reading them back, and turning event batches (live or recorded)
//! into [`Tag`]s for the [`Binner`]. The format is specified in
//! `scatterscope_drivers::raw` and `firmware-protocol/PROTOCOL.md`.

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use firmware_protocol::record::Record;
use firmware_protocol::{
    EventBatch, FrameDecoder, FrameKind, Response, ResponseFrame, Totals, from_payload,
};
pub use scatterscope_drivers::raw::{MAGIC, RawHeader};
use scatterscope_drivers::raw::{RawError, read_header};

use super::Tag;
use super::binning::Binner;

/// Bytes read per chunk (constant memory for any file size).
const CHUNK: usize = 1 << 20;

/// Counts of one batch beyond what the binner keeps.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct BatchCounts {
    /// Photons the device reported lost (lost records).
    pub lost_in_device: u64,
    /// Records that did not decode.
    pub invalid_records: u64,
}

impl std::ops::AddAssign for BatchCounts {
    fn add_assign(&mut self, o: Self) {
        self.lost_in_device += o.lost_in_device;
        self.invalid_records += o.invalid_records;
    }
}

/// Feeds every event of a batch payload to `binner`.
///
/// The record loop is the throughput-critical path of live acquisition and
/// of reading raw files (see BENCHMARKS.md): records are decoded in place,
/// wraps applied to a running base, no intermediate event list.
pub fn bin_batch(batch: &EventBatch<'_>, binner: &mut Binner) -> BatchCounts {
    let mut counts = BatchCounts::default();
    if binner.is_sensor() {
        // Photons in bulk (see `Binner::push_sensor_photons`); the rare
        // other records are handled on the way.
        let mut markers = 0;
        let photons = batch.record_bytes().chunks_exact(8).filter_map(|c| {
            let raw = u64::from_le_bytes(c.try_into().expect("8-byte chunk"));
            match Record::decode(raw) {
                Ok(Record::Photon { pixel, micro, .. }) => return Some((pixel, micro)),
                Ok(Record::Marker { .. }) => markers += 1,
                Ok(Record::Wrap { .. }) => {}
                Ok(Record::Lost { count }) => counts.lost_in_device += count,
                Err(_) => counts.invalid_records += 1,
            }
            None
        });
        binner.push_sensor_photons(photons);
        binner.count_markers(markers);
        return counts;
    }
    let mut base = batch.header.sync_base;
    for raw in batch.raw_records() {
        match Record::decode(raw) {
            Ok(Record::Photon {
                pixel,
                micro,
                sync_offset,
            }) => binner.push(Some(Tag::Photon {
                channel: pixel,
                macro_time: base + u64::from(sync_offset),
                micro_time: micro,
            })),
            Ok(Record::Marker { bits, sync_offset }) => binner.push(Some(Tag::Marker {
                bits,
                macro_time: base + u64::from(sync_offset),
            })),
            Ok(Record::Wrap { count }) => {
                base += u64::from(count) << firmware_protocol::record::SYNC_BITS
            }
            Ok(Record::Lost { count }) => counts.lost_in_device += count,
            Err(_) => counts.invalid_records += 1,
        }
    }
    counts
}

/// What a raw file holds, from one pass.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RawSummary {
    /// The file.
    pub path: PathBuf,
    /// Its header.
    pub header: RawHeader,
    /// Event batches.
    pub batches: u64,
    /// The device's totals from the end frame; `None` if the recording was
    /// cut (crash, disconnect) before it.
    pub totals: Option<Totals>,
    /// Bytes that did not form valid frames (damage, or a last batch cut
    /// mid-write).
    pub bytes_skipped: u64,
    /// Batches whose payload did not parse.
    pub malformed_batches: u64,
    /// Per-batch counts.
    pub counts: BatchCounts,
}

/// Reads a raw tag file, feeding every batch to `on_batch`.
pub fn read_raw(
    path: &Path,
    mut on_batch: impl FnMut(&EventBatch<'_>),
) -> Result<RawSummary, RawError> {
    let io = |source| RawError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut file = File::open(path).map_err(io)?;
    let (header, _) = read_header(path, &mut file)?;
    let mut decoder = FrameDecoder::new();
    // Small files get a small buffer.
    let size = file.metadata().map_err(io)?.len();
    let mut buf = vec![0u8; CHUNK.min(usize::try_from(size).unwrap_or(CHUNK)).max(1)];
    let mut summary = RawSummary {
        path: path.to_path_buf(),
        header,
        batches: 0,
        totals: None,
        bytes_skipped: 0,
        malformed_batches: 0,
        counts: BatchCounts::default(),
    };
    loop {
        let n = file.read(&mut buf).map_err(io)?;
        if n == 0 {
            decoder.end_stream();
        }
        decoder.push_with(&buf[..n], |frame| match frame.kind {
            FrameKind::Events => match EventBatch::parse(frame.payload) {
                Ok(b) => {
                    summary.batches += 1;
                    on_batch(&b);
                }
                Err(_) => summary.malformed_batches += 1,
            },
            FrameKind::Response => {
                if let Ok(ResponseFrame {
                    response: Response::Stopped(t),
                    ..
                }) = from_payload(frame.payload)
                {
                    summary.totals = Some(t);
                }
            }
            FrameKind::Request => {}
        });
        if n == 0 {
            break;
        }
    }
    summary.bytes_skipped = decoder.stats().bytes_skipped;
    Ok(summary)
}

/// Whether `path` starts with the raw tag file magic.
pub fn is_raw_file(path: &Path) -> bool {
    let mut magic = [0u8; 8];
    File::open(path)
        .and_then(|mut f| f.read_exact(&mut magic))
        .is_ok()
        && &magic == MAGIC
}
