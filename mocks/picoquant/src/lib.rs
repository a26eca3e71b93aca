//! A stand-in for PicoQuant's programming libraries (MHLib for MultiHarp,
//! HHLib v3 for HydraHarp 400, TH260Lib 3.1 for TimeHarp 260 Pico and
//! Nano, PH330Lib 2.0 for PicoHarp 330, PHLib 3.0 for PicoHarp 300): a
//! shared
//! library exporting the C functions `scatterscope_drivers::picoquant`
//! calls, with every family's prefix, so that the
//! driver, the acquisition and the tests go through the same run-time
//! loader as with the vendor's library. Not the vendor's code: its
//! behaviour follows the published API (the vendor's demos), with T3
//! records sampled from the ST-PSF of a built-in scene, overflow records,
//! line and frame markers for scans, dark counts, pacing at the photon rate
//! and fault modes ([`config`] says how to choose them).

#![allow(non_snake_case, clippy::missing_safety_doc)]

pub mod config;
pub mod pool;

use std::ffi::{c_char, c_double, c_int, c_uint};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

use config::{Fault, MockConfig};
use pool::{Pool, Records};

const MAX_DEVICES: usize = 8;
const FLAG_FIFO_FULL: c_int = 0x0002;
/// PHLib's `FLAG_FIFOFULL` (phdefin.h): two bits where the others have one.
const FLAG_FIFO_FULL_PH300: c_int = 0x0003;
/// `FLAG_ACTIVE` ("measurement is running", hhdefin.h); th260defin.h has
/// no such flag (its 0x0020 is `FLAG_SOFTERROR`), phdefin.h neither.
const FLAG_ACTIVE: c_int = 0x0020;
/// MHLib's "counts were dropped" flag (mhdefin.h).
const FLAG_CNTS_DROPPED: c_int = 0x0040;
/// TH260Lib's dropped-events flag (th260defin.h `FLAG_EVTS_DROPPED`).
const FLAG_EVTS_DROPPED_TH260: c_int = 0x0008;
/// `WARNING_INPT_RATE_RATIO` (hhdefin.h, th260defin.h): an input rate
/// above 5 % of the sync rate, the pile-up criterion (0x0040 is
/// `WARNING_INPT_RATE_TOO_HIGH`).
const WARNING_INPUT_RATE_RATIO: c_int = 0x0100;

/// Error codes: the vendor's numbers (errorcodes.h of MHLib 2.0 and HHLib
/// 3.0 agree on these), except [`code::CONFIG`], which is the stand-in's.
pub mod code {
    /// `ERROR_DEVICE_OPEN_FAIL`: no device at this index.
    pub const DEVICE_OPEN_FAIL: i32 = -1;
    /// `ERROR_DEVICE_NOT_OPEN`.
    pub const DEVICE_NOT_OPEN: i32 = -10;
    /// `ERROR_INVALID_ARGUMENT`: an argument out of range.
    pub const INVALID_ARGUMENT: i32 = -17;
    /// `ERROR_NOT_INITIALIZED`: opened but not initialised.
    pub const NOT_INITIALIZED: i32 = -22;
    /// `ERROR_USB_VCMD_FAIL`: a USB command failed (fault `vanish`).
    pub const DEVICE_LOST: i32 = -36;
    /// `ERROR_USB_BULKRD_FAIL`: a FIFO read failed (fault `error`).
    pub const READ_FAIL: i32 = -37;
    /// `TH260_ERROR_UNSUPPORTED_FUNCTION` (TH260Lib's errorcodes.h): the
    /// stand-in's answer to a Pico-only call on a Nano or the reverse
    /// (which code the vendor's library gives there its header does not
    /// say).
    pub const UNSUPPORTED_FUNCTION: i32 = -80;
    /// The stand-in's own: `SCATTERSCOPE_PQ_MOCK` could not be read.
    pub const CONFIG: i32 = -99;
}

/// Which library's functions were called.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Family {
    MultiHarp,
    HydraHarp,
    TimeHarp260,
    PicoHarp330,
    PicoHarp300,
}

impl Family {
    /// Base resolution, ps. The TimeHarp 260's are the boards' published
    /// 25 ps (Pico) and 250 ps (Nano); no file of either is at hand.
    fn base_resolution_ps(self, config: &MockConfig) -> f64 {
        match self {
            Family::MultiHarp => 5.0,
            Family::HydraHarp | Family::PicoHarp330 => 1.0,
            Family::TimeHarp260 if config.th260_nano => 250.0,
            Family::TimeHarp260 => 25.0,
            // The PicoHarp 300's published 4 ps.
            Family::PicoHarp300 => 4.0,
        }
    }

    /// `MAXINPCHAN`: 2 in th260defin.h; the stand-in's other devices have
    /// 4; a PicoHarp 300 has one input besides its sync (channel 1 of
    /// `PH_SetInputCFD`).
    fn inputs(self) -> c_int {
        match self {
            Family::TimeHarp260 => 2,
            Family::PicoHarp300 => 1,
            _ => 4,
        }
    }

    /// The flag by which the family says it dropped counts (none in
    /// phdefin.h).
    fn dropped_flag(self) -> c_int {
        match self {
            Family::TimeHarp260 => FLAG_EVTS_DROPPED_TH260,
            Family::PicoHarp300 => 0,
            _ => FLAG_CNTS_DROPPED,
        }
    }

    /// The flags an overrun sets.
    fn fifo_full_flag(self) -> c_int {
        match self {
            Family::PicoHarp300 => FLAG_FIFO_FULL_PH300,
            _ => FLAG_FIFO_FULL,
        }
    }

    /// The flag bits `GetFlags` reports: phdefin.h and th260defin.h
    /// define no "active" flag.
    fn reported_flags(self, flags: c_int) -> c_int {
        match self {
            Family::PicoHarp300 | Family::TimeHarp260 => flags & !FLAG_ACTIVE,
            _ => flags,
        }
    }

    /// Binning steps (`GetBaseResolution`'s `binsteps`): `BINSTEPSMAX` 8
    /// in phdefin.h, `MAXBINSTEPS` 22 in th260defin.h; 24 for the others
    /// here.
    fn binning_steps(self) -> c_int {
        match self {
            Family::PicoHarp300 => 8,
            Family::TimeHarp260 => 22,
            _ => 24,
        }
    }

