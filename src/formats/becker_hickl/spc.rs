//! Becker & Hickl FIFO files (`.spc`): a file header record, then one
//! record per photon, marker or macro-time overflow, read in constant
//! memory.
//!
//! The layouts follow B&H's `SPC_data_file_structure.h` (the SPCM
//! software's description of its files, "FIFO Data Files"):
//! - SPC-130/140/150/160/180/830 (and -EM/-IN variants), 32 bits: macro
//!   time bits 0-11, routing 12-15, ADC 16-27, then MARK (28), GAP (29),
//!   MTOV (30) and INVALID (31). INVALID with MTOV and without MARK
//!   counts overflows in bits 0-27; INVALID with MARK is a marker whose
//!   bits are the routing field (pixel, line, frame clocks).
//! - SPC-600/630 in 256-channel mode, 32 bits: ADC bits 0-7, macro time
//!   8-24, routing 25-27 (the header's table; its `ROUT6_32` mask, bits
//!   24-26, overlaps the macro time and is not followed), GAP 29, MTOV 30,
//!   INVALID 31; the overflow count entry as above.
//! - SPC-600/630 in 4096-channel mode, 48 bits: ADC bytes 0-1 (12 bits),
//!   INVALID, MTOV and GAP in byte 1 (bits 4, 5, 6), macro time bytes 4, 5
//!   and 2 (24 bits), routing byte 3.
//!
//! The ADC counts back from the sync ("reversed start-stop"): the micro
//! time is the last ADC channel minus the ADC value, as the header says.
//! The file header (the first record) holds the macro-time clock in 0.1 ns
//! units and the routing bits used. A `.spc` file records neither its TAC
//! range nor its module: the micro-time unit comes from the setup file
//! SPCM saves beside it (`NAME.set`, [`super::setup`]) or from the caller,
//! the layout from the caller (the SPC-130 family when unsaid).

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

use super::setup::{SetupText, check_micro_unit_ps};
use crate::events::{ChunkDecoder, Tag, TagSink};

/// Which card family wrote the records: their layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SpcModule {
    /// SPC-130/134/140/144/150/154/160/180/830, 32-bit records.
    #[default]
    Spc130,
    /// SPC-600/630 in 256-channel mode, 32-bit records.
    Spc600Channels256,
    /// SPC-600/630 in 4096-channel mode, 48-bit records.
    Spc600Channels4096,
}

crate::named::named!(SpcModule {
    Spc130 => "spc-130",
    Spc600Channels256 => "spc-600-256",
    Spc600Channels4096 => "spc-600-4096",
});

impl SpcModule {
    /// The cards whose records this layout reads, in words.
    pub fn cards(self) -> &'static str {
        match self {
            SpcModule::Spc130 => "SPC-130/140/150/160/180/830 (32-bit records)",
            SpcModule::Spc600Channels256 => "SPC-600/630, 256 channels (32-bit records)",
            SpcModule::Spc600Channels4096 => "SPC-600/630, 4096 channels (48-bit records)",
        }
    }

    /// Bytes per record (the header record included).
    pub fn record_bytes(self) -> u64 {
        match self {
            SpcModule::Spc600Channels4096 => 6,
            _ => 4,
        }
    }

    /// ADC channels: micro times run from 0 to this minus one.
    pub fn adc_channels(self) -> u32 {
        match self {
            SpcModule::Spc600Channels256 => 256,
            _ => 4096,
        }
    }

    /// Macro-time clocks per overflow.
    pub fn macro_wrap(self) -> u64 {
        match self {
            SpcModule::Spc130 => 1 << 12,
            SpcModule::Spc600Channels256 => 1 << 17,
            SpcModule::Spc600Channels4096 => 1 << 24,
        }
    }
}

