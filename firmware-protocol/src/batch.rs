//! Event batches: the payload of [`crate::FrameKind::Events`] frames.
//!
//! ```text
//! seq u32 | photon_offset u64 | sync_base u64 | records (u64 LE each)
//! ```
//!
//! `seq` counts batches from 0 at Start; `photon_offset` is the number of
//! photon records in all earlier batches, so the host knows exactly how many
//! photons a missing batch carried; `sync_base` is the full laser-sync count
//! the batch's sync fields are relative to, so every batch decodes on its
//! own (duplicated or reordered batches cannot corrupt later ones).

use alloc::vec::Vec;

use crate::frame::MAX_PAYLOAD;
use crate::record::{Event, MAX_LOST, MAX_MICRO, Record, RecordError, SYNC_BITS};

/// Bytes of the batch header.
pub const HEADER_LEN: usize = 20;
/// Most records one batch can carry (the frame payload limit).
pub const MAX_RECORDS: usize = (MAX_PAYLOAD - HEADER_LEN) / 8;

/// The fixed part of a batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BatchHeader {
    /// Batch number since Start.
    pub seq: u32,
    /// Photon records in all earlier batches.
    pub photon_offset: u64,
    /// Sync count the first record is relative to.
    pub sync_base: u64,
}

/// Why a batch payload does not parse.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BatchError {
    /// Shorter than the header.
    Short(usize),
    /// The records part is not a whole number of records.
    Ragged(usize),
}

impl core::fmt::Display for BatchError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            BatchError::Short(n) => write!(
                f,
                "event batch of {n} bytes is shorter than its {HEADER_LEN}-byte header"
            ),
            BatchError::Ragged(n) => {
                write!(f, "event batch records take {n} bytes, not a multiple of 8")
            }
        }
    }
}

/// A parsed batch borrowing the frame payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EventBatch<'a> {
    /// Header fields.
    pub header: BatchHeader,
    records: &'a [u8],
}

impl<'a> EventBatch<'a> {
    /// Parses a batch payload.
    pub fn parse(payload: &'a [u8]) -> Result<Self, BatchError> {
        if payload.len() < HEADER_LEN {
            return Err(BatchError::Short(payload.len()));
        }
        let records = &payload[HEADER_LEN..];
        if !records.len().is_multiple_of(8) {
            return Err(BatchError::Ragged(records.len()));
        }
        let u64_at = |i: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&payload[i..i + 8]);
            u64::from_le_bytes(b)
        };
        let header = BatchHeader {
            seq: u32::from_le_bytes([payload[0], payload[1], payload[2], payload[3]]),
            photon_offset: u64_at(4),
            sync_base: u64_at(12),
        };
        Ok(Self { header, records })
    }

    /// Number of records (wraps included).
    pub fn len(&self) -> usize {
        self.records.len() / 8
    }

    /// Whether the batch has no records.
    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// The records as bytes (8 per record, little-endian).
    pub fn record_bytes(&self) -> &'a [u8] {
        self.records
    }

    /// The raw records.
    pub fn raw_records(&self) -> impl Iterator<Item = u64> + 'a {
        self.records
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
    }

    /// The events with absolute sync counts; wraps are applied, not
    /// returned. An invalid record yields an error and decoding goes on.
    pub fn events(&self) -> impl Iterator<Item = Result<Event, RecordError>> + 'a {
        let mut base = self.header.sync_base;
        self.raw_records()
            .filter_map(move |raw| match Record::decode(raw) {
                Ok(Record::Photon {
                    pixel,
                    micro,
                    sync_offset,
                }) => Some(Ok(Event::Photon {
                    pixel,
                    micro,
                    sync: base.wrapping_add(u64::from(sync_offset)),
                })),
                Ok(Record::Wrap { count }) => {
                    base = base.wrapping_add(u64::from(count) << SYNC_BITS);
                    None
                }
                Ok(Record::Marker { bits, sync_offset }) => Some(Ok(Event::Marker {
                    bits,
                    sync: base.wrapping_add(u64::from(sync_offset)),
                })),
                Ok(Record::Lost { count }) => Some(Ok(Event::Lost { count })),
                Err(e) => Some(Err(e)),
            })
    }
}