    /// `SetOffset`'s unit (ps) and range in it: picoseconds, 0 to
    /// 1 000 000 000, in phdefin.h (`OFFSETMIN`/`OFFSETMAX`); nanoseconds,
    /// 0 to 100 000 000, in mhdefin.h and th260defin.h (the PicoHarp 330
    /// here alike); 0 to 500 000 in hhdefin.h (`OFFSETMAX`).
    fn offset_unit_and_range(self) -> (i64, c_int) {
        match self {
            Family::PicoHarp300 => (1, 1_000_000_000),
            Family::HydraHarp => (1000, 500_000),
            _ => (1000, 100_000_000),
        }
    }

    /// The T3 records the FIFO delivers.
    fn records(self) -> Records {
        match self {
            Family::PicoHarp300 => Records::PicoHarp,
            _ => Records::Wide,
        }
    }

    /// The model `GetHardwareInfo` reports (th260defin.h's `HWIDENT_PICO`
    /// and `HWIDENT_NANO` for the TimeHarp 260).
    fn model(self, config: &MockConfig) -> &'static str {
        match self {
            Family::MultiHarp => "MultiHarp 150",
            Family::HydraHarp => "HydraHarp 400",
            Family::TimeHarp260 if config.th260_nano => "TimeHarp 260 N",
            Family::TimeHarp260 => "TimeHarp 260 P",
            Family::PicoHarp330 => "PicoHarp 330",
            Family::PicoHarp300 => "PicoHarp 300",
        }
    }

    /// `TTREADMAX`.
    fn read_max(self) -> usize {
        match self {
            Family::MultiHarp | Family::PicoHarp330 => 1_048_576,
            Family::HydraHarp | Family::TimeHarp260 | Family::PicoHarp300 => 131_072,
        }
    }

    /// `SYNCDIVMAX`: 16 in mhdefin.h and hhdefin.h, 8 in th260defin.h,
    /// ph330defin.h and phdefin.h.
    fn sync_divider_max(self) -> c_int {
        match self {
            Family::TimeHarp260 | Family::PicoHarp330 | Family::PicoHarp300 => 8,
            _ => 16,
        }
    }

    /// Whether only powers of two divide the sync (the TimeHarp 260,
    /// PicoHarp 330 and PicoHarp 300 manuals list 1, 2, 4 and 8).
    fn sync_divider_powers_of_two(self) -> bool {
        matches!(
            self,
            Family::TimeHarp260 | Family::PicoHarp330 | Family::PicoHarp300
        )
    }
}

/// A running measurement.
struct Measurement {
    pool: Arc<Pool>,
    started: Instant,
    end_syncs: u64,
    pos: usize,
    replays: u64,
    delivered: u64,
    photons: u64,
    markers: u64,
    pixel_counts: Vec<u64>,
    ended: bool,
    truth_written: bool,
    /// The T3 offset the device was set to (ps).
    offset_ps: i64,
    /// The marker edges set, and the inputs enabled, at the start.
    marker_edges: Option<[c_int; 4]>,
    inputs_enabled: [Option<bool>; 4],
}

#[derive(Default)]
struct Device {
    open: bool,
    initialized: bool,
    gone: bool,
    family: Option<Family>,
    binning: i32,
    sync_divider: i32,
    offset_ps: i64,
    /// Marker edges as set (`None`: never set).
    marker_edges: Option<[c_int; 4]>,
    /// Each input's enable as set (`None`: never set).
    inputs_enabled: [Option<bool>; 4],
    flags: c_int,
    pool: Option<(f64, Records, Arc<Pool>)>,
    measurement: Option<Measurement>,
}

struct State {
    config: Result<MockConfig, String>,
    devices: Vec<Device>,
}

static STATE: Mutex<Option<State>> = Mutex::new(None);

fn state() -> MutexGuard<'static, Option<State>> {
    let mut guard = STATE.lock().unwrap_or_else(|p| p.into_inner());
    if guard.is_none() {
        *guard = Some(State {
            config: MockConfig::from_env(),
            devices: (0..MAX_DEVICES).map(|_| Device::default()).collect(),
        });
    }
    guard
}

/// Runs `f` on device `index` with the configuration, or returns the
/// error code.
fn with_device(index: c_int, f: impl FnOnce(&mut Device, &MockConfig) -> c_int) -> c_int {
    let mut guard = state();
    let st = guard.as_mut().expect("initialised by state()");
    let config = match &st.config {
        Ok(c) => c.clone(),
        Err(e) => {
            eprintln!("{e}");
            return code::CONFIG;
        }
    };
    let Some(dev) = usize::try_from(index)
        .ok()
        .filter(|&i| i < config.devices.min(MAX_DEVICES))
        .and_then(|i| st.devices.get_mut(i))
    else {
        return code::DEVICE_OPEN_FAIL;
    };
    if dev.gone {
        return code::DEVICE_LOST;
    }
    f(dev, &config)
}

/// Like [`with_device`] for a device that must be initialised.
fn with_ready(index: c_int, f: impl FnOnce(&mut Device, &MockConfig) -> c_int) -> c_int {
    with_device(index, |d, c| {
        if !d.open {
            code::DEVICE_NOT_OPEN
        } else if !d.initialized {
            code::NOT_INITIALIZED
        } else {
            f(d, c)
        }
    })
}

/// Writes `s` NUL-terminated into `out`, at most `cap` bytes in all.
unsafe fn write_str(out: *mut c_char, s: &str, cap: usize) {
    if out.is_null() {
        return;
    }
    let bytes = &s.as_bytes()[..s.len().min(cap - 1)];
    // SAFETY: the caller's buffer holds `cap` bytes (the vendor header's size).
    unsafe {
        std::ptr::copy_nonoverlapping(bytes.as_ptr(), out.cast::<u8>(), bytes.len());
        *out.add(bytes.len()) = 0;
    }
}

unsafe fn put<T>(out: *mut T, v: T) -> c_int {
    if out.is_null() {
        return code::INVALID_ARGUMENT;
    }
    // SAFETY: a non-null out-pointer from the caller.
    unsafe { *out = v };
    0
}