/// What a `.spc` file does not record, from its caller: the card family
/// (default: the SPC-130 family) and the micro-time unit (default: from
/// the setup file beside it).
///
/// The command line's `.spc` flags are these fields (their docs are the
/// flags' help).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct SpcOptions {
    /// Layout of a Becker & Hickl .spc file's records (the file does not
    /// record its module): spc-130 (SPC-130/140/150/160/180/830, the
    /// default), spc-600-256 or spc-600-4096 (SPC-600/630).
    #[cfg_attr(feature = "cli", arg(long = "spc-module", value_name = "MODULE", value_parser = crate::named::choice::<SpcModule>()))]
    pub module: Option<SpcModule>,
    /// Micro-time unit of a .spc file (default unit ps: TAC range / TAC
    /// gain / ADC channels); default: from the SPCM setup file beside it
    /// (NAME.set).
    #[cfg_attr(feature = "cli", arg(long = "micro-unit", value_name = "TIME", value_parser = crate::units::parse_ps))]
    pub micro_unit_ps: Option<f64>,
}

impl SpcOptions {
    /// Refuses these options for `path`, a file of `format`, when they
    /// are set and it is not a `.spc` (whose header says its own layout
    /// and resolution); the one check of every reader that takes them.
    pub fn check_applies(
        &self,
        path: &Path,
        format: crate::formats::detect::Format,
    ) -> Result<(), SpcFileError> {
        match format != crate::formats::detect::Format::BeckerHicklFifo && *self != Self::default()
        {
            true => Err(SpcFileError {
                path: path.to_owned(),
                error: SpcError::Misapplied,
            }),
            false => Ok(()),
        }
    }
}

/// Why a `.spc` file cannot be read; the file is named by [`SpcFileError`].
#[derive(Debug, thiserror::Error)]
pub enum SpcError {
    /// Operating-system error.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// `.spc` options were given for another kind of file.
    #[error(
        "the .spc module and micro-time unit apply to Becker & Hickl FIFO files (.spc); this file's header says its own layout and resolution"
    )]
    Misapplied,
    /// The header record is wrong.
    #[error("header record: {0}")]
    Header(String),
    /// The file ends inside a record.
    #[error(
        "file is cut: {records} complete records, then {trailing} bytes of a partial {bytes}-byte record (a recording stopped mid-write); refused unless a truncated file is allowed"
    )]
    Truncated {
        /// Complete records read (the header record excluded).
        records: u64,
        /// Bytes after the last complete record.
        trailing: u64,
        /// Bytes per record.
        bytes: u64,
    },
    /// The micro-time unit is neither given nor in a setup file.
    #[error("{0}")]
    MicroUnit(String),
}

/// An [`SpcError`] with the file it concerns.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {error}")]
pub struct SpcFileError {
    /// The file.
    pub path: PathBuf,
    /// What went wrong.
    pub error: SpcError,
}

/// What the header record and the file's size say.
#[derive(Debug, Clone, PartialEq)]
pub struct SpcInfo {
    /// The file.
    pub path: PathBuf,
    /// The layout read.
    pub module: SpcModule,
    /// Whether the layout was the default, not the caller's.
    pub module_assumed: bool,
    /// Macro-time clock period (s).
    pub macro_clock_s: f64,
    /// Routing bits used in the measurement (0: no router).
    pub routing_bits: u8,
    /// Whether the header says the file holds markers.
    pub has_markers: bool,
    /// Micro-time unit (s), when known.
    pub micro_unit_s: Option<f64>,
    /// Where the micro-time unit came from, in words.
    pub micro_unit_from: String,
    /// Complete records after the header record.
    pub records_present: u64,
    /// Bytes after the last complete record.
    pub trailing_bytes: u64,
}

impl SpcInfo {
    /// The header in words, one line each (what `info` prints first).
    pub fn describe(&self) -> Vec<String> {
        vec![
            format!("file: {}", self.path.display()),
            format!(
                "container: Becker & Hickl FIFO (.spc); layout: {}{}",
                self.module.cards(),
                if self.module_assumed {
                    " (assumed: a .spc file does not record its module; SPC-600/630 files need --spc-module)"
                } else {
                    ""
                }
            ),
            format!(
                "macro-time clock: {:.3} ns; routing bits: {}; markers: {}",
                self.macro_clock_s * 1e9,
                self.routing_bits,
                if self.has_markers { "yes" } else { "no" }
            ),
            match self.micro_unit_s {
                Some(u) => format!(
                    "micro-time unit: {:.6} ps ({})",
                    u * 1e12,
                    self.micro_unit_from
                ),
                None => format!("micro-time unit: unknown ({})", self.micro_unit_from),
            },
            format!(
                "records: {} after the header{}",
                self.records_present,
                if self.trailing_bytes > 0 {
                    format!(", {} trailing bytes (cut)", self.trailing_bytes)
                } else {
                    String::new()
                }
            ),
        ]
    }

