//! Writes PTU files that PicoQuant's software, ptufile and tttrlib open:
//! live acquisitions from PicoQuant devices stream their raw records here
//! (`acquire --device picoquant`), `convert` re-encodes recorded tags, and
//! tests build files of every record type and edge case.
//!
//! The file is written under a temporary name and renamed into place by
//! [`PtuWriter::finish`] ([`crate::files::AtomicFile`]). Its header is
//! written first with `TTResult_NumberOfRecords` 0 and the project's tag
//! [`INCOMPLETE_TAG`] true; `finish` patches in the true record count and,
//! for a run that reached its planned end, sets the tag false. So a file
//! whose writer never finished (killed, a full disk) lies under its
//! temporary name with no record count, which ptufile warns about and the
//! project's readers flag, and an interrupted acquisition is a valid file
//! whose header says it was interrupted.

use std::io::{self, BufWriter, Seek, SeekFrom, Write};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use super::ptu::{self, ty};
use super::records::{
    HYDRAHARP_V1_T2_WRAP, PICOHARP_T2_WRAP, PICOHARP_T3_WRAP, RecordType, WIDE_T2_WRAP,
    WIDE_T3_WRAP,
};
use crate::events::Imaging;
use crate::events::Tag;
use crate::files::AtomicFile;
pub use crate::files::Completion;

/// Header content of a written file.
#[derive(Debug, Clone)]
pub struct WriterHeader {
    /// Micro-time (T3) or time-tag (T2) unit, seconds.
    pub resolution_s: f64,
    /// Sync rate (Hz); the sync period is the T3 macro unit.
    pub sync_rate_hz: f64,
    /// Device name for `HW_Type`.
    pub device: String,
    /// Scan description; makes the file an imaging file (sub mode 3).
    pub imaging: Option<Imaging>,
    /// Further tags: the measurement's settings (`HWSync_Divider`,
    /// `HW_SerialNo`, ...), written after the required ones.
    pub extra: Vec<(String, HeaderEntry)>,
}

/// The value of an extra header tag.
#[derive(Debug, Clone, PartialEq)]
pub enum HeaderEntry {
    /// `tyInt8`.
    Int(i64),
    /// `tyFloat8`.
    Float(f64),
    /// `tyBool8`.
    Bool(bool),
    /// `tyAnsiString` (NUL-terminated).
    Text(String),
}

/// The project's header tag (`tyBool8`) that says a file is not the whole
/// of what its writer meant to write: true from the start, false once the
/// writer finished a complete run. PicoQuant's software ignores tags it
/// does not know.
pub const INCOMPLETE_TAG: &str = "Scatterscope_Incomplete";

/// Tags the writer always writes itself, never copied from another file:
/// the record count and the incomplete mark it patches, and the end.
pub const OWN_TAGS: [&str; 3] = ["TTResult_NumberOfRecords", INCOMPLETE_TAG, "Header_End"];

/// Streams tags into a PTU file, inserting overflow records as needed.
pub struct PtuWriter {
    out: BufWriter<AtomicFile>,
    record_type: RecordType,
    base: u64,
    records: u64,
    count_offset: u64,
    incomplete_offset: u64,
    max_records: u64,
}

/// `text` NUL-terminated and padded with NULs to a multiple of 8 bytes, as
/// PicoQuant's software writes strings (readers such as ptufile expect
/// every tag to start 8-byte aligned).
fn padded(text: &str) -> Vec<u8> {
    let mut bytes = text.as_bytes().to_vec();
    bytes.push(0);
    bytes.resize(bytes.len().div_ceil(8) * 8, 0);
    bytes
}

fn invalid(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg)
}

impl PtuWriter {
    /// Starts `path` (a derived file, such as a conversion: removed if the
    /// writer is dropped unfinished) and writes the header.
    pub fn create(path: &Path, record_type: RecordType, h: &WriterHeader) -> io::Result<Self> {
        Self::start(AtomicFile::create(path)?, record_type, h, &[])
    }