fn error_text(code: c_int) -> &'static str {
    match code {
        // The header's symbols, as the text (the vendor's own strings are
        // not published in its headers).
        code::DEVICE_OPEN_FAIL => "ERROR_DEVICE_OPEN_FAIL",
        code::DEVICE_NOT_OPEN => "ERROR_DEVICE_NOT_OPEN",
        code::INVALID_ARGUMENT => "ERROR_INVALID_ARGUMENT",
        code::NOT_INITIALIZED => "ERROR_NOT_INITIALIZED",
        code::READ_FAIL => "ERROR_USB_BULKRD_FAIL",
        code::UNSUPPORTED_FUNCTION => "ERROR_UNSUPPORTED_FUNCTION",
        code::DEVICE_LOST => "ERROR_USB_VCMD_FAIL",
        code::CONFIG => "SCATTERSCOPE_PQ_MOCK invalid",
        _ => "unknown error",
    }
}

fn serial(index: c_int) -> String {
    format!("{:07}", 1_000_001 + index)
}

/// The period the records refer to: one laser period, whatever the sync
/// divider. PicoQuant's own `v20_t3.ptu` (HydraHarp, `HWSync_Divider` 8)
/// holds `TTResult_SyncRate` 4 999 960 Hz with `MeasDesc_GlobalResolution`
/// its inverse, its last nsync times 200 ns equals its 10 s acquisition
/// time, and its largest dtime is one undivided period: the divider thins
/// what the hardware's sync input sees, not the records' time base.
fn sync_period_ps(config: &MockConfig) -> f64 {
    1e12 / config.sync_hz
}

fn resolution_ps(dev: &Device, config: &MockConfig) -> f64 {
    dev.family.map_or(1.0, |f| f.base_resolution_ps(config)) * f64::from(1u32 << dev.binning)
}

fn write_truth(m: &mut Measurement, config: &MockConfig) {
    let Some(path) = &config.truth else { return };
    if m.truth_written {
        return;
    }
    m.truth_written = true;
    let pixels: Vec<String> = m.pixel_counts.iter().map(u64::to_string).collect();
    let json = format!(
        "{{\"records\": {}, \"photons\": {}, \"markers\": {}, \"overflows\": {}, \"offset_ns\": {}, \"offset_ps\": {}, \"marker_edges\": {}, \"inputs_enabled\": [{}], \"pixel_photons\": [{}]}}\n",
        m.delivered,
        m.photons,
        m.markers,
        m.delivered - m.photons - m.markers,
        m.offset_ps as f64 / 1000.0,
        m.offset_ps,
        m.marker_edges
            .map_or("null".to_string(), |e| format!("{e:?}")),
        m.inputs_enabled
            .iter()
            .map(|e| e.map_or("null".to_string(), |b| b.to_string()))
            .collect::<Vec<_>>()
            .join(", "),
        pixels.join(", ")
    );
    if let Err(e) = std::fs::write(path, json) {
        eprintln!("stand-in: writing {}: {e}", path.display());
    }
}

/// Copies the records due into `out`; returns how many.
fn deliver(dev: &mut Device, config: &MockConfig, out: &mut [u32]) -> Result<usize, c_int> {
    let period_ps = sync_period_ps(config);
    let Some(m) = dev.measurement.as_mut() else {
        return Ok(0);
    };
    if m.ended {
        return Ok(0);
    }
    let mut limit = out.len() as u64;
    match config.fault {
        Some(Fault::Overrun(n)) if m.delivered >= n => {
            dev.flags |= dev.family.map_or(FLAG_FIFO_FULL, Family::fifo_full_flag);
            dev.flags &= !FLAG_ACTIVE;
            m.ended = true;
            return Ok(0);
        }
        Some(Fault::ReadError(n)) if m.delivered >= n => return Err(code::READ_FAIL),
        Some(Fault::Vanish(n)) if m.delivered >= n => {
            write_truth(m, config);
            dev.gone = true;
            return Err(code::DEVICE_LOST);
        }
        Some(Fault::DropCounts(n)) if m.delivered >= n => {
            dev.flags |= dev.family.map_or(FLAG_CNTS_DROPPED, Family::dropped_flag)
        }
        Some(Fault::Overrun(n) | Fault::ReadError(n) | Fault::Vanish(n) | Fault::DropCounts(n)) => {
            limit = limit.min(n - m.delivered)
        }
        None => {}
    }
    let due_syncs = if config.unpaced {
        m.end_syncs
    } else {
        let elapsed_ps = m.started.elapsed().as_secs_f64() * 1e12;
        ((elapsed_ps / period_ps) as u64).min(m.end_syncs)
    };
    let pool = m.pool.clone();
    let mut n = 0usize;
    while (n as u64) < limit {
        let offset = m.replays * pool.span;
        if offset + pool.sync_at[m.pos] >= due_syncs {
            if due_syncs >= m.end_syncs {
                m.ended = true;
                dev.flags &= !FLAG_ACTIVE;
            }
            break;
        }
        // Records of this replay due now, up to the limit.
        let bound = due_syncs - offset;
        let end_in_pool = pool.sync_at[m.pos..].partition_point(|&s| s < bound) + m.pos;
        let take = (end_in_pool - m.pos).min(limit as usize - n);
        let range = m.pos..m.pos + take;
        out[n..n + take].copy_from_slice(&pool.records[range.clone()]);
        for (&rec, i) in pool.records[range.clone()].iter().zip(range) {
            if pool.layout.is_photon(rec) {
                m.photons += 1;
                if let Some(&p) = pool.pixel_of.get(i) {
                    m.pixel_counts[p as usize] += 1;
                }
            } else if pool.layout.is_marker(rec) {
                m.markers += 1;
            }
        }
        n += take;
        m.pos += take;
        if m.pos == pool.records.len() {
            m.pos = 0;
            m.replays += 1;
        }
    }
    m.delivered += n as u64;
    Ok(n)
}

/// Initialises device `index` (mode 3 = T3 only): each family's
/// `Initialize` ([`library!`] callers), whatever its arguments.
fn initialize(index: c_int, mode: c_int) -> c_int {
    with_device(index, |d, _| {
        if !d.open {
            return code::DEVICE_NOT_OPEN;
        }
        if mode != 3 {
            return code::INVALID_ARGUMENT;
        }
        d.initialized = true;
        d.sync_divider = 1;
        0
    })
}