    /// The micro-time unit (s), or an error that says how to give it.
    pub fn micro_unit(&self) -> Result<f64, SpcFileError> {
        self.micro_unit_s.ok_or_else(|| SpcFileError {
            path: self.path.clone(),
            error: SpcError::MicroUnit(format!(
                "a .spc file does not record its TAC range, so its micro-time unit is unknown ({}); save the SPCM setup beside it as {} or give the unit (--micro-unit, ps: TAC range / TAC gain / {} ADC channels)",
                self.micro_unit_from,
                self.path.with_extension("set").display(),
                self.module.adc_channels()
            )),
        })
    }

    /// Refuses a cut file unless `allow_truncated`.
    pub fn check_whole(&self, allow_truncated: bool) -> Result<(), SpcFileError> {
        if self.trailing_bytes > 0 && !allow_truncated {
            return Err(SpcFileError {
                path: self.path.clone(),
                error: self.cut(),
            });
        }
        Ok(())
    }

    /// The cut, as an error.
    pub fn cut(&self) -> SpcError {
        SpcError::Truncated {
            records: self.records_present,
            trailing: self.trailing_bytes,
            bytes: self.module.record_bytes(),
        }
    }

    /// A reader of the `part`-th of `parts` consecutive ranges of the
    /// records (`0, 1`: all of them), on the file opened anew.
    pub fn records_part(&self, part: usize, parts: usize) -> Result<SpcReader, SpcFileError> {
        let bytes = self.module.record_bytes();
        // The records follow the one header record.
        let (reader, first, end) =
            crate::formats::open_part(&self.path, bytes, bytes, self.records_present, part, parts)
                .map_err(|e| SpcFileError {
                    path: self.path.clone(),
                    error: e.into(),
                })?;
        Ok(SpcReader {
            reader,
            remaining: end - first,
            bytes,
        })
    }

    /// A decoder of this file's records from time 0.
    pub fn decoder(&self) -> SpcDecoder {
        SpcDecoder::new(self.module)
    }
}

/// Reads the header record of the `.spc` file at `path` as `options`
/// say, and the micro-time unit from them or from the setup file beside
/// it.
pub fn open(path: &Path, options: &SpcOptions) -> Result<SpcInfo, SpcFileError> {
    open_inner(path, options).map_err(|error| SpcFileError {
        path: path.to_owned(),
        error,
    })
}