    /// [`Self::create`] whose header starts with `copied`, tags of another
    /// file copied byte for byte (a conversion keeps its input's header at
    /// full precision); the writer's own tags of the same name are left
    /// out, except those it must own ([`OWN_TAGS`]).
    pub fn create_copying(
        path: &Path,
        record_type: RecordType,
        h: &WriterHeader,
        copied: &[ptu::HeaderTag],
    ) -> io::Result<Self> {
        Self::start(AtomicFile::create(path)?, record_type, h, copied)
    }

    /// Starts `path` for a live recording (kept under its temporary name if
    /// the writer is dropped unfinished: its photons were read once) and
    /// writes the header.
    pub fn create_recording(
        path: &Path,
        record_type: RecordType,
        h: &WriterHeader,
    ) -> io::Result<Self> {
        Self::start(AtomicFile::create_recording(path)?, record_type, h, &[])
    }

    fn start(
        file: AtomicFile,
        record_type: RecordType,
        h: &WriterHeader,
        copied: &[ptu::HeaderTag],
    ) -> io::Result<Self> {
        let mut out = BufWriter::with_capacity(1 << 20, file);
        out.write_all(ptu::MAGIC)?;
        out.write_all(b"1.0.00\0\0")?;
        let mut pos = 16u64;
        let copied: Vec<&ptu::HeaderTag> = copied
            .iter()
            .filter(|t| !OWN_TAGS.contains(&t.ident.as_str()))
            .collect();
        for t in &copied {
            out.write_all(&t.raw)?;
            pos += t.raw.len() as u64;
        }
        let mut tag = |out: &mut BufWriter<AtomicFile>,
                       ident: &str,
                       typ: u32,
                       value: [u8; 8],
                       payload: &[u8]|
         -> io::Result<u64> {
            if copied.iter().any(|t| t.ident == ident) {
                return Ok(0);
            }
            let mut name = [0u8; 32];
            name[..ident.len()].copy_from_slice(ident.as_bytes());
            out.write_all(&name)?;
            out.write_all(&(-1i32).to_le_bytes())?;
            out.write_all(&typ.to_le_bytes())?;
            let value_at = pos + 40;
            out.write_all(&value)?;
            out.write_all(payload)?;
            pos += 48 + payload.len() as u64;
            Ok(value_at)
        };
        let int = |v: i64| v.to_le_bytes();
        let float = |v: f64| v.to_le_bytes();
        let device = padded(&h.device);
        tag(
            &mut out,
            "HW_Type",
            ty::ANSI_STRING,
            int(device.len() as i64),
            &device,
        )?;
        tag(
            &mut out,
            "TTResultFormat_TTTRRecType",
            ty::INT8,
            int(i64::from(record_type.code())),
            &[],
        )?;
        tag(
            &mut out,
            "TTResultFormat_BitsPerRecord",
            ty::INT8,
            int(32),
            &[],
        )?;
        tag(
            &mut out,
            "Measurement_Mode",
            ty::INT8,
            int(if record_type.is_t3() { 3 } else { 2 }),
            &[],
        )?;
        tag(
            &mut out,
            "MeasDesc_Resolution",
            ty::FLOAT8,
            float(h.resolution_s),
            &[],
        )?;
        let global = if record_type.is_t3() {
            1.0 / h.sync_rate_hz
        } else {
            h.resolution_s
        };
        tag(
            &mut out,
            "MeasDesc_GlobalResolution",
            ty::FLOAT8,
            float(global),
            &[],
        )?;
        tag(
            &mut out,
            "TTResult_SyncRate",
            ty::INT8,
            int(h.sync_rate_hz.round() as i64),
            &[],
        )?;
        tag(
            &mut out,
            "Measurement_SubMode",
            ty::INT8,
            int(if h.imaging.is_some() { 3 } else { 0 }),
            &[],
        )?;
        if let Some(img) = &h.imaging {
            let bit = |mask: u8| i64::from(mask.trailing_zeros() + 1);
            // Image files say they hold an image: PicoQuant's snAPI demo
            // for image measurements tags its file `ImgHdr_Dimensions` 3
            // (1 a point, 2 a line, 3 an image, 4 a stack), and ptufile
            // reads a file as an image only with it. A caller's own tag of
            // that name (the live recordings') is written instead.
            if !h
                .extra
                .iter()
                .any(|(ident, _)| ident == "ImgHdr_Dimensions")
            {
                tag(&mut out, "ImgHdr_Dimensions", ty::INT8, int(3), &[])?;
            }
            tag(
                &mut out,
                "ImgHdr_PixX",
                ty::INT8,
                int(img.pixels_x as i64),
                &[],
            )?;
            tag(
                &mut out,
                "ImgHdr_PixY",
                ty::INT8,
                int(img.pixels_y as i64),
                &[],
            )?;
            tag(
                &mut out,
                "ImgHdr_LineStart",
                ty::INT8,
                int(bit(img.line_start)),
                &[],
            )?;
            tag(
                &mut out,
                "ImgHdr_LineStop",
                ty::INT8,
                int(bit(img.line_stop)),
                &[],
            )?;
            if img.frame != 0 {
                tag(&mut out, "ImgHdr_Frame", ty::INT8, int(bit(img.frame)), &[])?;
            }
            tag(
                &mut out,
                "ImgHdr_BiDirect",
                ty::BOOL8,
                int(i64::from(img.bidirectional)),
                &[],
            )?;
        }
        for (ident, entry) in &h.extra {
            if ident.is_empty() || ident.len() > 31 {
                return Err(invalid(format!(
                    "header tag name `{ident}` must be 1 to 31 bytes"
                )));
            }
            match entry {
                HeaderEntry::Int(v) => tag(&mut out, ident, ty::INT8, int(*v), &[])?,
                HeaderEntry::Float(v) => tag(&mut out, ident, ty::FLOAT8, float(*v), &[])?,
                HeaderEntry::Bool(v) => tag(&mut out, ident, ty::BOOL8, int(i64::from(*v)), &[])?,
                HeaderEntry::Text(t) => {
                    let bytes = padded(t);
                    tag(
                        &mut out,
                        ident,
                        ty::ANSI_STRING,
                        int(bytes.len() as i64),
                        &bytes,
                    )?
                }
            };
        }
        let incomplete_offset = tag(&mut out, INCOMPLETE_TAG, ty::BOOL8, int(1), &[])?;
        let count_offset = tag(&mut out, "TTResult_NumberOfRecords", ty::INT8, int(0), &[])?;
        tag(&mut out, "Header_End", ty::EMPTY8, int(0), &[])?;
        Ok(Self {
            out,
            record_type,
            base: 0,
            records: 0,
            count_offset,
            incomplete_offset,
            max_records: u64::MAX,
        })
    }

