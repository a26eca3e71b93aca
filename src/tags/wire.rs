//! Event batches of the wire protocol (live, or read back from the
//! project's tag files) -> the [`Binner`]. The file format, its writer and
//! its reader live in [`crate::formats::sstags`]; the format is specified
//! there and in `firmware-protocol/PROTOCOL.md`.

use firmware_protocol::EventBatch;
use firmware_protocol::record::Record;

use super::binning::Binner;
use crate::events::Tag;

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