/// `MH_Initialize(devidx, mode, refsource)` (mhlib.h).
#[unsafe(no_mangle)]
pub extern "C" fn MH_Initialize(index: c_int, mode: c_int, _refsource: c_int) -> c_int {
    initialize(index, mode)
}

/// `HH_Initialize(devidx, mode, refsource)` (hhlib.h).
#[unsafe(no_mangle)]
pub extern "C" fn HH_Initialize(index: c_int, mode: c_int, _refsource: c_int) -> c_int {
    initialize(index, mode)
}

/// `TH260_Initialize(devidx, mode)`: no reference source (th260lib.h).
#[unsafe(no_mangle)]
pub extern "C" fn TH260_Initialize(index: c_int, mode: c_int) -> c_int {
    initialize(index, mode)
}

/// `PH_Initialize(devidx, mode)`: no reference source (phlib.h, PHLib
/// 3.0).
#[unsafe(no_mangle)]
pub extern "C" fn PH_Initialize(index: c_int, mode: c_int) -> c_int {
    initialize(index, mode)
}

/// `PH330_Initialize(devidx, mode, refsource)`: refsource 0 to 3, the
/// internal clock or an external 10, 100 or 500 MHz one (ph330defin.h).
#[unsafe(no_mangle)]
pub extern "C" fn PH330_Initialize(index: c_int, mode: c_int, refsource: c_int) -> c_int {
    if !(0..=3).contains(&refsource) {
        return code::INVALID_ARGUMENT;
    }
    initialize(index, mode)
}