fn open_inner(path: &Path, options: &SpcOptions) -> Result<SpcInfo, SpcError> {
    let module = options.module.unwrap_or_default();
    let (mut file, meta) = crate::files::open_regular(path, "recording")?;
    let bytes = module.record_bytes();
    let mut head = [0u8; 6];
    let got = read_up_to(&mut file, &mut head[..bytes as usize])?;
    if (got as u64) < bytes {
        return Err(SpcError::Header(format!(
            "the file holds {got} bytes, less than the {bytes}-byte header record of the {} layout",
            module.cards()
        )));
    }
    let other = if module == SpcModule::Spc600Channels4096 {
        "spc-130 or spc-600-256"
    } else {
        "spc-600-4096"
    };
    let wrong = |what: String| {
        SpcError::Header(format!(
            "{what}: not a {} .spc file (another module's file needs --spc-module {other})",
            module.cards()
        ))
    };
    let (clock, routing_bits, has_markers) = match module {
        SpcModule::Spc600Channels4096 => {
            if head[1] & 0x10 == 0 || head[4] != 0 || head[5] != 0 {
                return Err(wrong(format!(
                    "bytes {:02X?} do not open with the header record (byte 1 bit 4 set, bytes 4-5 zero)",
                    &head[..6]
                )));
            }
            (
                u32::from(u16::from_le_bytes([head[2], head[3]])),
                head[1] & 0x0F,
                false,
            )
        }
        _ => {
            let r = u32::from_le_bytes([head[0], head[1], head[2], head[3]]);
            if r >> 31 == 0 {
                return Err(wrong(format!(
                    "0x{r:08X} is not a header record (its INVALID bit 31 is clear)"
                )));
            }
            // Byte 3 of the SPC-130 family's header: bit 2 (26) marks a
            // raw-data file, bit 1 (25) a file with markers. In the
            // SPC-600/630 256-channel layout the header's text calls bits
            // 0-2 of byte 3 reserved (its R_FILE6_32 mask says otherwise,
            // but the sample file SPCM wrote for an SPC-630,
            // `bh_spc630_256.spc`, sets bit 26 over 294,884 valid photons),
            // so neither is read there.
            let raw = module == SpcModule::Spc130 && r & (1 << 26) != 0;
            if raw {
                return Err(SpcError::Header(format!(
                    "0x{r:08X} marks a raw-data file in the SPC-130 family's layout (bit 26: SPCM's diagnostic mode), whose records carry no photons; an SPC-600/630 file in 256-channel mode, where that bit is reserved, needs --spc-module spc-600-256"
                )));
            }
            let markers = module == SpcModule::Spc130 && r & (1 << 25) != 0;
            (r & 0x00FF_FFFF, ((r >> 27) & 0xF) as u8, markers)
        }
    };
    if clock == 0 {
        return Err(wrong("its macro-time clock is 0".into()));
    }
    let body = meta.len() - bytes;
    let (micro_unit_s, micro_unit_from) = micro_unit(path, module, options)?;
    Ok(SpcInfo {
        path: path.to_owned(),
        module,
        module_assumed: options.module.is_none(),
        macro_clock_s: f64::from(clock) * 1e-10,
        routing_bits,
        has_markers,
        micro_unit_s,
        micro_unit_from,
        records_present: body / bytes,
        trailing_bytes: body % bytes,
    })
}

/// The micro-time unit (s) the caller gave, else the setup file's beside
/// `path`, and where it came from.
fn micro_unit(
    path: &Path,
    module: SpcModule,
    options: &SpcOptions,
) -> Result<(Option<f64>, String), SpcError> {
    if let Some(ps) = options.micro_unit_ps {
        let ps = check_micro_unit_ps(ps, "--micro-unit").map_err(SpcError::MicroUnit)?;
        return Ok((Some(ps * 1e-12), "given".into()));
    }
    let set = path.with_extension("set");
    if !set.is_file() {
        return Ok((None, format!("no setup file {}", set.display())));
    }
    let in_set = |e: String| SpcError::MicroUnit(format!("setup file {}: {e}", set.display()));
    let text = SetupText::read(&set).map_err(|e| in_set(e.to_string()))?;
    Ok(
        match text.micro_unit_s(module.adc_channels()).map_err(in_set)? {
            Some((unit, words)) => (Some(unit), format!("{}: {words}", set.display())),
            None => (
                None,
                format!("{} holds no positive SP_TAC_R and SP_TAC_G", set.display()),
            ),
        },
    )
}

fn read_up_to(file: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match file.read(&mut buf[got..])? {
            0 => break,
            n => got += n,
        }
    }
    Ok(got)
}

/// Streams a `.spc` file's records in chunks.
pub struct SpcReader {
    reader: BufReader<File>,
    remaining: u64,
    bytes: u64,
}

/// Records per chunk.
const CHUNK_RECORDS: usize = 1 << 20;

impl SpcReader {
    /// Reads the next chunk of records as stored into `out`; false at the
    /// end.
    fn next_stored<R: bytemuck::Pod + Default>(
        &mut self,
        out: &mut Vec<R>,
    ) -> Result<bool, SpcError> {
        debug_assert_eq!(std::mem::size_of::<R>() as u64, self.bytes);
        if self.remaining == 0 {
            out.clear();
            return Ok(false);
        }
        let n = (self.remaining as usize).min(CHUNK_RECORDS);
        crate::formats::read_records(&mut self.reader, out, n)?;
        self.remaining -= n as u64;
        Ok(true)
    }

    /// Reads the next chunk of 32-bit records into `out`; false at the end.
    pub fn next_chunk32(&mut self, out: &mut Vec<u32>) -> Result<bool, SpcError> {
        let more = self.next_stored(out)?;
        crate::formats::u32_from_le(out);
        Ok(more)
    }

