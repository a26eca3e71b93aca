//! Legacy HydraHarp HT3/HT2 and PicoHarp PT3/PT2 files: a fixed binary
//! header (text part, measurement part, hardware part, time-tagging part,
//! image header) followed by 32-bit records. The HydraHarp layout is
//! checked against PicoQuant's sample files: records start exactly where
//! the header says, and header size plus `nRecords x 4` is the file size.
//! The PicoHarp layout (format version 2.0) follows PicoQuant's published
//! file-access demos; no sample file was at hand to check it against.

use std::io::Read;

use super::TtrError;
use super::records::RecordType;

/// What the legacy header tells.
#[derive(Debug, Clone, PartialEq)]
pub struct LegacyHeader {
    /// `FormatVersion`, e.g. `2.0`.
    pub version: String,
    /// Acquisition software and version.
    pub creator: String,
    /// Hardware identifier, e.g. `HydraHarp 400`.
    pub hardware: String,
    /// Record type implied by format version and measurement mode.
    pub record_type: RecordType,
    /// TCSPC resolution (ps).
    pub resolution_ps: f64,
    /// Base resolution of T2 time tags (ps).
    pub base_resolution_ps: f64,
    /// Sync rate (Hz).
    pub sync_rate_hz: f64,
    /// Input channels present.
    pub channels: u32,
    /// Records the header announces.
    pub records: u64,
    /// Offset of the first record.
    pub data_offset: u64,
}

struct Cursor<'a> {
    r: &'a mut dyn Read,
    offset: u64,
}

impl Cursor<'_> {
    fn bytes(&mut self, n: usize, what: &str) -> Result<Vec<u8>, TtrError> {
        let mut buf = vec![0u8; n];
        self.r.read_exact(&mut buf).map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                TtrError::header(
                    self.offset,
                    format!("file ends inside the header field {what}"),
                )
            } else {
                TtrError::Io(e)
            }
        })?;
        self.offset += n as u64;
        Ok(buf)
    }
    fn text(&mut self, n: usize, what: &str) -> Result<String, TtrError> {
        let b = self.bytes(n, what)?;
        let end = b.iter().position(|&c| c == 0).unwrap_or(n);
        Ok(b[..end]
            .iter()
            .map(|&c| c as char)
            .collect::<String>()
            .trim()
            .to_string())
    }
    /// The next `N` bytes.
    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], TtrError> {
        Ok(self.bytes(N, what)?.try_into().expect("N bytes"))
    }
    fn i32(&mut self, what: &str) -> Result<i32, TtrError> {
        self.array(what).map(i32::from_le_bytes)
    }
    fn f32(&mut self, what: &str) -> Result<f32, TtrError> {
        self.array(what).map(f32::from_le_bytes)
    }
    fn f64(&mut self, what: &str) -> Result<f64, TtrError> {
        self.array(what).map(f64::from_le_bytes)
    }
    fn i64(&mut self, what: &str) -> Result<i64, TtrError> {
        self.array(what).map(i64::from_le_bytes)
    }
    fn skip(&mut self, n: usize, what: &str) -> Result<(), TtrError> {
        self.bytes(n, what).map(|_| ())
    }
}

/// `ImgHdrSize`: the 32-bit words of the image header that follows.
fn image_header_ints(c: &mut Cursor<'_>) -> Result<i32, TtrError> {
    let at = c.offset;
    let ints = c.i32("ImgHdrSize")?;
    if !(0..=1 << 20).contains(&ints) {
        return Err(TtrError::header(
            at,
            format!("ImgHdrSize = {ints} is not plausible"),
        ));
    }
    Ok(ints)
}

/// The text part: the 16-byte ident (must be `ident`), then format version
/// and creator (name and version); file time, CRLF and comment are skipped.
fn text_part(c: &mut Cursor<'_>, ident: &str) -> Result<(String, String), TtrError> {
    let found = c.text(16, "Ident")?;
    if found != ident {
        return Err(TtrError::header(
            0,
            format!("Ident is {found:?}, expected {ident:?}"),
        ));
    }
    let version = c.text(6, "FormatVersion")?;
    let creator_name = c.text(18, "CreatorName")?;
    let creator_version = c.text(12, "CreatorVersion")?;
    c.skip(18 + 2 + 256, "FileTime, CRLF and Comment")?;
    Ok((version, format!("{creator_name} {creator_version}")))
}

/// Reads `BitsPerRecord`, which must be 32.
fn bits_per_record(c: &mut Cursor<'_>) -> Result<(), TtrError> {
    let bits = c.i32("BitsPerRecord")?;
    if bits != 32 {
        return Err(TtrError::header(
            c.offset - 4,
            format!("BitsPerRecord = {bits}, expected 32"),
        ));
    }
    Ok(())
}