macro_rules! library {
    ($family:expr, $version:literal,
     $GetLibraryVersion:ident, $GetErrorString:ident, $OpenDevice:ident, $CloseDevice:ident,
     $GetHardwareInfo:ident, $GetSerialNumber:ident,
     $GetBaseResolution:ident, $SetSyncDiv:ident, $SetBinning:ident,
     $SetOffset:ident, $SetMarkerEnable:ident, $SetMarkerEdges:ident,
     $GetResolution:ident, $GetCountRate:ident, $GetFlags:ident, $GetWarnings:ident,
     $GetWarningsText:ident, $StartMeas:ident, $StopMeas:ident, $CTCStatus:ident) => {
        /// The library's version string.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $GetLibraryVersion(vers: *mut c_char) -> c_int {
            unsafe { write_str(vers, $version, 8) };
            0
        }

        /// The text of an error code.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $GetErrorString(text: *mut c_char, code: c_int) -> c_int {
            unsafe { write_str(text, error_text(code), 40) };
            0
        }

        /// Opens device `index`, writing its serial number.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $OpenDevice(index: c_int, serial_out: *mut c_char) -> c_int {
            unsafe { write_str(serial_out, "", 8) };
            with_device(index, |d, _| {
                d.open = true;
                d.family = Some($family);
                unsafe { write_str(serial_out, &serial(index), 8) };
                0
            })
        }

        /// Closes device `index`.
        #[unsafe(no_mangle)]
        pub extern "C" fn $CloseDevice(index: c_int) -> c_int {
            with_device(index, |d, c| {
                if let Some(m) = d.measurement.as_mut() {
                    write_truth(m, c);
                }
                *d = Device::default();
                0
            })
        }

        /// Model, part number and version.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $GetHardwareInfo(
            index: c_int,
            model: *mut c_char,
            part: *mut c_char,
            version: *mut c_char,
        ) -> c_int {
            with_ready(index, |_, c| {
                unsafe {
                    write_str(model, $family.model(c), 16);
                    write_str(part, "SSMOCK", 8);
                    write_str(version, "1.0", 8);
                }
                0
            })
        }

        /// Serial number.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $GetSerialNumber(index: c_int, out: *mut c_char) -> c_int {
            with_ready(index, |_, _| {
                unsafe { write_str(out, &serial(index), 8) };
                0
            })
        }

        /// Base resolution (ps) and binning steps.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $GetBaseResolution(
            index: c_int,
            res: *mut c_double,
            steps: *mut c_int,
        ) -> c_int {
            with_ready(index, |d, c| unsafe {
                put(steps, $family.binning_steps());
                put(res, d.family.map_or(1.0, |f| f.base_resolution_ps(c)))
            })
        }

        /// Sync divider 1 to the family's `SYNCDIVMAX`, a power of two
        /// where the family's manual lists only those.
        #[unsafe(no_mangle)]
        pub extern "C" fn $SetSyncDiv(index: c_int, div: c_int) -> c_int {
            with_ready(index, |d, _| {
                if !(1..=$family.sync_divider_max()).contains(&div)
                    || ($family.sync_divider_powers_of_two() && !(div as u32).is_power_of_two())
                {
                    return code::INVALID_ARGUMENT;
                }
                d.sync_divider = div;
                0
            })
        }

        /// Binning code 0 to the family's steps less one.
        #[unsafe(no_mangle)]
        pub extern "C" fn $SetBinning(index: c_int, binning: c_int) -> c_int {
            with_ready(index, |d, _| {
                if !(0..$family.binning_steps()).contains(&binning) {
                    return code::INVALID_ARGUMENT;
                }
                d.binning = binning;
                0
            })
        }

        /// T3 offset in the family's unit
        /// ([`Family::offset_unit_and_range`]), kept for the truth file.
        #[unsafe(no_mangle)]
        pub extern "C" fn $SetOffset(index: c_int, offset: c_int) -> c_int {
            with_ready(index, |d, _| {
                let (unit_ps, max) = $family.offset_unit_and_range();
                let r = in_range(offset, 0, max);
                if r == 0 {
                    d.offset_ps = i64::from(offset) * unit_ps;
                }
                r
            })
        }

        /// Marker inputs (accepted; a scan always sends its markers).
        #[unsafe(no_mangle)]
        pub extern "C" fn $SetMarkerEnable(
            index: c_int,
            _e1: c_int,
            _e2: c_int,
            _e3: c_int,
            _e4: c_int,
        ) -> c_int {
            with_ready(index, |_, _| 0)
        }

        /// Marker edges, each 1 (rising) or 0 (falling): the vendor's
        /// `SetMarkerEdges(devidx, me1, me2, me3, me4)` (hhlib.h) with
        /// EDGE_RISING 1 and EDGE_FALLING 0 (hhdefin.h, mhdefin.h); kept
        /// for the truth file.
        #[unsafe(no_mangle)]
        pub extern "C" fn $SetMarkerEdges(
            index: c_int,
            e1: c_int,
            e2: c_int,
            e3: c_int,
            e4: c_int,
        ) -> c_int {
            with_ready(index, |d, _| {
                let edges = [e1, e2, e3, e4];
                if edges.iter().any(|e| !(0..=1).contains(e)) {
                    return code::INVALID_ARGUMENT;
                }
                d.marker_edges = Some(edges);
                0
            })
        }

        /// Micro-time unit, ps.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $GetResolution(index: c_int, res: *mut c_double) -> c_int {
            with_ready(index, |d, c| unsafe { put(res, resolution_ps(d, c)) })
        }

        /// Count rate of input `ch` (the detector is on input 0). PHLib's
        /// `PH_GetCountRate(devidx, channel, *rate)` counts the sync on
        /// channel 0 and the input on 1 (its demos read both; it has no
        /// `GetSyncRate`).
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $GetCountRate(
            index: c_int,
            ch: c_int,
            rate: *mut c_int,
        ) -> c_int {
            with_ready(index, |_, c| {
                let r = match ($family, ch) {
                    (Family::PicoHarp300, 0) => c.sync_hz,
                    (Family::PicoHarp300, 1) => c.rate_hz + c.dark_hz,
                    (Family::PicoHarp300, _) => return code::INVALID_ARGUMENT,
                    (_, 0) => c.rate_hz + c.dark_hz,
                    _ => 0.0,
                };
                unsafe { put(rate, r.min(f64::from(c_int::MAX)) as c_int) }
            })
        }

        /// Status flags.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $GetFlags(index: c_int, flags: *mut c_int) -> c_int {
            with_ready(index, |d, _| unsafe { put(flags, $family.reported_flags(d.flags)) })
        }

        /// Warning bits: input rate above 5 % of the sync rate (pile-up).
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $GetWarnings(index: c_int, warnings: *mut c_int) -> c_int {
            with_ready(index, |_, c| {
                let w = if !c.unpaced && c.rate_hz + c.dark_hz > 0.05 * c.sync_hz {
                    WARNING_INPUT_RATE_RATIO
                } else {
                    0
                };
                unsafe { put(warnings, w) }
            })
        }

        /// The warnings' text.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $GetWarningsText(
            index: c_int,
            text: *mut c_char,
            warnings: c_int,
        ) -> c_int {
            with_ready(index, |_, _| {
                let t = if warnings & WARNING_INPUT_RATE_RATIO != 0 {
                    "WARNING: the input count rate exceeds 5 % of the sync rate: pile-up distorts the histogram\n"
                } else {
                    ""
                };
                unsafe { write_str(text, t, 16384) };
                0
            })
        }

        /// Starts a measurement of `tacq` ms.
        #[unsafe(no_mangle)]
        pub extern "C" fn $StartMeas(index: c_int, tacq: c_int) -> c_int {
            with_ready(index, |d, c| {
                if !(1..=360_000_000).contains(&tacq) {
                    return code::INVALID_ARGUMENT;
                }
                let res = resolution_ps(d, c);
                let period = sync_period_ps(c);
                let layout = $family.records();
                let pool = match &d.pool {
                    Some((r, l, p)) if *r == res && *l == layout => p.clone(),
                    _ => match pool::build(c, res, period, layout) {
                        Ok(p) => {
                            let p = Arc::new(p);
                            d.pool = Some((res, layout, p.clone()));
                            p
                        }
                        Err(e) => {
                            eprintln!("stand-in: {e}");
                            return code::INVALID_ARGUMENT;
                        }
                    },
                };
                let pixels = c.scan.map_or(0, |(w, h)| w * h);
                let mut end_syncs = (f64::from(tacq) * 1e9 / period) as u64;
                if c.scan.is_some() {
                    // A scanner finishes the frame it is in.
                    end_syncs = end_syncs.div_ceil(pool.frame_span) * pool.frame_span;
                }
                d.flags = FLAG_ACTIVE;
                d.measurement = Some(Measurement {
                    pool,
                    started: Instant::now(),
                    end_syncs,
                    pos: 0,
                    replays: 0,
                    delivered: 0,
                    photons: 0,
                    markers: 0,
                    pixel_counts: vec![0; pixels],
                    ended: false,
                    truth_written: false,
                    offset_ps: d.offset_ps,
                    marker_edges: d.marker_edges,
                    inputs_enabled: d.inputs_enabled,
                });
                0
            })
        }

        /// Stops the measurement (writes the truth file when asked).
        #[unsafe(no_mangle)]
        pub extern "C" fn $StopMeas(index: c_int) -> c_int {
            with_ready(index, |d, c| {
                d.flags &= !FLAG_ACTIVE;
                if let Some(m) = d.measurement.as_mut() {
                    m.ended = true;
                    write_truth(m, c);
                }
                0
            })
        }

        /// 1 once the measurement time has elapsed (or the run ended).
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $CTCStatus(index: c_int, status: *mut c_int) -> c_int {
            with_ready(index, |d, _| {
                let done = d.measurement.as_ref().is_none_or(|m| m.ended);
                unsafe { put(status, c_int::from(done)) }
            })
        }
    };
}