    /// Reads the next chunk of 48-bit records into `out`; false at the end.
    pub fn next_chunk48(&mut self, out: &mut Vec<[u8; 6]>) -> Result<bool, SpcError> {
        self.next_stored(out)
    }
}

/// What the card flagged in the records, beside photons and markers.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct CardFlags {
    /// Records with the GAP flag: the card's FIFO was full and photons
    /// before each were lost.
    pub gaps: u64,
    /// INVALID records that are neither markers nor overflow counts: no
    /// valid routing, micro or macro time (dropped).
    pub invalid: u64,
    /// Overflow count entries (INVALID with MTOV): no event.
    pub overflow_entries: u64,
    /// Macro-time overflows in all (flags and counts).
    pub overflows: u64,
}

impl std::ops::AddAssign for CardFlags {
    fn add_assign(&mut self, o: CardFlags) {
        self.gaps += o.gaps;
        self.invalid += o.invalid;
        self.overflow_entries += o.overflow_entries;
        self.overflows += o.overflows;
    }
}

/// Stateful decoder of one layout's records, carrying the macro-time
/// base and the [`CardFlags`]; times saturate instead of wrapping.
#[derive(Debug, Clone)]
pub struct SpcDecoder {
    module: SpcModule,
    base: u64,
    /// What the records decoded so far flagged.
    pub flags: CardFlags,
}

impl SpcDecoder {
    /// A decoder for `module`'s layout from time 0.
    pub fn new(module: SpcModule) -> Self {
        Self {
            module,
            base: 0,
            flags: CardFlags::default(),
        }
    }

    #[inline(always)]
    fn overflow(&mut self, n: u64) {
        self.flags.overflows += n;
        self.base = self
            .base
            .saturating_add(self.module.macro_wrap().saturating_mul(n));
    }

    /// Decodes one 32-bit record (SPC-130 family or SPC-600/630 with 256
    /// channels); `None` for overflow counts and invalid records.
    #[inline(always)]
    pub fn decode32(&mut self, r: u32) -> Option<Tag> {
        let spc130 = self.module == SpcModule::Spc130;
        let (invalid, mtov, gap) = (r >> 31 != 0, r & (1 << 30) != 0, r & (1 << 29) != 0);
        // Only the SPC-130 family's layout has a MARK bit.
        let mark = spc130 && r & (1 << 28) != 0;
        self.flags.gaps += u64::from(gap);
        if invalid && mtov && !mark {
            self.flags.overflow_entries += 1;
            self.overflow(u64::from(r & 0x0FFF_FFFF));
            return None;
        }
        if mtov {
            self.overflow(1);
        }
        let macro_time = self.base.saturating_add(u64::from(if spc130 {
            r & 0xFFF
        } else {
            (r >> 8) & 0x1_FFFF
        }));
        if invalid {
            if mark {
                return Some(Tag::Marker {
                    bits: ((r >> 12) & 0xF) as u8,
                    macro_time,
                });
            }
            self.flags.invalid += 1;
            return None;
        }
        let (channel, micro_time) = if spc130 {
            ((r >> 12) & 0xF, 4095 - ((r >> 16) & 0xFFF))
        } else {
            ((r >> 25) & 0x7, 255 - (r & 0xFF))
        };
        Some(Tag::Photon {
            channel: channel as u16,
            macro_time,
            micro_time,
        })
    }

    /// Decodes one 48-bit record (SPC-600/630 with 4096 channels).
    #[inline(always)]
    pub fn decode48(&mut self, b: [u8; 6]) -> Option<Tag> {
        let (invalid, mtov, gap) = (b[1] & 0x10 != 0, b[1] & 0x20 != 0, b[1] & 0x40 != 0);
        self.flags.gaps += u64::from(gap);
        if mtov {
            self.overflow(1);
        }
        if invalid {
            self.flags.invalid += 1;
            return None;
        }
        let adc = u32::from(b[0]) | (u32::from(b[1] & 0x0F) << 8);
        let mt = u64::from(b[4]) | (u64::from(b[5]) << 8) | (u64::from(b[2]) << 16);
        Some(Tag::Photon {
            channel: u16::from(b[3]),
            macro_time: self.base.saturating_add(mt),
            micro_time: 4095 - adc,
        })
    }
}

