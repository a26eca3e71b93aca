//! Event batches of the wire protocol (live, or read back from the
//! project's tag files) -> the [`Binner`]. The file format, its writer and
//! its reader live in [`crate::formats::sstags`]; the format is specified
//! there and in `firmware-protocol/PROTOCOL.md`.

use firmware_protocol::EventBatch;
use firmware_protocol::record::{Record, RecordError};

use super::binning::Binner;
use super::counts::Counts;
use crate::events::Tag;

/// Feeds every event of a batch payload to `binner`, which counts every
/// record: photons and markers as it bins them, overflows, losses (and the
/// photons they report lost) and records that do not decode here.
///
/// The record loop is the throughput-critical path of live acquisition and
/// of reading raw files (see BENCHMARKS.md): records are decoded in place,
/// wraps applied to a running base, no intermediate event list.
pub fn bin_batch(batch: &EventBatch<'_>, binner: &mut Binner) {
    let mut counts = Counts::default();
    if binner.is_sensor() {
        // Photons in bulk (see `Binner::push_sensor_photons`); the rare
        // other records are handled on the way.
        let mut markers = 0;
        let photons = batch.record_bytes().chunks_exact(8).filter_map(|c| {
            let raw = u64::from_le_bytes(c.try_into().expect("8-byte chunk"));
            match Record::decode(raw) {
                Ok(Record::Photon { pixel, micro, .. }) => return Some((pixel, micro)),
                Ok(Record::Marker { .. }) => markers += 1,
                other => count_other(&mut counts, &other),
            }
            None
        });
        binner.push_sensor_photons(photons);
        binner.count_markers(markers);
        binner.count_other_records(counts);
        return;
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
                counts.records += 1;
                base += u64::from(count) << firmware_protocol::record::SYNC_BITS;
            }
            other => count_other(&mut counts, &other),
        }
    }
    binner.count_other_records(counts);
}

/// Counts a record that places no photon: an overflow, a loss (with the
/// photons it reports lost) or one that does not decode.
#[inline]
fn count_other(counts: &mut Counts, record: &Result<Record, RecordError>) {
    counts.records += 1;
    match record {
        Ok(Record::Lost { count }) => counts.lost_in_device += count,
        Err(_) => counts.invalid_records += 1,
        Ok(_) => {}
    }
}