/// The functions of the families whose inputs are numbered channels with
/// their own offsets and enables, and whose sync rate has its own call
/// (mhlib.h, hhlib.h, th260lib.h, ph330lib.h); PHLib 3.0 has none of them.
macro_rules! channel_functions {
    ($family:expr, $GetNumOfInputChannels:ident, $SetSyncChannelOffset:ident,
     $SetInputChannelOffset:ident, $SetInputChannelEnable:ident, $GetSyncRate:ident) => {
        /// Four inputs (two on a TimeHarp 260).
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $GetNumOfInputChannels(index: c_int, n: *mut c_int) -> c_int {
            with_ready(index, |_, _| unsafe { put(n, $family.inputs()) })
        }

        /// Sync offset, ps (accepted).
        #[unsafe(no_mangle)]
        pub extern "C" fn $SetSyncChannelOffset(index: c_int, ps: c_int) -> c_int {
            with_ready(index, |_, _| in_range(ps, -99_999, 99_999))
        }

        /// Input offset, ps (accepted).
        #[unsafe(no_mangle)]
        pub extern "C" fn $SetInputChannelOffset(index: c_int, ch: c_int, ps: c_int) -> c_int {
            with_ready(index, |_, _| {
                if !(0..$family.inputs()).contains(&ch) {
                    return code::INVALID_ARGUMENT;
                }
                in_range(ps, -99_999, 99_999)
            })
        }

        /// Enables (1) or disables (0) input `ch`: the vendor's
        /// `SetInputChannelEnable(devidx, channel, enable)` (hhlib.h); kept
        /// for the truth file.
        #[unsafe(no_mangle)]
        pub extern "C" fn $SetInputChannelEnable(index: c_int, ch: c_int, enable: c_int) -> c_int {
            with_ready(index, |d, _| {
                if !(0..$family.inputs()).contains(&ch) || !(0..=1).contains(&enable) {
                    return code::INVALID_ARGUMENT;
                }
                d.inputs_enabled[ch as usize] = Some(enable == 1);
                0
            })
        }

        /// Sync rate at the input, before the divider, Hz (as the vendor's
        /// file at [`sync_period_ps`] records it).
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $GetSyncRate(index: c_int, rate: *mut c_int) -> c_int {
            with_ready(index, |_, c| unsafe { put(rate, c.sync_hz as c_int) })
        }
    };
}

fn in_range(v: c_int, lo: c_int, hi: c_int) -> c_int {
    if (lo..=hi).contains(&v) {
        0
    } else {
        code::INVALID_ARGUMENT
    }
}

library!(
    Family::MultiHarp,
    "3.1",
    MH_GetLibraryVersion,
    MH_GetErrorString,
    MH_OpenDevice,
    MH_CloseDevice,
    MH_GetHardwareInfo,
    MH_GetSerialNumber,
    MH_GetBaseResolution,
    MH_SetSyncDiv,
    MH_SetBinning,
    MH_SetOffset,
    MH_SetMarkerEnable,
    MH_SetMarkerEdges,
    MH_GetResolution,
    MH_GetCountRate,
    MH_GetFlags,
    MH_GetWarnings,
    MH_GetWarningsText,
    MH_StartMeas,
    MH_StopMeas,
    MH_CTCStatus
);

channel_functions!(
    Family::MultiHarp,
    MH_GetNumOfInputChannels,
    MH_SetSyncChannelOffset,
    MH_SetInputChannelOffset,
    MH_SetInputChannelEnable,
    MH_GetSyncRate
);

library!(
    Family::HydraHarp,
    "3.0",
    HH_GetLibraryVersion,
    HH_GetErrorString,
    HH_OpenDevice,
    HH_CloseDevice,
    HH_GetHardwareInfo,
    HH_GetSerialNumber,
    HH_GetBaseResolution,
    HH_SetSyncDiv,
    HH_SetBinning,
    HH_SetOffset,
    HH_SetMarkerEnable,
    HH_SetMarkerEdges,
    HH_GetResolution,
    HH_GetCountRate,
    HH_GetFlags,
    HH_GetWarnings,
    HH_GetWarningsText,
    HH_StartMeas,
    HH_StopMeas,
    HH_CTCStatus
);

channel_functions!(
    Family::HydraHarp,
    HH_GetNumOfInputChannels,
    HH_SetSyncChannelOffset,
    HH_SetInputChannelOffset,
    HH_SetInputChannelEnable,
    HH_GetSyncRate
);

library!(
    Family::TimeHarp260,
    "3.1",
    TH260_GetLibraryVersion,
    TH260_GetErrorString,
    TH260_OpenDevice,
    TH260_CloseDevice,
    TH260_GetHardwareInfo,
    TH260_GetSerialNumber,
    TH260_GetBaseResolution,
    TH260_SetSyncDiv,
    TH260_SetBinning,
    TH260_SetOffset,
    TH260_SetMarkerEnable,
    TH260_SetMarkerEdges,
    TH260_GetResolution,
    TH260_GetCountRate,
    TH260_GetFlags,
    TH260_GetWarnings,
    TH260_GetWarningsText,
    TH260_StartMeas,
    TH260_StopMeas,
    TH260_CTCStatus
);

channel_functions!(
    Family::TimeHarp260,
    TH260_GetNumOfInputChannels,
    TH260_SetSyncChannelOffset,
    TH260_SetInputChannelOffset,
    TH260_SetInputChannelEnable,
    TH260_GetSyncRate
);

library!(
    Family::PicoHarp330,
    "2.0",
    PH330_GetLibraryVersion,
    PH330_GetErrorString,
    PH330_OpenDevice,
    PH330_CloseDevice,
    PH330_GetHardwareInfo,
    PH330_GetSerialNumber,
    PH330_GetBaseResolution,
    PH330_SetSyncDiv,
    PH330_SetBinning,
    PH330_SetOffset,
    PH330_SetMarkerEnable,
    PH330_SetMarkerEdges,
    PH330_GetResolution,
    PH330_GetCountRate,
    PH330_GetFlags,
    PH330_GetWarnings,
    PH330_GetWarningsText,
    PH330_StartMeas,
    PH330_StopMeas,
    PH330_CTCStatus
);

channel_functions!(
    Family::PicoHarp330,
    PH330_GetNumOfInputChannels,
    PH330_SetSyncChannelOffset,
    PH330_SetInputChannelOffset,
    PH330_SetInputChannelEnable,
    PH330_GetSyncRate
);

library!(
    Family::PicoHarp300,
    "3.0",
    PH_GetLibraryVersion,
    PH_GetErrorString,
    PH_OpenDevice,
    PH_CloseDevice,
    PH_GetHardwareInfo,
    PH_GetSerialNumber,
    PH_GetBaseResolution,
    PH_SetSyncDiv,
    PH_SetBinning,
    PH_SetOffset,
    PH_SetMarkerEnable,
    PH_SetMarkerEdges,
    PH_GetResolution,
    PH_GetCountRate,
    PH_GetFlags,
    PH_GetWarnings,
    PH_GetWarningsText,
    PH_StartMeas,
    PH_StopMeas,
    PH_CTCStatus
);