    /// Refuses, before writing them, records past `max` in all (a time
    /// jump whose overflow records would fill the disk is then an error,
    /// not a file that grows until the disk is full).
    pub fn limit_records(&mut self, max: u64) {
        self.max_records = max;
    }

    /// Overflow records this record type needs to advance its time base
    /// by `delta` (at most; the time tags' own bits take the rest).
    pub fn overflow_records_for(record_type: RecordType, delta: u64) -> u64 {
        match record_type {
            RecordType::PicoHarpT3 => delta / PICOHARP_T3_WRAP,
            RecordType::PicoHarpT2 => delta / PICOHARP_T2_WRAP,
            RecordType::HydraHarpV1T3 => delta / WIDE_T3_WRAP,
            RecordType::HydraHarpV1T2 => delta / HYDRAHARP_V1_T2_WRAP,
            t if t.is_t3() => (delta / WIDE_T3_WRAP).div_ceil(1023),
            _ => (delta / WIDE_T2_WRAP).div_ceil((1 << 25) - 1),
        }
    }

    /// Writes one raw record (for malformed-file tests).
    pub fn write_raw(&mut self, rec: u32) -> io::Result<()> {
        self.records += 1;
        self.out.write_all(&rec.to_le_bytes())
    }

    /// Writes records exactly as a device of this file's record type sent
    /// them (a FIFO read): the overflow records are theirs, so the writer's
    /// own time base no longer applies and [`Self::write_tag`] must not be
    /// mixed in after it.
    pub fn write_records(&mut self, records: &[u32]) -> io::Result<()> {
        self.records += records.len() as u64;
        if cfg!(target_endian = "little") {
            self.out.write_all(bytemuck::cast_slice(records))
        } else {
            records
                .iter()
                .try_for_each(|r| self.out.write_all(&r.to_le_bytes()))
        }
    }