/// Why an event cannot be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncodeError {
    /// Micro time above [`MAX_MICRO`].
    MicroTooLarge(u32),
    /// Sync count before the batch's running base (events must be in time order).
    SyncBackwards {
        /// The event's sync count.
        sync: u64,
        /// The running base.
        base: u64,
    },
}

/// Builds batch payloads from events in time order.
#[derive(Debug)]
pub struct BatchEncoder {
    seq: u32,
    photons_before: u64,
    photons_in_batch: u64,
    base: u64,
    records: Vec<u64>,
    sync_base: u64,
}

impl BatchEncoder {
    /// A fresh stream (batch 0, sync 0).
    pub fn new() -> Self {
        Self {
            seq: 0,
            photons_before: 0,
            photons_in_batch: 0,
            base: 0,
            records: Vec::new(),
            sync_base: 0,
        }
    }

    /// Records in the open batch.
    pub fn len(&self) -> usize {
        self.records.len()
    }

    /// Whether the open batch is empty.
    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// Whether the open batch can take `n` more records (an event may need
    /// a wrap record before it).
    pub fn has_room(&self, n: usize) -> bool {
        self.records.len() + n <= MAX_RECORDS
    }

    /// Photon records in all finished batches plus the open one.
    pub fn photons(&self) -> u64 {
        self.photons_before + self.photons_in_batch
    }

    /// Batches finished so far.
    pub fn batches(&self) -> u32 {
        self.seq
    }

    fn advance_to(&mut self, sync: u64) -> Result<u32, EncodeError> {
        if sync < self.base {
            return Err(EncodeError::SyncBackwards {
                sync,
                base: self.base,
            });
        }
        let mut delta = sync - self.base;
        while delta >> SYNC_BITS != 0 {
            let wraps = (delta >> SYNC_BITS).min(u64::from(u32::MAX));
            self.records.push(
                Record::Wrap {
                    count: wraps as u32,
                }
                .encode(),
            );
            self.base += wraps << SYNC_BITS;
            delta = sync - self.base;
        }
        Ok(delta as u32)
    }

    /// Appends an event. The caller checks [`Self::has_room`] (2 records
    /// suffice for any event) and calls [`Self::finish_batch`] when full.
    pub fn push(&mut self, event: Event) -> Result<(), EncodeError> {
        match event {
            Event::Photon { pixel, micro, sync } => {
                if micro > MAX_MICRO {
                    return Err(EncodeError::MicroTooLarge(micro));
                }
                let sync_offset = self.advance_to(sync)?;
                self.records.push(
                    Record::Photon {
                        pixel,
                        micro,
                        sync_offset,
                    }
                    .encode(),
                );
                self.photons_in_batch += 1;
            }
            Event::Marker { bits, sync } => {
                let sync_offset = self.advance_to(sync)?;
                self.records
                    .push(Record::Marker { bits, sync_offset }.encode());
            }
            Event::Lost { mut count } => {
                while count > 0 {
                    let c = count.min(MAX_LOST);
                    self.records.push(Record::Lost { count: c }.encode());
                    count -= c;
                }
            }
        }
        Ok(())
    }

    /// Closes the open batch and appends its payload to `out`; the next
    /// batch starts at the current sync base.
    pub fn finish_batch(&mut self, out: &mut Vec<u8>) -> BatchHeader {
        let header = BatchHeader {
            seq: self.seq,
            photon_offset: self.photons_before,
            sync_base: self.sync_base,
        };
        out.reserve(HEADER_LEN + 8 * self.records.len());
        out.extend_from_slice(&header.seq.to_le_bytes());
        out.extend_from_slice(&header.photon_offset.to_le_bytes());
        out.extend_from_slice(&header.sync_base.to_le_bytes());
        for r in self.records.drain(..) {
            out.extend_from_slice(&r.to_le_bytes());
        }
        self.seq = self.seq.wrapping_add(1);
        self.photons_before += self.photons_in_batch;
        self.photons_in_batch = 0;
        self.sync_base = self.base;
        header
    }
}

impl Default for BatchEncoder {
    fn default() -> Self {
        Self::new()
    }
}