/// PicoHarp 300 CFD of channel 0 (the sync) or 1 (the input): level 0 to
/// 800 mV, zero cross 0 to 20 mV (`DISCRMIN`/`DISCRMAX`, `ZCMIN`/`ZCMAX`
/// of phdefin.h; `PH_SetInputCFD(devidx, channel, level, zc)` of phlib.h).
#[unsafe(no_mangle)]
pub extern "C" fn PH_SetInputCFD(
    index: c_int,
    ch: c_int,
    level: c_int,
    zero_cross: c_int,
) -> c_int {
    with_ready(index, |_, _| {
        if !(0..=1).contains(&ch) {
            return code::INVALID_ARGUMENT;
        }
        cfd_within(level, zero_cross, 0..=800, 0..=20)
    })
}

/// PicoHarp 300 sync offset, ps: -99,999 to 99,999 (`SYNCOFFSMIN`/`MAX`
/// of phdefin.h), where the other libraries set a sync channel offset.
#[unsafe(no_mangle)]
pub extern "C" fn PH_SetSyncOffset(index: c_int, ps: c_int) -> c_int {
    with_ready(index, |_, _| in_range(ps, -99_999, 99_999))
}

/// PicoHarp 300 calibration (instant here; the vendor's demos call it
/// after `PH_Initialize`).
#[unsafe(no_mangle)]
pub extern "C" fn PH_Calibrate(index: c_int) -> c_int {
    with_ready(index, |_, _| 0)
}

/// `PH_ReadFiFo(devidx, buffer, count, *nactual)`: up to `count` records,
/// at most `TTREADMAX` 131,072 (phdefin.h) and, as the vendor's TTTR demo
/// says of its block size, in steps of 512.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn PH_ReadFiFo(
    index: c_int,
    buffer: *mut c_uint,
    count: c_int,
    n: *mut c_int,
) -> c_int {
    let max = Family::PicoHarp300.read_max();
    if !(512..=max as c_int).contains(&count) || count % 512 != 0 {
        return code::INVALID_ARGUMENT;
    }
    unsafe { read_fifo(index, buffer, count as usize, n) }
}

/// MultiHarp edge trigger of the sync input.
#[unsafe(no_mangle)]
pub extern "C" fn MH_SetSyncEdgeTrg(index: c_int, level: c_int, edge: c_int) -> c_int {
    with_ready(index, |_, _| edge_trigger(level, edge))
}

/// MultiHarp edge trigger of an input.
#[unsafe(no_mangle)]
pub extern "C" fn MH_SetInputEdgeTrg(index: c_int, ch: c_int, level: c_int, edge: c_int) -> c_int {
    with_ready(index, |_, _| {
        if !(0..4).contains(&ch) {
            return code::INVALID_ARGUMENT;
        }
        edge_trigger(level, edge)
    })
}

/// `FEATURE_INPT_MODE` (ph330defin.h of PH330Lib 2.0): the inputs' trigger
/// mode can be set.
const FEATURE_INPT_MODE: c_int = 0x0200;

/// PicoHarp 330 features: `FEATURE_DLL | FEATURE_TTTR | FEATURE_MARKERS`
/// (1, 2, 4, as in every family's header) and, unless configured away,
/// `FEATURE_INPT_MODE`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn PH330_GetFeatures(index: c_int, features: *mut c_int) -> c_int {
    with_ready(index, |_, c| {
        let f = 0x0007
            | if c.ph330_input_modes {
                FEATURE_INPT_MODE
            } else {
                0
            };
        unsafe { put(features, f) }
    })
}

/// PicoHarp 330 trigger mode of the sync input: `TRGMODE_ETR` 0 or
/// `TRGMODE_CFD` 1 (ph330defin.h).
#[unsafe(no_mangle)]
pub extern "C" fn PH330_SetSyncTrgMode(index: c_int, mode: c_int) -> c_int {
    with_ready(index, |_, _| in_range(mode, 0, 1))
}

/// PicoHarp 330 trigger mode of an input (as the sync's); refused on a
/// device without `FEATURE_INPT_MODE`.
#[unsafe(no_mangle)]
pub extern "C" fn PH330_SetInputTrgMode(index: c_int, ch: c_int, mode: c_int) -> c_int {
    with_ready(index, |_, c| {
        if !c.ph330_input_modes {
            return code::UNSUPPORTED_FUNCTION;
        }
        if !(0..4).contains(&ch) {
            return code::INVALID_ARGUMENT;
        }
        in_range(mode, 0, 1)
    })
}

/// PicoHarp 330 edge trigger of the sync input: level -1500 to 1500 mV
/// (`TRGLVLMIN`/`TRGLVLMAX` of ph330defin.h).
#[unsafe(no_mangle)]
pub extern "C" fn PH330_SetSyncEdgeTrg(index: c_int, level: c_int, edge: c_int) -> c_int {
    with_ready(index, |_, _| edge_trigger_within(level, edge, 1500))
}

/// PicoHarp 330 edge trigger of an input.
#[unsafe(no_mangle)]
pub extern "C" fn PH330_SetInputEdgeTrg(
    index: c_int,
    ch: c_int,
    level: c_int,
    edge: c_int,
) -> c_int {
    with_ready(index, |_, _| {
        if !(0..4).contains(&ch) {
            return code::INVALID_ARGUMENT;
        }
        edge_trigger_within(level, edge, 1500)
    })
}

/// HydraHarp CFD of the sync input.
#[unsafe(no_mangle)]
pub extern "C" fn HH_SetSyncCFD(index: c_int, level: c_int, zero_cross: c_int) -> c_int {
    with_ready(index, |_, _| cfd(level, zero_cross))
}

/// HydraHarp CFD of an input.
#[unsafe(no_mangle)]
pub extern "C" fn HH_SetInputCFD(
    index: c_int,
    ch: c_int,
    level: c_int,
    zero_cross: c_int,
) -> c_int {
    with_ready(index, |_, _| {
        if !(0..4).contains(&ch) {
            return code::INVALID_ARGUMENT;
        }
        cfd(level, zero_cross)
    })
}

