//! PicoQuant TTTR record types and their decoders.
//!
//! Layouts (32-bit little-endian records):
//! - PicoHarp T3: sync 16 bits, dtime 12, channel 4. Channel 15 is special:
//!   dtime 0 is one overflow of 65536 syncs, otherwise the low 4 dtime bits
//!   are markers. Photon channels count from 1 (PicoQuant's routing
//!   channels 1-4; its file demos call 0 illegal): the tag's channel is the
//!   record's less one, as ptufile numbers them, so that input 0 is channel
//!   0 for every family; an illegal 0 becomes channel 15, which no record
//!   can otherwise give.
//! - PicoHarp T2: time 28 bits, channel 4. Channel 15: low 4 bits 0 is one
//!   overflow of 210,698,240, otherwise markers.
//! - HydraHarp, TimeHarp 260, MultiHarp, PicoHarp 330 T3: sync 10 bits,
//!   dtime 15, channel 6, special 1. Special with channel 63 is an overflow
//!   of 1024 syncs: always one in HydraHarp v1, otherwise the sync field
//!   counts them (0 meaning 1). Special channels 1-15 are markers; 0 and
//!   16-62 carry nothing (the vendor's PTU demo readers skip them).
//! - The same families in T2: time 25 bits, channel 6, special 1. Channel
//!   63 overflows by 33,552,000 (HydraHarp v1, always one) or by 2^25 times
//!   the count (0 meaning 1); special channel 0 is a sync; 1-15 markers;
//!   16-62 carry nothing.

use crate::events::{ChunkDecoder, Tag, TagSink};

/// A TTTR record type, as `TTResultFormat_TTTRRecType` codes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordType {
    /// PicoHarp 300 T3 (0x00010303).
    PicoHarpT3,
    /// PicoHarp 300 T2 (0x00010203).
    PicoHarpT2,
    /// HydraHarp 400 v1 T3 (0x00010304).
    HydraHarpV1T3,
    /// HydraHarp 400 v1 T2 (0x00010204).
    HydraHarpV1T2,
    /// HydraHarp 400 v2 T3 (0x01010304).
    HydraHarpV2T3,
    /// HydraHarp 400 v2 T2 (0x01010204).
    HydraHarpV2T2,
    /// TimeHarp 260 N T3 (0x00010305).
    TimeHarp260NT3,
    /// TimeHarp 260 N T2 (0x00010205).
    TimeHarp260NT2,
    /// TimeHarp 260 P T3 (0x00010306).
    TimeHarp260PT3,
    /// TimeHarp 260 P T2 (0x00010206).
    TimeHarp260PT2,
    /// Generic T3: MultiHarp, PicoHarp 330 (0x00010307).
    GenericT3,
    /// Generic T2: MultiHarp, PicoHarp 330 (0x00010207).
    GenericT2,
}

impl RecordType {
    /// Every supported type.
    pub const ALL: [RecordType; 12] = [
        RecordType::PicoHarpT3,
        RecordType::PicoHarpT2,
        RecordType::HydraHarpV1T3,
        RecordType::HydraHarpV1T2,
        RecordType::HydraHarpV2T3,
        RecordType::HydraHarpV2T2,
        RecordType::TimeHarp260NT3,
        RecordType::TimeHarp260NT2,
        RecordType::TimeHarp260PT3,
        RecordType::TimeHarp260PT2,
        RecordType::GenericT3,
        RecordType::GenericT2,
    ];

    /// The header code.
    pub fn code(self) -> u32 {
        match self {
            RecordType::PicoHarpT3 => 0x0001_0303,
            RecordType::PicoHarpT2 => 0x0001_0203,
            RecordType::HydraHarpV1T3 => 0x0001_0304,
            RecordType::HydraHarpV1T2 => 0x0001_0204,
            RecordType::HydraHarpV2T3 => 0x0101_0304,
            RecordType::HydraHarpV2T2 => 0x0101_0204,
            RecordType::TimeHarp260NT3 => 0x0001_0305,
            RecordType::TimeHarp260NT2 => 0x0001_0205,
            RecordType::TimeHarp260PT3 => 0x0001_0306,
            RecordType::TimeHarp260PT2 => 0x0001_0206,
            RecordType::GenericT3 => 0x0001_0307,
            RecordType::GenericT2 => 0x0001_0207,
        }
    }