impl ChunkDecoder for SpcDecoder {
    type Record = u32;

    #[inline]
    fn decode_chunk<S: TagSink>(&mut self, records: &[u32], mut sink: S) -> S {
        let mut local = self.clone();
        for &r in records {
            sink.push(local.decode32(r));
        }
        *self = local;
        sink
    }
}

/// [`SpcDecoder`] on 48-bit records.
#[derive(Debug, Clone)]
pub struct Spc48Decoder(pub SpcDecoder);

impl ChunkDecoder for Spc48Decoder {
    type Record = [u8; 6];

    #[inline]
    fn decode_chunk<S: TagSink>(&mut self, records: &[[u8; 6]], mut sink: S) -> S {
        let mut local = self.0.clone();
        for &r in records {
            sink.push(local.decode48(r));
        }
        self.0 = local;
        sink
    }
}

/// Decodes `reader`'s records (from [`SpcInfo::records_part`]) in
/// order, handing each record's tag to `each` (`None` for overflow counts
/// and invalid records), until the end, a read error or `each`'s first
/// error; returns what the records flagged.
pub fn decode_each<E: From<SpcFileError>>(
    info: &SpcInfo,
    mut reader: SpcReader,
    mut each: impl FnMut(Option<Tag>) -> Result<(), E>,
) -> Result<CardFlags, E> {
    let read_err = |error| SpcFileError {
        path: info.path.clone(),
        error,
    };
    let mut decoder = info.decoder();
    if info.module == SpcModule::Spc600Channels4096 {
        let mut chunk = Vec::new();
        while reader.next_chunk48(&mut chunk).map_err(read_err)? {
            for &r in &chunk {
                each(decoder.decode48(r))?;
            }
        }
    } else {
        let mut chunk = Vec::new();
        while reader.next_chunk32(&mut chunk).map_err(read_err)? {
            for &r in &chunk {
                each(decoder.decode32(r))?;
            }
        }
    }
    Ok(decoder.flags)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spc130_records_by_hand() {
        let mut d = SpcDecoder::new(SpcModule::Spc130);
        // Routing 3, ADC 0x123, macro time 7.
        let photon = (0x123 << 16) | (3 << 12) | 7;
        assert_eq!(
            d.decode32(photon),
            Some(Tag::Photon {
                channel: 3,
                macro_time: 7,
                micro_time: 4095 - 0x123
            })
        );
        // Three overflows counted, then one flagged on a photon with GAP.
        assert_eq!(d.decode32(0xC000_0003), None);
        assert_eq!(
            d.decode32(photon | (1 << 30) | (1 << 29)),
            Some(Tag::Photon {
                channel: 3,
                macro_time: 4 * 4096 + 7,
                micro_time: 4095 - 0x123
            })
        );
        // A line-clock marker (M[1]) and an invalid photon.
        assert_eq!(
            d.decode32(0x9000_2000 | 5),
            Some(Tag::Marker {
                bits: 2,
                macro_time: 4 * 4096 + 5
            })
        );
        assert_eq!(d.decode32(0x8000_0000 | photon), None);
        assert_eq!(
            d.flags,
            CardFlags {
                gaps: 1,
                invalid: 1,
                overflow_entries: 1,
                overflows: 4
            }
        );
    }

    #[test]
    fn spc600_records_by_hand() {
        let mut d = SpcDecoder::new(SpcModule::Spc600Channels256);
        // ADC 200, macro time 0x1_2345, routing 5.
        let photon = 200 | (0x1_2345 << 8) | (5 << 25);
        assert_eq!(
            d.decode32(photon),
            Some(Tag::Photon {
                channel: 5,
                macro_time: 0x1_2345,
                micro_time: 55
            })
        );
        let mut d = SpcDecoder::new(SpcModule::Spc600Channels4096);
        // ADC 0xABC with MTOV, macro time 0x12_3456, routing 200.
        let rec = [0xBC, 0x2A, 0x12, 200, 0x56, 0x34];
        assert_eq!(
            d.decode48(rec),
            Some(Tag::Photon {
                channel: 200,
                macro_time: (1 << 24) + 0x12_3456,
                micro_time: 4095 - 0xABC
            })
        );
    }
}