/// Runs `f` on a TimeHarp 260 that is a Nano (`nano`) or a Pico; the
/// other board's call fails with [`code::UNSUPPORTED_FUNCTION`]
/// (th260lib.h marks `SetSyncCFD`/`SetInputCFD` "TH 260 Pico only" and
/// the edge triggers "TH 260 Nano only").
fn th260_board(index: c_int, nano: bool, f: impl FnOnce() -> c_int) -> c_int {
    with_ready(index, |_, c| {
        if c.th260_nano == nano {
            f()
        } else {
            code::UNSUPPORTED_FUNCTION
        }
    })
}

/// TimeHarp 260 Pico CFD of the sync input: level -1200 to 0 mV, zero
/// cross -40 to 0 mV (th260defin.h `CFDLVLMIN` ... `CFDZCMAX`).
#[unsafe(no_mangle)]
pub extern "C" fn TH260_SetSyncCFD(index: c_int, level: c_int, zero_cross: c_int) -> c_int {
    th260_board(index, false, || th260_cfd(level, zero_cross))
}

/// TimeHarp 260 Pico CFD of an input.
#[unsafe(no_mangle)]
pub extern "C" fn TH260_SetInputCFD(
    index: c_int,
    ch: c_int,
    level: c_int,
    zero_cross: c_int,
) -> c_int {
    th260_board(index, false, || {
        if !(0..2).contains(&ch) {
            return code::INVALID_ARGUMENT;
        }
        th260_cfd(level, zero_cross)
    })
}

/// TimeHarp 260 Nano edge trigger of the sync input: level -1200 to 1200
/// mV (th260defin.h `TRGLVLMIN`/`TRGLVLMAX`).
#[unsafe(no_mangle)]
pub extern "C" fn TH260_SetSyncEdgeTrg(index: c_int, level: c_int, edge: c_int) -> c_int {
    th260_board(index, true, || edge_trigger_within(level, edge, 1200))
}

/// TimeHarp 260 Nano edge trigger of an input.
#[unsafe(no_mangle)]
pub extern "C" fn TH260_SetInputEdgeTrg(
    index: c_int,
    ch: c_int,
    level: c_int,
    edge: c_int,
) -> c_int {
    th260_board(index, true, || {
        if !(0..2).contains(&ch) {
            return code::INVALID_ARGUMENT;
        }
        edge_trigger_within(level, edge, 1200)
    })
}

/// TimeHarp 260 Pico CFD ranges (th260defin.h `CFDLVLMIN` ... `CFDZCMAX`).
fn th260_cfd(level: c_int, zero_cross: c_int) -> c_int {
    cfd_within(level, zero_cross, -1200..=0, -40..=0)
}

/// HydraHarp calibration (instant here).
#[unsafe(no_mangle)]
pub extern "C" fn HH_Calibrate(index: c_int) -> c_int {
    with_ready(index, |_, _| 0)
}

fn edge_trigger(level: c_int, edge: c_int) -> c_int {
    edge_trigger_within(level, edge, 1200)
}

fn edge_trigger_within(level: c_int, edge: c_int, max_mv: c_int) -> c_int {
    if (-max_mv..=max_mv).contains(&level) && (0..=1).contains(&edge) {
        0
    } else {
        code::INVALID_ARGUMENT
    }
}

/// HydraHarp CFD ranges (hhdefin.h: 0 to 1000 mV, zero cross 0 to 40).
fn cfd(level: c_int, zero_cross: c_int) -> c_int {
    cfd_within(level, zero_cross, 0..=1000, 0..=40)
}

/// 0 when a CFD's level and zero cross lie in their ranges (mV), else
/// `ERROR_INVALID_ARGUMENT`.
fn cfd_within(
    level: c_int,
    zero_cross: c_int,
    levels: std::ops::RangeInclusive<c_int>,
    zero_crosses: std::ops::RangeInclusive<c_int>,
) -> c_int {
    if levels.contains(&level) && zero_crosses.contains(&zero_cross) {
        0
    } else {
        code::INVALID_ARGUMENT
    }
}

/// `MH_ReadFiFo`: up to 1,048,576 records into `buffer`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn MH_ReadFiFo(index: c_int, buffer: *mut c_uint, n: *mut c_int) -> c_int {
    unsafe { read_fifo(index, buffer, Family::MultiHarp.read_max(), n) }
}

/// `PH330_ReadFiFo`: up to 1,048,576 records into `buffer` (`TTREADMAX`
/// of ph330defin.h; the buffer's length is not passed).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn PH330_ReadFiFo(index: c_int, buffer: *mut c_uint, n: *mut c_int) -> c_int {
    unsafe { read_fifo(index, buffer, Family::PicoHarp330.read_max(), n) }
}

/// `TH260_ReadFiFo`: up to `count` records, from `TTREADMIN` 128 to
/// `TTREADMAX` 131,072 (th260defin.h).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn TH260_ReadFiFo(
    index: c_int,
    buffer: *mut c_uint,
    count: c_int,
    n: *mut c_int,
) -> c_int {
    let max = Family::TimeHarp260.read_max();
    if !(128..=max as c_int).contains(&count) {
        return code::INVALID_ARGUMENT;
    }
    unsafe { read_fifo(index, buffer, count as usize, n) }
}

/// `HH_ReadFiFo`: up to `count` (at most 131,072) records into `buffer`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn HH_ReadFiFo(
    index: c_int,
    buffer: *mut c_uint,
    count: c_int,
    n: *mut c_int,
) -> c_int {
    let max = Family::HydraHarp.read_max();
    if !(128..=max as c_int).contains(&count) {
        return code::INVALID_ARGUMENT;
    }
    unsafe { read_fifo(index, buffer, count as usize, n) }
}

unsafe fn read_fifo(index: c_int, buffer: *mut c_uint, cap: usize, n: *mut c_int) -> c_int {
    if buffer.is_null() || n.is_null() {
        return code::INVALID_ARGUMENT;
    }
    // SAFETY: the caller's buffer holds `cap` records (the API's contract).
    let out = unsafe { std::slice::from_raw_parts_mut(buffer, cap) };
    with_ready(index, |d, c| match deliver(d, c, out) {
        Ok(k) => unsafe { put(n, k as c_int) },
        Err(e) => {
            unsafe { put(n, 0) };
            e
        }
    })
}