    /// The type with header code `code`.
    pub fn from_code(code: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.code() == code)
    }

    /// Human-readable name.
    pub fn name(self) -> &'static str {
        match self {
            RecordType::PicoHarpT3 => "PicoHarp T3",
            RecordType::PicoHarpT2 => "PicoHarp T2",
            RecordType::HydraHarpV1T3 => "HydraHarp v1 T3",
            RecordType::HydraHarpV1T2 => "HydraHarp v1 T2",
            RecordType::HydraHarpV2T3 => "HydraHarp v2 T3",
            RecordType::HydraHarpV2T2 => "HydraHarp v2 T2",
            RecordType::TimeHarp260NT3 => "TimeHarp 260 N T3",
            RecordType::TimeHarp260NT2 => "TimeHarp 260 N T2",
            RecordType::TimeHarp260PT3 => "TimeHarp 260 P T3",
            RecordType::TimeHarp260PT2 => "TimeHarp 260 P T2",
            RecordType::GenericT3 => "Generic T3 (MultiHarp, PicoHarp 330)",
            RecordType::GenericT2 => "Generic T2 (MultiHarp, PicoHarp 330)",
        }
    }

    /// Whether records carry a micro time after a sync (T3) rather than an
    /// absolute time (T2).
    pub fn is_t3(self) -> bool {
        matches!(self.layout(), Layout::PicoHarpT3 | Layout::WideT3 { .. })
    }

    fn layout(self) -> Layout {
        match self {
            RecordType::PicoHarpT3 => Layout::PicoHarpT3,
            RecordType::PicoHarpT2 => Layout::PicoHarpT2,
            RecordType::HydraHarpV1T3 => Layout::WideT3 {
                single_overflow: true,
            },
            RecordType::HydraHarpV1T2 => Layout::WideT2 { v1: true },
            RecordType::HydraHarpV2T3
            | RecordType::TimeHarp260NT3
            | RecordType::TimeHarp260PT3
            | RecordType::GenericT3 => Layout::WideT3 {
                single_overflow: false,
            },
            RecordType::HydraHarpV2T2
            | RecordType::TimeHarp260NT2
            | RecordType::TimeHarp260PT2
            | RecordType::GenericT2 => Layout::WideT2 { v1: false },
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Layout {
    PicoHarpT3,
    PicoHarpT2,
    WideT3 { single_overflow: bool },
    WideT2 { v1: bool },
}

/// PicoHarp T3 overflow period (syncs).
pub const PICOHARP_T3_WRAP: u64 = 65_536;
/// PicoHarp T2 overflow period (time units).
pub const PICOHARP_T2_WRAP: u64 = 210_698_240;
/// HydraHarp-family T3 overflow period (syncs).
pub const WIDE_T3_WRAP: u64 = 1024;
/// HydraHarp v1 T2 overflow period (time units).
pub const HYDRAHARP_V1_T2_WRAP: u64 = 33_552_000;
/// HydraHarp v2 and later T2 overflow period (time units).
pub const WIDE_T2_WRAP: u64 = 33_554_432;

/// Stateful decoder: carries the overflow-corrected time base. Times
/// saturate instead of wrapping, so that garbage input cannot panic.
#[derive(Debug, Clone)]
pub struct Decoder {
    layout: Layout,
    base: u64,
}

impl Decoder {
    /// A decoder for `record_type` starting at time 0.
    pub fn new(record_type: RecordType) -> Self {
        Self {
            layout: record_type.layout(),
            base: 0,
        }
    }

    /// Decodes one record; overflow records only advance the time base and
    /// return `None`.
    #[inline]
    pub fn decode(&mut self, rec: u32) -> Option<Tag> {
        self.decode_as(self.layout, rec)
    }

    #[inline(always)]
    fn decode_as(&mut self, layout: Layout, rec: u32) -> Option<Tag> {
        match layout {
            Layout::PicoHarpT3 => {
                let nsync = u64::from(rec & 0xFFFF);
                let dtime = (rec >> 16) & 0xFFF;
                let channel = (rec >> 28) as u8;
                if channel == 15 {
                    if dtime == 0 {
                        self.base = self.base.saturating_add(PICOHARP_T3_WRAP);
                        return None;
                    }
                    return Some(Tag::Marker {
                        bits: (dtime & 0xF) as u8,
                        macro_time: self.base.saturating_add(nsync),
                    });
                }
                Some(Tag::Photon {
                    channel: u16::from(channel.wrapping_sub(1) & 15),
                    macro_time: self.base.saturating_add(nsync),
                    micro_time: dtime,
                })
            }
            Layout::PicoHarpT2 => {
                let time = u64::from(rec & 0x0FFF_FFFF);
                let channel = (rec >> 28) as u8;
                if channel == 15 {
                    let bits = (rec & 0xF) as u8;
                    if bits == 0 {
                        self.base = self.base.saturating_add(PICOHARP_T2_WRAP);
                        return None;
                    }
                    return Some(Tag::Marker {
                        bits,
                        macro_time: self.base.saturating_add(time),
                    });
                }
                Some(Tag::Photon {
                    channel: u16::from(channel),
                    macro_time: self.base.saturating_add(time),
                    micro_time: 0,
                })
            }
            Layout::WideT3 { single_overflow } => {
                let nsync = u64::from(rec & 0x3FF);
                let channel = ((rec >> 25) & 0x3F) as u8;
                if rec >> 31 == 1 {
                    if channel == 0x3F {
                        let n = if single_overflow || nsync == 0 {
                            1
                        } else {
                            nsync
                        };
                        self.base = self.base.saturating_add(WIDE_T3_WRAP * n);
                        return None;
                    }
                    // Special channels 1-15 are markers; 0 and 16-62 are
                    // nothing the vendor's readers (the PTU demos'
                    // ReadHT3) report, so nothing here either.
                    return (1..=15).contains(&channel).then(|| Tag::Marker {
                        bits: channel,
                        macro_time: self.base.saturating_add(nsync),
                    });
                }
                Some(Tag::Photon {
                    channel: u16::from(channel),
                    macro_time: self.base.saturating_add(nsync),
                    micro_time: (rec >> 10) & 0x7FFF,
                })
            }
            Layout::WideT2 { v1 } => {
                let time = u64::from(rec & 0x01FF_FFFF);
                let channel = ((rec >> 25) & 0x3F) as u8;
                if rec >> 31 == 1 {
                    if channel == 0x3F {
                        self.base = self.base.saturating_add(if v1 {
                            HYDRAHARP_V1_T2_WRAP
                        } else {
                            WIDE_T2_WRAP * if time == 0 { 1 } else { time }
                        });
                        return None;
                    }
                    let macro_time = self.base.saturating_add(time);
                    // Special channel 0 is a sync, 1-15 markers; 16-62 are
                    // nothing the vendor's readers (ReadHT2) report.
                    return match channel {
                        0 => Some(Tag::Sync { macro_time }),
                        1..=15 => Some(Tag::Marker {
                            bits: channel,
                            macro_time,
                        }),
                        _ => None,
                    };
                }
                Some(Tag::Photon {
                    channel: u16::from(channel),
                    macro_time: self.base.saturating_add(time),
                    micro_time: 0,
                })
            }
        }
    }
}

impl ChunkDecoder for Decoder {
    type Record = u32;

    /// The layout is matched once per chunk, not per record: each arm is a
    /// loop the compiler specialises, on a copy of the decoder in a local
    /// (the decode + bin hot path, see BENCHMARKS.md).
    #[inline]
    fn decode_chunk<S: TagSink>(&mut self, records: &[u32], mut sink: S) -> S {
        let mut local = self.clone();
        macro_rules! run {
            ($layout:expr) => {
                for &r in records {
                    sink.push(local.decode_as($layout, r));
                }
            };
        }
        match self.layout {
            Layout::PicoHarpT3 => run!(Layout::PicoHarpT3),
            Layout::PicoHarpT2 => run!(Layout::PicoHarpT2),
            Layout::WideT3 {
                single_overflow: true,
            } => run!(Layout::WideT3 {
                single_overflow: true
            }),
            Layout::WideT3 {
                single_overflow: false,
            } => run!(Layout::WideT3 {
                single_overflow: false
            }),
            Layout::WideT2 { v1: true } => run!(Layout::WideT2 { v1: true }),
            Layout::WideT2 { v1: false } => run!(Layout::WideT2 { v1: false }),
        }
        *self = local;
        sink
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip() {
        for t in RecordType::ALL {
            assert_eq!(RecordType::from_code(t.code()), Some(t));
        }
        assert_eq!(RecordType::from_code(0x1234), None);
    }

    #[test]
    fn picoharp_t3_by_hand() {
        let mut d = Decoder::new(RecordType::PicoHarpT3);
        // routing channel 2 (the second input: channel 1), dtime 0x123,
        // nsync 7
        let photon = (2 << 28) | (0x123 << 16) | 7;
        assert_eq!(
            d.decode(photon),
            Some(Tag::Photon {
                channel: 1,
                macro_time: 7,
                micro_time: 0x123
            })
        );
        assert_eq!(d.decode(15 << 28), None); // overflow
        assert_eq!(
            d.decode(photon),
            Some(Tag::Photon {
                channel: 1,
                macro_time: 65_536 + 7,
                micro_time: 0x123
            })
        );
        // The illegal routing channel 0 stays a photon, on channel 15.
        assert_eq!(
            d.decode(0x123 << 16),
            Some(Tag::Photon {
                channel: 15,
                macro_time: 65_536,
                micro_time: 0x123
            })
        );
        assert_eq!(
            d.decode((15 << 28) | (4 << 16) | 9),
            Some(Tag::Marker {
                bits: 4,
                macro_time: 65_536 + 9
            })
        );
    }

    #[test]
    fn hydraharp_overflow_counts() {
        let overflow = |n: u32| (1 << 31) | (0x3F << 25) | n;
        let mut v1 = Decoder::new(RecordType::HydraHarpV1T3);
        let mut v2 = Decoder::new(RecordType::HydraHarpV2T3);
        for d in [&mut v1, &mut v2] {
            d.decode(overflow(5));
            d.decode(overflow(0));
        }
        let photon = (3 << 25) | (100 << 10) | 1;
        assert_eq!(
            v1.decode(photon),
            Some(Tag::Photon {
                channel: 3,
                macro_time: 2 * 1024 + 1,
                micro_time: 100
            })
        );
        assert_eq!(
            v2.decode(photon),
            Some(Tag::Photon {
                channel: 3,
                macro_time: 6 * 1024 + 1,
                micro_time: 100
            })
        );
        let mut t2 = Decoder::new(RecordType::HydraHarpV1T2);
        t2.decode(overflow(3));
        assert_eq!(
            t2.decode((1 << 31) | 17),
            Some(Tag::Sync {
                macro_time: 33_552_000 + 17
            })
        );
    }
}
