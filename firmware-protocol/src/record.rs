//! Event records: one little-endian `u64` each, type in the top 4 bits.
//!
//! | type | name   | fields (bit ranges)                                      |
//! |------|--------|----------------------------------------------------------|
//! | 0    | photon | pixel 59..44 (16), micro time 43..24 (20), sync 23..0 (24) |
//! | 1    | wrap   | count 31..0: the sync counter advanced count x 2^24      |
//! | 2    | marker | bits 59..52 (8), sync 23..0 (24)                         |
//! | 3    | lost   | count 47..0 (>= 1): photons the device dropped (FIFO)    |
//!
//! `sync` is the low 24 bits of the laser-sync counter relative to the
//! batch's running base; wrap records move the base. Unused bits are zero.

/// Bits of the sync field of photon and marker records.
pub const SYNC_BITS: u32 = 24;
/// Largest pixel index a record carries.
pub const MAX_PIXEL: u32 = (1 << 16) - 1;
/// Largest micro time a record carries.
pub const MAX_MICRO: u32 = (1 << 20) - 1;
/// Largest photon count of one lost record.
pub const MAX_LOST: u64 = (1 << 48) - 1;

const TYPE_PHOTON: u64 = 0;
const TYPE_WRAP: u64 = 1;
const TYPE_MARKER: u64 = 2;
const TYPE_LOST: u64 = 3;
const SYNC_MASK: u64 = (1 << SYNC_BITS) - 1;

/// A decoded event with its absolute sync count.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// A detected photon.
    Photon {
        /// Pixel index, row-major over the device's full sensor.
        pixel: u16,
        /// Delay after the laser sync, in the configured resolution.
        micro: u32,
        /// Laser-sync count (macro time).
        sync: u64,
    },
    /// External marker bits (bit 0 = marker 1).
    Marker {
        /// Marker bits set.
        bits: u8,
        /// Laser-sync count.
        sync: u64,
    },
    /// The device dropped `count` photons here (its FIFO overflowed).
    Lost {
        /// Photons dropped.
        count: u64,
    },
}

/// A record that does not decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordError {
    /// The raw record.
    pub raw: u64,
}

impl core::fmt::Display for RecordError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "invalid event record {:#018x} (type {})",
            self.raw,
            self.raw >> 60
        )
    }
}

/// A raw record, classified; wraps are returned to the caller, which owns
/// the running sync base.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Record {
    /// Photon with the sync offset from the running base.
    Photon {
        /// Pixel index.
        pixel: u16,
        /// Micro time.
        micro: u32,
        /// Low sync bits.
        sync_offset: u32,
    },
    /// Sync counter advanced by `count << 24`.
    Wrap {
        /// Number of 2^24 periods.
        count: u32,
    },
    /// Marker with sync offset.
    Marker {
        /// Marker bits.
        bits: u8,
        /// Low sync bits.
        sync_offset: u32,
    },
    /// Photons dropped in the device.
    Lost {
        /// Count.
        count: u64,
    },
}

impl Record {
    /// Classifies one record; reserved types and non-zero unused bits are
    /// errors.
    #[inline]
    pub fn decode(raw: u64) -> Result<Self, RecordError> {
        let err = Err(RecordError { raw });
        match raw >> 60 {
            TYPE_PHOTON => Ok(Record::Photon {
                pixel: (raw >> 44) as u16,
                micro: ((raw >> 24) as u32) & MAX_MICRO,
                sync_offset: (raw & SYNC_MASK) as u32,
            }),
            TYPE_WRAP if (raw >> 32) & 0x0fff_ffff == 0 && raw as u32 != 0 => {
                Ok(Record::Wrap { count: raw as u32 })
            }
            TYPE_MARKER if (raw >> 24) & 0x0fff_ffff == 0 => Ok(Record::Marker {
                bits: (raw >> 52) as u8,
                sync_offset: (raw & SYNC_MASK) as u32,
            }),
            TYPE_LOST if (raw >> 48) & 0x0fff == 0 && raw & MAX_LOST != 0 => Ok(Record::Lost {
                count: raw & MAX_LOST,
            }),
            _ => err,
        }
    }

    /// The raw record.
    #[inline]
    pub fn encode(self) -> u64 {
        match self {
            Record::Photon {
                pixel,
                micro,
                sync_offset,
            } => {
                TYPE_PHOTON << 60
                    | u64::from(pixel) << 44
                    | (u64::from(micro) & u64::from(MAX_MICRO)) << 24
                    | (u64::from(sync_offset) & SYNC_MASK)
            }
            Record::Wrap { count } => TYPE_WRAP << 60 | u64::from(count),
            Record::Marker { bits, sync_offset } => {
                TYPE_MARKER << 60 | u64::from(bits) << 52 | (u64::from(sync_offset) & SYNC_MASK)
            }
            Record::Lost { count } => TYPE_LOST << 60 | (count & MAX_LOST),
        }
    }
}