/// Parses a HydraHarp HT3/HT2 header (versions 1.0 and 2.0).
pub fn parse_hydraharp(r: &mut dyn Read) -> Result<LegacyHeader, TtrError> {
    let mut c = Cursor { r, offset: 0 };
    let (version, creator) = text_part(&mut c, "HydraHarp")?;
    let _curves = c.i32("NumberOfCurves")?;
    bits_per_record(&mut c)?;
    let _active = c.i32("ActiveCurve")?;
    let mode_offset = c.offset;
    let mode = c.i32("MeasurementMode")?;
    c.skip(8, "SubMode and Binning")?;
    let resolution_ps = c.f64("Resolution")?;
    // Offset .. DispCountsTo (10 ints), DispCurves (8 x 2 ints), Params
    // (3 x 3 floats), Repeat fields (4 ints), ScriptName (20 bytes).
    c.skip(40 + 64 + 36 + 16 + 20, "display and repeat settings")?;
    let hardware = c.text(16, "HardwareIdent")?;
    c.skip(8 + 4, "HardwarePartNo and HardwareSerial")?;
    let _modules = c.i32("nModulesPresent")?;
    c.skip(80, "ModuleInfo")?;
    let base_resolution_ps = c.f64("BaseResolution")?;
    c.skip(8, "InputsEnabled")?;
    let channels_offset = c.offset;
    let channels = c.i32("InpChansPresent")?;
    if !(1..=64).contains(&channels) {
        return Err(TtrError::header(
            channels_offset,
            format!("InpChansPresent = {channels} is not plausible"),
        ));
    }
    // RefClockSource, ExtDevices, MarkerSettings, SyncDivider, SyncCFDLevel,
    // SyncCFDZeroCross, SyncOffset; then 4 ints per channel and one input
    // rate per channel.
    c.skip(28 + 20 * channels as usize, "channel settings and rates")?;
    let sync_rate = c.i32("SyncRate")?;
    c.skip(8, "StopAfter and StopReason")?;
    let img_ints = image_header_ints(&mut c)?;
    let records_offset = c.offset;
    let records = c.i64("nRecords")?;
    let records = u64::try_from(records).map_err(|_| {
        TtrError::header(records_offset, format!("nRecords = {records} is negative"))
    })?;
    c.skip(4 * img_ints as usize, "ImgHdr")?;
    let v2 = version.starts_with('2');
    let record_type = match (mode, v2) {
        (3, false) => RecordType::HydraHarpV1T3,
        (2, false) => RecordType::HydraHarpV1T2,
        (3, true) => RecordType::HydraHarpV2T3,
        (2, true) => RecordType::HydraHarpV2T2,
        _ => {
            return Err(TtrError::header(
                mode_offset,
                format!(
                    "MeasurementMode = {mode} with FormatVersion {version} is not a time-tagging mode"
                ),
            ));
        }
    };
    Ok(LegacyHeader {
        version,
        creator,
        hardware,
        record_type,
        resolution_ps,
        base_resolution_ps,
        sync_rate_hz: f64::from(sync_rate),
        channels: channels as u32,
        records,
        data_offset: c.offset,
    })
}

/// Time-tag unit of PicoHarp 300 T2 records (ps).
const PICOHARP_T2_UNIT_PS: f64 = 4.0;

/// Parses a PicoHarp 300 PT3/PT2 header (format version 2.0).
pub fn parse_picoharp(r: &mut dyn Read) -> Result<LegacyHeader, TtrError> {
    let mut c = Cursor { r, offset: 0 };
    let (version, creator) = text_part(&mut c, "PicoHarp 300")?;
    if version != "2.0" {
        return Err(TtrError::Unsupported(format!(
            "PicoHarp file format version {version:?}; only 2.0 is supported (export the data as PTU)"
        )));
    }
    let _curves = c.i32("Curves")?;
    bits_per_record(&mut c)?;
    let _routing = c.i32("RoutingChannels")?;
    let boards_offset = c.offset;
    let boards = c.i32("NumberOfBoards")?;
    if boards != 1 {
        return Err(TtrError::header(
            boards_offset,
            format!("NumberOfBoards = {boards}, expected 1"),
        ));
    }
    let _active = c.i32("ActiveCurve")?;
    let mode_offset = c.offset;
    let mode = c.i32("MeasMode")?;
    // SubMode .. DispCountTo (12 ints), DispCurves (8 x 2 ints), Params
    // (3 x 3 floats), Repeat fields (4 ints), ScriptName (20 bytes).
    c.skip(48 + 64 + 36 + 16 + 20, "display and repeat settings")?;
    let hardware = c.text(16, "HardwareIdent")?;
    c.skip(8, "HardwareVersion")?;
    // HardwareSerial, SyncDivider, CFD settings of both inputs.
    c.skip(24, "HardwareSerial, SyncDivider and CFD settings")?;
    let res_offset = c.offset;
    let resolution_ns = c.f32("Resolution")?;
    if !(resolution_ns > 0.0 && resolution_ns.is_finite()) {
        return Err(TtrError::header(
            res_offset,
            format!("Resolution = {resolution_ns} ns is not positive"),
        ));
    }
    // RouterModelCode, RouterEnabled, 4 router channels x 6 ints.
    c.skip(8 + 96, "router settings")?;
    c.skip(12, "ExtDevices and reserved fields")?;
    let sync_rate = c.i32("CntRate0")?;
    c.skip(12, "CntRate1, StopAfter and StopReason")?;
    let records_offset = c.offset;
    let records = c.i32("Records")?;
    let records = u32::try_from(records).map_err(|_| {
        TtrError::header(records_offset, format!("Records = {records} is negative"))
    })?;
    let img_ints = image_header_ints(&mut c)?;
    c.skip(4 * img_ints as usize, "ImgHdr")?;
    let record_type = match mode {
        3 => RecordType::PicoHarpT3,
        2 => RecordType::PicoHarpT2,
        _ => {
            return Err(TtrError::header(
                mode_offset,
                format!("MeasMode = {mode} is not a time-tagging mode (2 = T2, 3 = T3)"),
            ));
        }
    };
    Ok(LegacyHeader {
        version,
        creator,
        hardware,
        record_type,
        resolution_ps: f64::from(resolution_ns) * 1e3,
        base_resolution_ps: PICOHARP_T2_UNIT_PS,
        sync_rate_hz: f64::from(sync_rate),
        channels: 1,
        records: u64::from(records),
        data_offset: c.offset,
    })
}