    /// Records written so far.
    pub fn records(&self) -> u64 {
        self.records
    }

    fn advance_to(&mut self, time: u64, stop: &AtomicBool) -> io::Result<u64> {
        if time < self.base {
            return Err(invalid(format!(
                "time {time} is before the previous record's time base {}",
                self.base
            )));
        }
        let needed = Self::overflow_records_for(self.record_type, time - self.base);
        if self.records.saturating_add(needed) >= self.max_records {
            return Err(io::Error::new(
                io::ErrorKind::StorageFull,
                format!(
                    "a jump of {} time units would need {needed} overflow records after the {} written, past the {} the output's disk holds",
                    time - self.base,
                    self.records,
                    self.max_records
                ),
            ));
        }
        let special = |ch: u32| (1u32 << 31) | (ch << 25);
        let mut written = 0u64;
        loop {
            // One jump may take millions of overflow records: `stop` is
            // heeded between them.
            written += 1;
            if written.is_multiple_of(1 << 20) && stop.load(Ordering::Relaxed) {
                return Err(io::Error::new(
                    io::ErrorKind::Interrupted,
                    "stopped while writing overflow records",
                ));
            }
            let delta = time - self.base;
            match self.record_type {
                RecordType::PicoHarpT3 if delta >= PICOHARP_T3_WRAP => {
                    self.write_raw(15 << 28)?;
                    self.base += PICOHARP_T3_WRAP;
                }
                RecordType::PicoHarpT2 if delta >= PICOHARP_T2_WRAP => {
                    self.write_raw(15 << 28)?;
                    self.base += PICOHARP_T2_WRAP;
                }
                RecordType::HydraHarpV1T3 if delta >= WIDE_T3_WRAP => {
                    self.write_raw(special(63) | 1)?;
                    self.base += WIDE_T3_WRAP;
                }
                RecordType::HydraHarpV1T2 if delta >= HYDRAHARP_V1_T2_WRAP => {
                    self.write_raw(special(63))?;
                    self.base += HYDRAHARP_V1_T2_WRAP;
                }
                t if t.is_t3()
                    && !matches!(t, RecordType::PicoHarpT3 | RecordType::HydraHarpV1T3)
                    && delta >= WIDE_T3_WRAP =>
                {
                    let n = (delta / WIDE_T3_WRAP).min(1023);
                    self.write_raw(special(63) | n as u32)?;
                    self.base += n * WIDE_T3_WRAP;
                }
                t if !t.is_t3()
                    && !matches!(t, RecordType::PicoHarpT2 | RecordType::HydraHarpV1T2)
                    && delta >= WIDE_T2_WRAP =>
                {
                    let n = (delta / WIDE_T2_WRAP).min((1 << 25) - 1);
                    self.write_raw(special(63) | n as u32)?;
                    self.base += n * WIDE_T2_WRAP;
                }
                _ => return Ok(delta),
            }
        }
    }

    /// Writes one tag; tags must come in non-decreasing macro time.
    pub fn write_tag(&mut self, tag: Tag) -> io::Result<()> {
        static NEVER: AtomicBool = AtomicBool::new(false);
        self.write_tag_until(tag, &NEVER)
    }

    /// [`Self::write_tag`] that ends with an `Interrupted` error once
    /// `stop` is set while it writes the overflow records before the tag
    /// (a jump in time can take millions).
    pub fn write_tag_until(&mut self, tag: Tag, stop: &AtomicBool) -> io::Result<()> {
        let rt = self.record_type;
        let pico = matches!(rt, RecordType::PicoHarpT3 | RecordType::PicoHarpT2);
        let rec = match tag {
            Tag::Photon {
                channel,
                macro_time,
                micro_time,
            } => {
                // PicoHarp T3 routing channels count from 1 (channel 0 is
                // record 1); 15 is special.
                let max_channel = match rt {
                    RecordType::PicoHarpT3 => 13,
                    RecordType::PicoHarpT2 => 14,
                    _ => 62,
                };
                if channel > max_channel {
                    return Err(invalid(format!(
                        "channel {channel} exceeds {max_channel} for {}",
                        rt.name()
                    )));
                }
                let max_micro = match rt {
                    RecordType::PicoHarpT3 => 0xFFF,
                    t if t.is_t3() => 0x7FFF,
                    _ => 0,
                };
                if micro_time > max_micro {
                    return Err(invalid(format!(
                        "micro time {micro_time} exceeds {max_micro} for {}",
                        rt.name()
                    )));
                }
                let d = self.advance_to(macro_time, stop)? as u32;
                let ch = u32::from(channel);
                match rt {
                    RecordType::PicoHarpT3 => ((ch + 1) << 28) | (micro_time << 16) | d,
                    RecordType::PicoHarpT2 => (ch << 28) | d,
                    t if t.is_t3() => (ch << 25) | (micro_time << 10) | d,
                    _ => (ch << 25) | d,
                }
            }
            Tag::Marker { bits, macro_time } => {
                if bits == 0 || bits > 15 {
                    return Err(invalid(format!("marker bits {bits} must be 1 to 15")));
                }
                let b = u32::from(bits);
                match rt {
                    RecordType::PicoHarpT3 => {
                        let d = self.advance_to(macro_time, stop)? as u32;
                        (15 << 28) | (b << 16) | d
                    }
                    RecordType::PicoHarpT2 => {
                        // The low 4 time bits carry the markers.
                        let d = self.advance_to(macro_time, stop)? as u32;
                        (15 << 28) | (d & !0xF) | b
                    }
                    _ => {
                        let d = self.advance_to(macro_time, stop)? as u32;
                        (1 << 31) | (b << 25) | d
                    }
                }
            }
            Tag::Sync { macro_time } => {
                if rt.is_t3() || pico {
                    return Err(invalid(format!(
                        "{} records have no sync events",
                        rt.name()
                    )));
                }
                let d = self.advance_to(macro_time, stop)? as u32;
                1 << 31 | d
            }
        };
        self.write_raw(rec)
    }

    /// Patches the record count into the header and closes the file,
    /// renaming it into place; returns the number of records written.
    pub fn finish(self) -> io::Result<u64> {
        self.finish_as(Completion::Complete)
    }

    /// [`Self::finish`] for a run that ended as `completion` says; an
    /// interrupted run keeps [`INCOMPLETE_TAG`] true.
    pub fn finish_as(self, completion: Completion) -> io::Result<u64> {
        let records = self.records;
        let mut file = self.out.into_inner().map_err(|e| e.into_error())?;
        file.seek(SeekFrom::Start(self.count_offset))?;
        file.write_all(&(records as i64).to_le_bytes())?;
        if completion == Completion::Complete {
            file.seek(SeekFrom::Start(self.incomplete_offset))?;
            file.write_all(&0i64.to_le_bytes())?;
        }
        file.commit()?;
        Ok(records)
    }
}

/// Writes a synthetic Generic (MultiHarp) T3 file of `records` photons for
/// benchmarks and reader comparisons: 4 ps resolution, 80 MHz sync, four
/// channels, micro times uniform over the 3125-step period, about one
/// photon per 20 syncs (an overflow record every ~50 photons). The content
/// is fixed (xorshift from a constant seed).
pub fn write_synthetic_t3(path: &Path, records: u64) -> io::Result<()> {
    let h = WriterHeader {
        resolution_s: 4e-12,
        sync_rate_hz: 80e6,
        device: "scatterscope synthetic".into(),
        imaging: None,
        extra: Vec::new(),
    };
    let mut w = PtuWriter::create(path, RecordType::GenericT3, &h)?;
    let mut t = 0u64;
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    for _ in 0..records {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        t += state % 40;
        w.write_tag(Tag::Photon {
            channel: (state >> 40) as u16 % 4,
            macro_time: t,
            micro_time: (state >> 20) as u32 % 3125,
        })?;
    }
    w.finish().map(|_| ())
}

/// Writes a synthetic FLIM image file (Generic T3, sub mode 3) for reader
/// comparisons: a `side` x `side` unidirectional scan of two frames, line
/// start, line stop and frame markers 1, 2 and 3, 10 us per pixel, 100 ps
/// resolution and an 80 MHz sync (125 micro-time steps per period), about
/// `photons` photons in all on one channel. A bright disc on a dimmer
/// background; micro times decay exponentially (2.5 ns) from step 10,
/// wrapping at the period. The content is fixed (xorshift from a constant
/// seed).
pub fn write_synthetic_flim(path: &Path, side: usize, photons: u64) -> io::Result<()> {
    const SYNCS_PER_PIXEL: u64 = 800;
    const RETRACE_SYNCS: u64 = 20_000;
    const FRAMES: u64 = 2;
    let h = WriterHeader {
        resolution_s: 100e-12,
        sync_rate_hz: 80e6,
        device: "scatterscope synthetic FLIM".into(),
        imaging: Some(Imaging {
            pixels_x: side,
            pixels_y: side,
            line_start: 1,
            line_stop: 2,
            frame: 4,
            bidirectional: false,
        }),
        extra: Vec::new(),
    };
    let mut w = PtuWriter::create(path, RecordType::GenericT3, &h)?;
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let pixels = (side * side) as f64 * FRAMES as f64;
    // Mean photons per pixel of the background; the disc is four times as
    // bright and covers about a quarter of the image.
    let background = photons as f64 / pixels / (0.75 + 4.0 * 0.25);
    let line_syncs = side as u64 * SYNCS_PER_PIXEL;
    let mut t = 1_000u64;
    for _ in 0..FRAMES {
        w.write_tag(Tag::Marker {
            bits: 4,
            macro_time: t,
        })?;
        for y in 0..side {
            t += RETRACE_SYNCS;
            w.write_tag(Tag::Marker {
                bits: 1,
                macro_time: t,
            })?;
            for x in 0..side {
                let (dx, dy) = (x as f64 / side as f64 - 0.5, y as f64 / side as f64 - 0.5);
                let disc = dx * dx + dy * dy < 0.25 / std::f64::consts::PI;
                let mean = background * if disc { 4.0 } else { 1.0 };
                // Poisson count by inversion (means are a few photons).
                let (mut n, mut p, u) = (0u64, (-mean).exp(), uniform());
                let mut cdf = p;
                while u > cdf && n < 1_000 {
                    n += 1;
                    p *= mean / n as f64;
                    cdf += p;
                }
                let mut times: Vec<u64> = (0..n)
                    .map(|_| {
                        t + x as u64 * SYNCS_PER_PIXEL + (uniform() * SYNCS_PER_PIXEL as f64) as u64
                    })
                    .collect();
                times.sort_unstable();
                for macro_time in times {
                    let delay = 10.0 - 25.0 * (1.0 - uniform()).ln();
                    w.write_tag(Tag::Photon {
                        channel: 0,
                        macro_time,
                        micro_time: delay as u32 % 125,
                    })?;
                }
            }
            t += line_syncs;
            w.write_tag(Tag::Marker {
                bits: 2,
                macro_time: t,
            })?;
        }
    }
    w.finish().map(|_| ())
}
