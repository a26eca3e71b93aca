//! PicoQuant time taggers through the vendor's programming library, loaded
//! at run time: MHLib (MultiHarp 150/160), HHLib v3 (HydraHarp 400),
//! TH260Lib 3.1 (TimeHarp 260 Pico and Nano), PH330Lib 2.0 (PicoHarp
//! 330) and PHLib 3.0 (PicoHarp 300).
//!
//! Nothing links against the vendor's library: the project builds and its
//! tests run where none is installed, and [`VendorLib::load`] says which
//! files it looked for. The stand-in library in `mocks/picoquant` exports
//! the same C functions, so tests go through this same loader.
//!
//! The libraries differ where the hardware does: MultiHarp inputs have
//! edge triggers (a level and an edge), HydraHarp inputs constant-fraction
//! discriminators (a level and a zero cross), the TimeHarp 260 Pico CFDs
//! and the Nano edge triggers (one library; `TH260_GetHardwareInfo` says
//! which board, `TH260_Initialize` takes no reference source), PicoHarp
//! 330 inputs either,
//! chosen per input (`PH330_SetSyncTrgMode`, `PH330_SetInputTrgMode` in
//! the vendor's ph330lib.h; this driver sets edge triggers), and
//! `HH_ReadFiFo` takes the buffer's length where `MH_ReadFiFo` and
//! `PH330_ReadFiFo` assume their fixed one. PHLib 3.0 (the vendor's
//! phlib.h and phdefin.h, `PicoQuant/PH300-v3.x-Demos`) is the oldest
//! shape: one input beside the sync, both set by `PH_SetInputCFD(devidx,
//! channel, level, zc)` with channel 0 the sync; a sync offset
//! (`PH_SetSyncOffset`) and no per-input offsets, enables or input count;
//! the sync rate read as count rate 0; `PH_SetOffset` in picoseconds; its
//! own flag bits; PicoHarp T3 records. T3 mode only: every record carries
//! the sync count and the micro time.

use std::ffi::{CStr, c_char, c_double, c_int, c_uint};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Device indices the libraries address (`MAXDEVNUM`; 4 in th260defin.h,
/// [`Family::max_devices`]).
pub const MAX_DEVICES: i32 = 8;
/// `Initialize` mode for time tagging with micro times.
const MODE_T3: c_int = 3;
/// `GetFlags`: the FIFO overran; records were lost and the run is over.
pub const FLAG_FIFO_FULL: i32 = 0x0002;
/// `PH_GetFlags` (phdefin.h `FLAG_FIFOFULL`): the PicoHarp 300's overrun.
pub const FLAG_FIFO_FULL_PH300: i32 = 0x0003;
/// `PH_GetFlags` (phdefin.h `FLAG_SYSERROR`): a PicoHarp 300 hardware
/// problem.
pub const FLAG_SYS_ERROR_PH300: i32 = 0x0100;
/// `GetFlags`: the sync signal was lost.
pub const FLAG_SYNC_LOST: i32 = 0x0004;
/// `GetFlags`: the reference clock was lost.
pub const FLAG_REF_LOST: i32 = 0x0008;
/// `GetFlags`: a hardware error.
pub const FLAG_SYS_ERROR: i32 = 0x0010;
/// `GetFlags` (MultiHarp, PicoHarp 330): counts were dropped in the
/// device (mhdefin.h, ph330defin.h; HHLib v3 has no such flag).
pub const FLAG_CNTS_DROPPED: i32 = 0x0040;
/// `GetFlags` (TimeHarp 260): events dropped at a high input rate
/// (`FLAG_EVTS_DROPPED`, th260defin.h), where the others say the
/// reference clock was lost.
pub const FLAG_EVTS_DROPPED_TH260: i32 = 0x0008;
/// `TH260_GetFlags` (th260defin.h `FLAG_SOFTERROR`): a software error,
/// "must contact support".
pub const FLAG_SOFT_ERROR_TH260: i32 = 0x0020;
/// `PH330_GetFlags` (ph330defin.h of PH330Lib 2.0, `FLAG_SOFTERROR`; its
/// 0x0020 is `FLAG_ACTIVE`).
pub const FLAG_SOFT_ERROR_PH330: i32 = 0x0080;
/// `GetFeatures` (ph330defin.h `FEATURE_INPT_MODE`): the PicoHarp 330's
/// inputs' trigger mode can be set.
pub const FEATURE_INPT_MODE: i32 = 0x0200;
/// The libraries' "no device at this index" error.
const ERROR_DEVICE_OPEN_FAIL: c_int = -1;

/// Which vendor library, and so which device family.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// MultiHarp 150/160 (MHLib, edge triggers, Generic T3 records).
    MultiHarp,
    /// HydraHarp 400 (HHLib v3, CFD inputs, HydraHarp v2 T3 records).
    HydraHarp,
    /// TimeHarp 260 Pico (CFD inputs, TimeHarp 260 P T3 records) or Nano
    /// (edge triggers, TimeHarp 260 N T3 records): TH260Lib 3.1.
    TimeHarp260,
    /// PicoHarp 330 (PH330Lib 2.0, inputs set to edge triggers, Generic
    /// T3 records).
    PicoHarp330,
    /// PicoHarp 300 (PHLib 3.0, one CFD input besides the sync, PicoHarp
    /// T3 records).
    PicoHarp300,
}

impl Family {
    /// Every family, in the order `devices` searches them.
    pub const ALL: [Family; 5] = [
        Family::MultiHarp,
        Family::HydraHarp,
        Family::TimeHarp260,
        Family::PicoHarp330,
        Family::PicoHarp300,
    ];

    /// The family's name as `--device picoquant:NAME` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Family::MultiHarp => "multiharp",
            Family::HydraHarp => "hydraharp",
            Family::TimeHarp260 => "timeharp260",
            Family::PicoHarp330 => "picoharp330",
            Family::PicoHarp300 => "picoharp",
        }
    }

    fn prefix(self) -> &'static str {
        match self {
            Family::MultiHarp => "MH_",
            Family::HydraHarp => "HH_",
            Family::TimeHarp260 => "TH260_",
            Family::PicoHarp330 => "PH330_",
            Family::PicoHarp300 => "PH_",
        }
    }

    /// Where the vendor's installer puts the library, in search order:
    /// the linker-style name first (found on the library path), then the
    /// installer's own folder (for the PicoHarp 300 the folder its Linux
    /// demos' makefiles link from). (The TimeHarp 260's and PicoHarp 330's
    /// names follow the pattern of the other installers; no installer of
    /// theirs was at hand to check them: the file can always be named in
    /// [`Family::library_env`].)
    pub fn library_candidates(self) -> Vec<PathBuf> {
        let names: &[&str] = match (self, cfg!(windows)) {
            (Family::MultiHarp, false) => &["libmh150.so", "/usr/local/lib64/mh150/mhlib.so"],
            (Family::HydraHarp, false) => &["libhh400.so", "/usr/local/lib64/hh400/hhlib.so"],
            (Family::TimeHarp260, false) => &["libth260.so", "/usr/local/lib64/th260/th260lib.so"],
            (Family::PicoHarp330, false) => &["libph330.so", "/usr/local/lib64/ph330/ph330lib.so"],
            (Family::PicoHarp300, false) => &["libph300.so", "/usr/local/lib64/ph300/phlib.so"],
            (Family::MultiHarp, true) => &["mhlib64.dll"],
            (Family::HydraHarp, true) => &["hhlib64.dll"],
            (Family::TimeHarp260, true) => &["th260lib64.dll"],
            (Family::PicoHarp330, true) => &["ph330lib64.dll"],
            (Family::PicoHarp300, true) => &["phlib64.dll"],
        };
        names.iter().map(PathBuf::from).collect()
    }

    /// How the family's inputs discriminate; `None` when it depends on
    /// the board (the TimeHarp 260 Pico has CFDs, the Nano edge
    /// triggers: [`Device::inputs`]).
    pub fn inputs(self) -> Option<Inputs> {
        match self {
            Family::MultiHarp | Family::PicoHarp330 => Some(Inputs::Edge),
            Family::HydraHarp | Family::PicoHarp300 => Some(Inputs::Cfd),
            Family::TimeHarp260 => None,
        }
    }

    /// Device indices the library addresses (`MAXDEVNUM`: 8, 4 in
    /// th260defin.h).
    pub fn max_devices(self) -> i32 {
        match self {
            Family::TimeHarp260 => 4,
            _ => MAX_DEVICES,
        }
    }

    /// The largest sync divider (`SYNCDIVMAX`: 16 in mhdefin.h and
    /// hhdefin.h, 8 in th260defin.h, ph330defin.h and phdefin.h).
    pub fn sync_divider_max(self) -> i32 {
        match self {
            Family::TimeHarp260 | Family::PicoHarp330 | Family::PicoHarp300 => 8,
            Family::MultiHarp | Family::HydraHarp => 16,
        }
    }

    /// Whether the family takes only powers of two as its sync divider:
    /// the TimeHarp 260, PicoHarp 330 and PicoHarp 300 manuals list 1, 2,
    /// 4 and 8 (their headers bound it 1 to 8, and the library refuses
    /// the others when it is called).
    pub fn sync_divider_powers_of_two(self) -> bool {
        matches!(
            self,
            Family::TimeHarp260 | Family::PicoHarp330 | Family::PicoHarp300
        )
    }

    /// Records one `ReadFiFo` may return (`TTREADMAX`).
    pub fn fifo_read_max(self) -> usize {
        match self {
            // TTREADMAX of mhdefin.h and ph330defin.h.
            Family::MultiHarp | Family::PicoHarp330 => 1_048_576,
            // TTREADMAX of hhdefin.h, th260defin.h and phdefin.h.
            Family::HydraHarp | Family::TimeHarp260 | Family::PicoHarp300 => 131_072,
        }
    }

    /// The largest binning code, where the family's header bounds it
    /// (`BINSTEPSMAX` 8 in phdefin.h: codes 0 to 7; `MAXBINSTEPS` 22 in
    /// th260defin.h: 0 to 21); `None`: the library's own check.
    pub fn binning_max(self) -> Option<i32> {
        match self {
            Family::PicoHarp300 => Some(7),
            // th260defin.h MAXBINSTEPS 22: codes 0 to 21.
            Family::TimeHarp260 => Some(21),
            _ => None,
        }
    }

    /// The T3 offset as `SetOffset` takes it: nanoseconds for every
    /// family but the PicoHarp 300, whose `PH_SetOffset` takes
    /// picoseconds, 0 to 1 000 000 000 (phdefin.h `OFFSETMIN`/`OFFSETMAX`);
    /// an offset it cannot take is refused by name.
    pub fn offset_arg(self, t3_offset_ns: i32) -> Result<c_int, VendorError> {
        match self {
            // hhdefin.h: OFFSETMIN 0, OFFSETMAX 500000.
            Family::HydraHarp if !(0..=500_000).contains(&t3_offset_ns) => {
                Err(VendorError::Setting(format!(
                    "T3 offset {t3_offset_ns} ns: a HydraHarp takes 0 to 500 000 (hhdefin.h OFFSETMAX)"
                )))
            }
            Family::PicoHarp300 => t3_offset_ns
                .checked_mul(1000)
                .filter(|ps| (0..=1_000_000_000).contains(ps))
                .ok_or_else(|| {
                    VendorError::Setting(format!(
                        "T3 offset {t3_offset_ns} ns: a PicoHarp 300 takes 0 to 1 000 000 ns (PH_SetOffset's 0 to 1e9 ps)"
                    ))
                }),
            _ => Ok(t3_offset_ns),
        }
    }

    /// What the environment variable naming this family's library is.
    pub fn library_env(self) -> &'static str {
        match self {
            Family::MultiHarp => "SCATTERSCOPE_MHLIB",
            Family::HydraHarp => "SCATTERSCOPE_HHLIB",
            Family::TimeHarp260 => "SCATTERSCOPE_TH260LIB",
            Family::PicoHarp330 => "SCATTERSCOPE_PH330LIB",
            Family::PicoHarp300 => "SCATTERSCOPE_PHLIB",
        }
    }
}

/// How a device's inputs discriminate pulses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Inputs {
    /// Edge triggers: a level and an edge.
    Edge,
    /// Constant-fraction discriminators: a level and a zero cross.
    Cfd,
}

/// Why the vendor library or a device failed.
#[derive(Debug, Clone, thiserror::Error)]
pub enum VendorError {
    /// No library file could be loaded.
    #[error(
        "no {family} library found: tried {tried}. Install PicoQuant's programming library for Linux (its `install` script puts it in /usr/local/lib64 and links {linker_name}), or name the library file in the settings or in {env}"
    )]
    NotInstalled {
        /// The family searched.
        family: &'static str,
        /// Every file tried, with why it failed.
        tried: String,
        /// The linker-style name the installer creates.
        linker_name: String,
        /// The environment variable that names the file.
        env: &'static str,
    },
    /// The library lacks a function this driver calls.
    #[error("{path}: not a {family} library: {reason}")]
    Symbols {
        /// The library file.
        path: String,
        /// The family expected.
        family: &'static str,
        /// The missing symbol.
        reason: String,
    },
    /// A library call returned an error code.
    #[error("{call} returned error {code} ({text})")]
    Call {
        /// The function.
        call: String,
        /// The library's error code.
        code: i32,
        /// The library's error text.
        text: String,
    },
    /// A setting the family does not have, or out of its range.
    #[error("{0}")]
    Setting(String),
}

type DevFn = unsafe extern "C" fn(c_int) -> c_int;
type DevIntFn = unsafe extern "C" fn(c_int, c_int) -> c_int;
type DevIntIntFn = unsafe extern "C" fn(c_int, c_int, c_int) -> c_int;
type DevIntIntIntFn = unsafe extern "C" fn(c_int, c_int, c_int, c_int) -> c_int;
type DevOutFn = unsafe extern "C" fn(c_int, *mut c_int) -> c_int;
type DevStrFn = unsafe extern "C" fn(c_int, *mut c_char) -> c_int;
type DevDoubleFn = unsafe extern "C" fn(c_int, *mut c_double) -> c_int;

/// The functions this driver calls, resolved once.
struct Functions {
    get_library_version: unsafe extern "C" fn(*mut c_char) -> c_int,
    get_error_string: unsafe extern "C" fn(*mut c_char, c_int) -> c_int,
    open_device: DevStrFn,
    close_device: DevFn,
    initialize: Initialize,
    get_hardware_info: unsafe extern "C" fn(c_int, *mut c_char, *mut c_char, *mut c_char) -> c_int,
    channels: Channels,
    calibrate: Option<DevFn>,
    set_sync_div: DevIntFn,
    /// `SetSyncEdgeTrg` and `SetInputEdgeTrg`, where the family has them.
    edge_triggers: Option<(DevIntIntFn, DevIntIntIntFn)>,
    /// `SetSyncCFD` and `SetInputCFD`, where the family has them.
    cfd_triggers: Option<(DevIntIntFn, DevIntIntIntFn)>,
    set_binning: DevIntFn,
    set_offset: DevIntFn,
    set_marker_enable: unsafe extern "C" fn(c_int, c_int, c_int, c_int, c_int) -> c_int,
    set_marker_edges: unsafe extern "C" fn(c_int, c_int, c_int, c_int, c_int) -> c_int,
    /// `SetSyncTrgMode(devidx, mode)`, `SetInputTrgMode(devidx, channel,
    /// mode)` and `GetFeatures(devidx, &features)`: the PicoHarp 330's
    /// choice of edge trigger or CFD, the inputs' only where the features
    /// say so.
    set_trigger_modes: Option<(DevIntFn, DevIntIntFn, DevOutFn)>,
    get_resolution: DevDoubleFn,
    get_count_rate: unsafe extern "C" fn(c_int, c_int, *mut c_int) -> c_int,
    get_flags: DevOutFn,
    get_warnings: DevOutFn,
    get_warnings_text: unsafe extern "C" fn(c_int, *mut c_char, c_int) -> c_int,
    start_meas: DevIntFn,
    stop_meas: DevFn,
    ctc_status: DevOutFn,
    read_fifo: ReadFifo,
}

/// How a library addresses the sync and the inputs.
#[derive(Clone, Copy)]
enum Channels {
    /// Numbered inputs with their own offsets and enables, and a sync rate
    /// of its own (MHLib, HHLib, TH260Lib, PH330Lib).
    Numbered {
        get_num_of_input_channels: DevOutFn,
        set_sync_channel_offset: DevIntFn,
        set_input_channel_offset: DevIntIntFn,
        set_input_channel_enable: DevIntIntFn,
        get_sync_rate: DevOutFn,
    },
    /// PHLib 3.0: the sync and one input as channels 0 and 1 of
    /// `PH_SetInputCFD(devidx, channel, level, zc)` and of
    /// `PH_GetCountRate`, and `PH_SetSyncOffset(devidx, ps)`.
    SyncAndOne {
        set_input_cfd: DevIntIntIntFn,
        set_sync_offset: DevIntFn,
    },
}

/// The two shapes of `Initialize`.
#[derive(Clone, Copy)]
enum Initialize {
    /// `Initialize(devidx, mode, refsource)` (MHLib, HHLib, PH330Lib).
    WithReference(DevIntIntFn),
    /// `TH260_Initialize(devidx, mode)` (th260lib.h), `PH_Initialize`
    /// (phlib.h).
    ModeOnly(DevIntFn),
}

/// The two shapes of `ReadFiFo`.
#[derive(Clone, Copy)]
enum ReadFifo {
    /// `MH_ReadFiFo(devidx, buffer, *nactual)`: the buffer holds `TTREADMAX`.
    Fixed(unsafe extern "C" fn(c_int, *mut c_uint, *mut c_int) -> c_int),
    /// `HH_ReadFiFo(devidx, buffer, count, *nactual)`.
    Counted(unsafe extern "C" fn(c_int, *mut c_uint, c_int, *mut c_int) -> c_int),
}

/// A loaded vendor library.
pub struct VendorLib {
    family: Family,
    path: PathBuf,
    functions: Functions,
    // Keeps the code the function pointers point into mapped; dropped last.
    _library: libloading::Library,
}

impl std::fmt::Debug for VendorLib {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VendorLib")
            .field("family", &self.family)
            .field("path", &self.path)
            .finish()
    }
}

/// Reads a NUL-terminated string the library wrote into `buf`.
fn text(buf: &[u8]) -> String {
    CStr::from_bytes_until_nul(buf)
        .map(|s| s.to_string_lossy().trim().to_string())
        .unwrap_or_else(|_| String::from_utf8_lossy(buf).trim().to_string())
}

impl VendorLib {
    /// Loads `family`'s library: the file `explicit` names, else the one
    /// the family's environment variable names (when not empty), else the
    /// installer's locations ([`Family::library_candidates`]).
    pub fn load(family: Family, explicit: Option<&Path>) -> Result<Arc<Self>, VendorError> {
        let candidates: Vec<PathBuf> = match explicit {
            Some(p) => vec![p.to_path_buf()],
            // An empty variable is unset (`SCATTERSCOPE_HHLIB= cmd`), not a
            // path to load.
            None => match std::env::var_os(family.library_env()).filter(|p| !p.is_empty()) {
                Some(p) => vec![PathBuf::from(p)],
                None => family.library_candidates(),
            },
        };
        let mut tried = Vec::new();
        for path in &candidates {
            // SAFETY: loading runs the library's initialisers; this is the
            // vendor's library (or its stand-in) that the user named or
            // installed for this purpose.
            match unsafe { libloading::Library::new(path) } {
                Ok(library) => return Self::resolve(family, path.clone(), library).map(Arc::new),
                Err(e) => {
                    let why =
                        std::error::Error::source(&e).map_or(e.to_string(), |s| s.to_string());
                    tried.push(format!("{} ({why})", path.display()))
                }
            }
        }
        Err(VendorError::NotInstalled {
            family: family.name(),
            tried: tried.join("; "),
            linker_name: family.library_candidates()[0].display().to_string(),
            env: family.library_env(),
        })
    }

    fn resolve(
        family: Family,
        path: PathBuf,
        library: libloading::Library,
    ) -> Result<Self, VendorError> {
        let prefix = family.prefix();
        let missing = |name: &str, e: libloading::Error| VendorError::Symbols {
            path: path.display().to_string(),
            family: family.name(),
            reason: format!("{prefix}{name}: {e}"),
        };
        macro_rules! sym {
            ($name:literal) => {{
                let full = format!("{prefix}{}\0", $name);
                // SAFETY: the symbol's type is the one the vendor's header
                // declares for this name.
                unsafe { library.get(full.as_bytes()) }
                    .map(|s: libloading::Symbol<'_, _>| *s)
                    .map_err(|e| missing($name, e))?
            }};
        }
        let edge_triggers = match family {
            Family::MultiHarp | Family::PicoHarp330 | Family::TimeHarp260 => {
                Some((sym!("SetSyncEdgeTrg"), sym!("SetInputEdgeTrg")))
            }
            Family::HydraHarp | Family::PicoHarp300 => None,
        };
        let cfd_triggers = match family {
            Family::HydraHarp | Family::TimeHarp260 => {
                Some((sym!("SetSyncCFD"), sym!("SetInputCFD")))
            }
            Family::MultiHarp | Family::PicoHarp330 | Family::PicoHarp300 => None,
        };
        let channels = match family {
            Family::PicoHarp300 => Channels::SyncAndOne {
                set_input_cfd: sym!("SetInputCFD"),
                set_sync_offset: sym!("SetSyncOffset"),
            },
            _ => Channels::Numbered {
                get_num_of_input_channels: sym!("GetNumOfInputChannels"),
                set_sync_channel_offset: sym!("SetSyncChannelOffset"),
                set_input_channel_offset: sym!("SetInputChannelOffset"),
                set_input_channel_enable: sym!("SetInputChannelEnable"),
                get_sync_rate: sym!("GetSyncRate"),
            },
        };
        let (calibrate, read_fifo) = match family {
            Family::MultiHarp | Family::PicoHarp330 => (None, ReadFifo::Fixed(sym!("ReadFiFo"))),
            Family::HydraHarp | Family::PicoHarp300 => {
                (Some(sym!("Calibrate")), ReadFifo::Counted(sym!("ReadFiFo")))
            }
            Family::TimeHarp260 => (None, ReadFifo::Counted(sym!("ReadFiFo"))),
        };
        let initialize = match family {
            Family::TimeHarp260 | Family::PicoHarp300 => Initialize::ModeOnly(sym!("Initialize")),
            _ => Initialize::WithReference(sym!("Initialize")),
        };
        let set_trigger_modes = match family {
            Family::PicoHarp330 => Some((
                sym!("SetSyncTrgMode"),
                sym!("SetInputTrgMode"),
                sym!("GetFeatures"),
            )),
            _ => None,
        };
        let functions = Functions {
            get_library_version: sym!("GetLibraryVersion"),
            get_error_string: sym!("GetErrorString"),
            open_device: sym!("OpenDevice"),
            close_device: sym!("CloseDevice"),
            initialize,
            get_hardware_info: sym!("GetHardwareInfo"),
            channels,
            calibrate,
            set_sync_div: sym!("SetSyncDiv"),
            edge_triggers,
            cfd_triggers,
            set_binning: sym!("SetBinning"),
            set_offset: sym!("SetOffset"),
            set_marker_enable: sym!("SetMarkerEnable"),
            set_marker_edges: sym!("SetMarkerEdges"),
            set_trigger_modes,
            get_resolution: sym!("GetResolution"),
            get_count_rate: sym!("GetCountRate"),
            get_flags: sym!("GetFlags"),
            get_warnings: sym!("GetWarnings"),
            get_warnings_text: sym!("GetWarningsText"),
            start_meas: sym!("StartMeas"),
            stop_meas: sym!("StopMeas"),
            ctc_status: sym!("CTCStatus"),
            read_fifo,
        };
        Ok(Self {
            family,
            path,
            functions,
            _library: library,
        })
    }

    /// The family this library drives.
    pub fn family(&self) -> Family {
        self.family
    }

    /// The file it was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The library's version string.
    pub fn version(&self) -> String {
        let mut buf = [0u8; 64];
        // SAFETY: the header asks for an 8-byte buffer; this one is larger.
        unsafe { (self.functions.get_library_version)(buf.as_mut_ptr().cast()) };
        text(&buf)
    }

    /// The library's text for `code`.
    pub fn error_text(&self, code: i32) -> String {
        let mut buf = [0u8; 128];
        // SAFETY: the header asks for a 40-byte buffer; this one is larger.
        unsafe { (self.functions.get_error_string)(buf.as_mut_ptr().cast(), code) };
        text(&buf)
    }

    fn check(&self, call: &str, code: c_int) -> Result<(), VendorError> {
        if code < 0 {
            Err(VendorError::Call {
                call: format!("{}{call}", self.family.prefix()),
                code,
                text: self.error_text(code),
            })
        } else {
            Ok(())
        }
    }

    /// The devices this library can open: (index, serial). Each is closed
    /// again after the look.
    pub fn list(&self) -> Vec<(i32, String)> {
        let mut found = Vec::new();
        for index in 0..self.family.max_devices() {
            let mut serial = [0u8; 16];
            // SAFETY: the header asks for an 8-byte serial buffer.
            let code = unsafe { (self.functions.open_device)(index, serial.as_mut_ptr().cast()) };
            if code == 0 {
                found.push((index, text(&serial)));
                // SAFETY: the index was just opened.
                unsafe { (self.functions.close_device)(index) };
            } else if code != ERROR_DEVICE_OPEN_FAIL {
                found.push((index, format!("busy or failing: {}", self.error_text(code))));
            }
        }
        found
    }
}

/// How an input discriminates pulses: an edge trigger (MultiHarp,
/// TimeHarp 260 Nano, PicoHarp 330) or a constant-fraction discriminator
/// (HydraHarp, TimeHarp 260 Pico).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Trigger {
    /// Trigger level (mV: -1200 to 1200, PicoHarp 330 -1500 to 1500) and edge.
    Edge {
        /// Level, mV.
        level_mv: i32,
        /// Rising (else falling) edge.
        rising: bool,
    },
    /// CFD discriminator level and zero cross (mV: 0 to 1000 and 0 to 40
    /// on a HydraHarp, -1200 to 0 and -40 to 0 on a TimeHarp 260 Pico, 0
    /// to 800 and 0 to 20 on a PicoHarp 300).
    Cfd {
        /// Level, mV.
        level_mv: i32,
        /// Zero cross, mV.
        zero_cross_mv: i32,
    },
}

impl Trigger {
    /// The usual setting of `inputs` on `family` for a negative detector
    /// pulse (edges at -50 mV falling, as the vendor demos; a HydraHarp's
    /// CFD at 50 mV, zero cross 10 mV, as its demos; a TimeHarp 260 Pico's
    /// CFD, whose levels th260defin.h gives as negative, at -50 and -10).
    pub fn default_for(family: Family, inputs: Inputs) -> Self {
        match (inputs, family) {
            (Inputs::Edge, _) => Trigger::Edge {
                level_mv: -50,
                rising: false,
            },
            (Inputs::Cfd, Family::TimeHarp260) => Trigger::Cfd {
                level_mv: -50,
                zero_cross_mv: -10,
            },
            (Inputs::Cfd, _) => Trigger::Cfd {
                level_mv: 50,
                zero_cross_mv: 10,
            },
        }
    }

    /// Whether `family`'s `inputs` can take this trigger for its `what`
    /// input (the kind and the header's ranges), before any device is
    /// touched.
    pub fn check(self, family: Family, inputs: Inputs, what: &str) -> Result<(), VendorError> {
        self.args(family, inputs, what).map(|_| ())
    }

    fn args(
        self,
        family: Family,
        inputs: Inputs,
        what: &str,
    ) -> Result<(c_int, c_int), VendorError> {
        let board = family.board(inputs);
        match (inputs, self) {
            (Inputs::Edge, Trigger::Edge { level_mv, rising }) => {
                // TRGLVLMIN/MAX: 1200 mV in mhdefin.h and th260defin.h,
                // 1500 in ph330defin.h.
                let max = if family == Family::PicoHarp330 {
                    1500
                } else {
                    1200
                };
                if !(-max..=max).contains(&level_mv) {
                    return Err(VendorError::Setting(format!(
                        "{what} trigger level {level_mv} mV is outside -{max} to {max} mV (a {board})"
                    )));
                }
                Ok((level_mv, c_int::from(rising)))
            }
            (
                Inputs::Cfd,
                Trigger::Cfd {
                    level_mv,
                    zero_cross_mv,
                },
            ) => {
                // hhdefin.h: 0 to 1000 and 0 to 40 mV; th260defin.h
                // (CFDLVLMIN/MAX, CFDZCMIN/MAX): -1200 to 0 and -40 to 0;
                // phdefin.h (DISCRMIN/MAX, ZCMIN/MAX): 0 to 800 and 0 to 20.
                let (levels, zero_crosses) = match family {
                    Family::TimeHarp260 => (-1200..=0, -40..=0),
                    Family::PicoHarp300 => (0..=800, 0..=20),
                    _ => (0..=1000, 0..=40),
                };
                if !levels.contains(&level_mv) || !zero_crosses.contains(&zero_cross_mv) {
                    return Err(VendorError::Setting(format!(
                        "{what} CFD level {level_mv} mV / zero cross {zero_cross_mv} mV: a {board} takes levels {} to {} mV and zero crosses {} to {} mV",
                        levels.start(),
                        levels.end(),
                        zero_crosses.start(),
                        zero_crosses.end()
                    )));
                }
                Ok((level_mv, zero_cross_mv))
            }
            (Inputs::Edge, Trigger::Cfd { .. }) => Err(VendorError::Setting(format!(
                "{what}: a {board} is driven with edge triggers (level and edge), not a CFD"
            ))),
            (Inputs::Cfd, Trigger::Edge { .. }) => Err(VendorError::Setting(format!(
                "{what}: a {board} has CFD inputs (level and zero cross), not edge triggers"
            ))),
        }
    }
}

impl Family {
    /// The family's board with `inputs`, in words.
    pub fn board(self, inputs: Inputs) -> &'static str {
        match (self, inputs) {
            (Family::MultiHarp, _) => "MultiHarp",
            (Family::HydraHarp, _) => "HydraHarp",
            (Family::TimeHarp260, Inputs::Cfd) => "TimeHarp 260 Pico",
            (Family::TimeHarp260, Inputs::Edge) => "TimeHarp 260 Nano",
            (Family::PicoHarp330, _) => "PicoHarp 330",
            (Family::PicoHarp300, _) => "PicoHarp 300",
        }
    }
}

/// The settings a lab sets before a T3 measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// Sync divider (1 to [`Family::sync_divider_max`]).
    pub sync_divider: i32,
    /// The sync input's discriminator.
    pub sync_trigger: Trigger,
    /// Sync channel offset, ps (a cable delay).
    pub sync_offset_ps: i32,
    /// Every input's discriminator.
    pub input_trigger: Trigger,
    /// Per-input offsets, ps (missing inputs: 0).
    pub input_offsets_ps: Vec<i32>,
    /// Binning code: the micro time unit is the base resolution times
    /// 2^binning.
    pub binning: i32,
    /// T3 offset, ns: the libraries take nanoseconds (MHLib's header
    /// gives `MH_SetOffset`'s range 0 to 100 000 000 ns; the HHLib manual
    /// calls it the histogram time offset in ns, though HHLib's header
    /// comments its 0 to 500 000 range as ps).
    pub t3_offset_ns: i32,
    /// Enable the four marker inputs (line and frame clocks of a scanner).
    pub markers: bool,
    /// The markers' active edge: rising (else falling); set with them.
    pub markers_rising: bool,
}

impl Settings {
    /// Whether `family` can take what these settings ask besides the
    /// triggers, for a device of `inputs` inputs: per-input offsets (none
    /// on a PicoHarp 300, whose PHLib has no `SetInputChannelOffset`; no
    /// more than the inputs elsewhere), the binning code (below
    /// `BINSTEPSMAX` where the header bounds it) and the T3 offset
    /// ([`Family::offset_arg`]). A refusal names the field of these
    /// settings it is about.
    pub fn check_family(
        &self,
        family: Family,
        inputs: i32,
    ) -> Result<(), (&'static str, VendorError)> {
        if family == Family::PicoHarp300 && !self.input_offsets_ps.is_empty() {
            return Err((
                "input_offsets_ps",
                VendorError::Setting(
                    "input offsets: a PicoHarp 300 has none (PHLib sets only a sync offset, PH_SetSyncOffset)".into(),
                ),
            ));
        }
        if self.input_offsets_ps.len() > usize::try_from(inputs).unwrap_or(0) {
            return Err((
                "input_offsets_ps",
                VendorError::Setting(format!(
                    "{} input offsets given; the device has {inputs} inputs",
                    self.input_offsets_ps.len()
                )),
            ));
        }
        if let Some(max) = family.binning_max()
            && !(0..=max).contains(&self.binning)
        {
            return Err((
                "binning",
                VendorError::Setting(format!(
                    "binning code {}: a {} takes 0 to {max} (BINSTEPSMAX or MAXBINSTEPS {} in its header)",
                    self.binning,
                    family.name(),
                    max + 1
                )),
            ));
        }
        family
            .offset_arg(self.t3_offset_ns)
            .map(|_| ())
            .map_err(|e| ("t3_offset_ns", e))
    }

    /// The vendor demos' settings for `family`'s `inputs`.
    pub fn default_for(family: Family, inputs: Inputs) -> Self {
        let input_trigger = match family {
            // PHLib 3.0's C demos (tttrmode.c): `CFDLevel0=50` for the
            // sync, `CFDLevel1=150` for the input, zero cross 10 mV.
            Family::PicoHarp300 => Trigger::Cfd {
                level_mv: 150,
                zero_cross_mv: 10,
            },
            _ => Trigger::default_for(family, inputs),
        };
        Self {
            sync_divider: 1,
            sync_trigger: Trigger::default_for(family, inputs),
            sync_offset_ps: 0,
            input_trigger,
            input_offsets_ps: Vec::new(),
            binning: 0,
            t3_offset_ns: 0,
            markers: false,
            markers_rising: true,
        }
    }
}

/// What an opened device is.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DeviceInfo {
    /// Device index in the library.
    pub index: i32,
    /// Serial number.
    pub serial: String,
    /// Model, part number and version as the library reports them.
    pub model: String,
    /// Part number.
    pub part: String,
    /// Hardware version.
    pub version: String,
    /// Input channels.
    pub inputs: i32,
    /// The library's version.
    pub library_version: String,
    /// The library file.
    pub library: String,
}

/// An opened, initialised device in T3 mode; closed on drop.
pub struct Device {
    lib: Arc<VendorLib>,
    info: DeviceInfo,
    inputs: Inputs,
}

/// Status of a running measurement, read between FIFO reads: the flag
/// bits and the family whose header gives them their meaning.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Flags(pub i32, pub Family);

impl Flags {
    /// The FIFO overran: records were lost.
    pub fn fifo_full(self) -> bool {
        let bits = match self.1 {
            Family::PicoHarp300 => FLAG_FIFO_FULL_PH300,
            _ => FLAG_FIFO_FULL,
        };
        self.0 & bits != 0
    }

    /// The bit by which the family says it dropped counts (phdefin.h has
    /// none).
    fn dropped_bit(self) -> i32 {
        match self.1 {
            Family::TimeHarp260 => FLAG_EVTS_DROPPED_TH260,
            Family::PicoHarp300 => 0,
            _ => FLAG_CNTS_DROPPED,
        }
    }

    /// The device dropped counts before they reached its FIFO.
    pub fn counts_dropped(self) -> bool {
        self.0 & self.dropped_bit() != 0
    }

    /// The conditions other than an overrun, in words.
    pub fn problems(self) -> Vec<&'static str> {
        // A TimeHarp 260 has no reference-clock flag: its 0x0008 is the
        // dropped events (th260defin.h). A PicoHarp 300 has neither sync
        // nor reference flags, and its own system-error bit (phdefin.h).
        let (sync_lost, ref_lost, sys_error) = match self.1 {
            Family::TimeHarp260 => (FLAG_SYNC_LOST, 0, FLAG_SYS_ERROR),
            Family::PicoHarp300 => (0, 0, FLAG_SYS_ERROR_PH300),
            _ => (FLAG_SYNC_LOST, FLAG_REF_LOST, FLAG_SYS_ERROR),
        };
        // The software-error flags the TimeHarp 260's and PicoHarp 330's
        // headers define (the other families' headers at hand have none).
        let soft_error = match self.1 {
            Family::TimeHarp260 => FLAG_SOFT_ERROR_TH260,
            Family::PicoHarp330 => FLAG_SOFT_ERROR_PH330,
            _ => 0,
        };
        [
            (
                self.dropped_bit(),
                "counts dropped in the device (more than it could take; how many it does not say)",
            ),
            (sync_lost, "sync lost"),
            (ref_lost, "reference clock lost"),
            (
                sys_error,
                "hardware error (the vendor asks to contact support)",
            ),
            (
                soft_error,
                "software error in the device (the vendor asks to contact support)",
            ),
        ]
        .into_iter()
        .filter(|(bit, _)| self.0 & bit != 0)
        .map(|(_, words)| words)
        .collect()
    }
}

impl Device {
    /// Opens the device with `serial` (or the first one) and initialises it
    /// in T3 mode with the internal clock.
    pub fn open(lib: Arc<VendorLib>, serial: Option<&str>) -> Result<Self, VendorError> {
        let f = &lib.functions;
        let listed = lib.list();
        let Some((index, found)) = listed
            .iter()
            .find(|(_, s)| serial.is_none_or(|want| s == want) && !s.starts_with("busy"))
            .cloned()
        else {
            let seen: Vec<String> = listed.iter().map(|(i, s)| format!("#{i} {s}")).collect();
            return Err(VendorError::Setting(format!(
                "no {} {} found by {} (devices seen: {})",
                lib.family.name(),
                serial.map_or("device".into(), |s| format!("with serial {s}")),
                lib.path.display(),
                if seen.is_empty() {
                    "none".into()
                } else {
                    seen.join(", ")
                }
            )));
        };
        let mut buf = [0u8; 16];
        // SAFETY: an 8-byte serial buffer is asked for; 16 are given.
        lib.check("OpenDevice", unsafe {
            (f.open_device)(index, buf.as_mut_ptr().cast())
        })?;
        let mut device = Self {
            inputs: Inputs::Edge,
            info: DeviceInfo {
                index,
                serial: found,
                model: String::new(),
                part: String::new(),
                version: String::new(),
                inputs: 0,
                library_version: lib.version(),
                library: lib.path.display().to_string(),
            },
            lib: lib.clone(),
        };
        // SAFETY: the index is open.
        // SAFETY: the index is open; each shape as its header declares it
        // (reference source 0: the internal clock).
        lib.check("Initialize", unsafe {
            match f.initialize {
                Initialize::WithReference(init) => init(index, MODE_T3, 0),
                Initialize::ModeOnly(init) => init(index, MODE_T3),
            }
        })?;
        let (mut model, mut part, mut version) = ([0u8; 64], [0u8; 16], [0u8; 32]);
        // SAFETY: buffers at least the header's sizes (32, 8, 16).
        lib.check("GetHardwareInfo", unsafe {
            (f.get_hardware_info)(
                index,
                model.as_mut_ptr().cast(),
                part.as_mut_ptr().cast(),
                version.as_mut_ptr().cast(),
            )
        })?;
        let inputs = match f.channels {
            Channels::Numbered {
                get_num_of_input_channels,
                ..
            } => {
                let mut inputs = 0;
                // SAFETY: one int out.
                lib.check("GetNumOfInputChannels", unsafe {
                    get_num_of_input_channels(index, &mut inputs)
                })?;
                inputs
            }
            // Channel 1 of `PH_SetInputCFD`, the one input.
            Channels::SyncAndOne { .. } => 1,
        };
        device.info.model = text(&model);
        device.inputs = match lib.family.inputs() {
            Some(inputs) => inputs,
            // HWIDENT_PICO / HWIDENT_NANO of th260defin.h.
            None if device.info.model.starts_with("TimeHarp 260 P") => Inputs::Cfd,
            None if device.info.model.starts_with("TimeHarp 260 N") => Inputs::Edge,
            None => {
                return Err(VendorError::Setting(format!(
                    "{} reports the model {:?}, neither a TimeHarp 260 P nor N",
                    lib.path.display(),
                    device.info.model
                )));
            }
        };
        device.info.part = text(&part);
        device.info.version = text(&version);
        device.info.inputs = inputs;
        if let Some(calibrate) = f.calibrate {
            // SAFETY: the device is initialised.
            lib.check("Calibrate", unsafe { calibrate(index) })?;
        }
        Ok(device)
    }

    /// What the device is.
    pub fn info(&self) -> &DeviceInfo {
        &self.info
    }

    /// The family's record layout and read size.
    pub fn family(&self) -> Family {
        self.lib.family
    }

    /// How this board's inputs discriminate.
    pub fn inputs(&self) -> Inputs {
        self.inputs
    }

    /// The PTU record type code of this board's T3 records.
    pub fn t3_record_type(&self) -> u32 {
        match (self.lib.family, self.inputs) {
            (Family::MultiHarp | Family::PicoHarp330, _) => 0x0001_0307,
            (Family::HydraHarp, _) => 0x0101_0304,
            (Family::TimeHarp260, Inputs::Edge) => 0x0001_0305,
            (Family::TimeHarp260, Inputs::Cfd) => 0x0001_0306,
            (Family::PicoHarp300, _) => 0x0001_0303,
        }
    }

    /// Applies `s`; returns the micro-time resolution (ps) it gives.
    pub fn configure(&mut self, s: &Settings) -> Result<f64, VendorError> {
        let (lib, i) = (&self.lib, self.info.index);
        let f = &lib.functions;
        let family = lib.family;
        let (sync_a, sync_b) = s.sync_trigger.args(family, self.inputs, "sync")?;
        let (in_a, in_b) = s.input_trigger.args(family, self.inputs, "input")?;
        s.check_family(family, self.info.inputs)
            .map_err(|(_, e)| e)?;
        let offset = family.offset_arg(s.t3_offset_ns)?;
        // SAFETY (every call below): plain integer arguments on an open,
        // initialised device.
        unsafe {
            lib.check("SetSyncDiv", (f.set_sync_div)(i, s.sync_divider))?;
            match f.channels {
                Channels::Numbered {
                    set_sync_channel_offset,
                    set_input_channel_offset,
                    set_input_channel_enable,
                    ..
                } => {
                    let (triggers, (sync_call, input_call)) = match self.inputs {
                        Inputs::Edge => (f.edge_triggers, ("SetSyncEdgeTrg", "SetInputEdgeTrg")),
                        Inputs::Cfd => (f.cfd_triggers, ("SetSyncCFD", "SetInputCFD")),
                    };
                    let (set_sync_trigger, set_input_trigger) = triggers.ok_or_else(|| {
                        VendorError::Setting(format!(
                            "the {} library has no {sync_call} for its inputs",
                            family.name()
                        ))
                    })?;
                    // The inputs' trigger mode is set only on a device
                    // whose features have FEATURE_INPT_MODE (0x0200 in
                    // ph330defin.h); without it they stay edge triggers.
                    let mut input_modes = None;
                    if let Some((sync_mode, input_mode, get_features)) = f.set_trigger_modes {
                        // TRGMODE_ETR 0 (ph330defin.h): edge triggers, then
                        // their level and edge below.
                        lib.check("SetSyncTrgMode", sync_mode(i, 0))?;
                        let mut features: c_int = 0;
                        lib.check("GetFeatures", get_features(i, &mut features))?;
                        if features & FEATURE_INPT_MODE != 0 {
                            input_modes = Some(input_mode);
                        }
                    }
                    lib.check(sync_call, set_sync_trigger(i, sync_a, sync_b))?;
                    lib.check(
                        "SetSyncChannelOffset",
                        set_sync_channel_offset(i, s.sync_offset_ps),
                    )?;
                    for ch in 0..self.info.inputs {
                        // Every input on, not left to the library's default
                        // (`SetInputChannelEnable(devidx, channel, enable)`
                        // in the vendor's hhlib.h and mhlib.h).
                        lib.check("SetInputChannelEnable", set_input_channel_enable(i, ch, 1))?;
                        if let Some(input_mode) = input_modes {
                            lib.check("SetInputTrgMode", input_mode(i, ch, 0))?;
                        }
                        lib.check(input_call, set_input_trigger(i, ch, in_a, in_b))?;
                        let offset = s.input_offsets_ps.get(ch as usize).copied().unwrap_or(0);
                        lib.check(
                            "SetInputChannelOffset",
                            set_input_channel_offset(i, ch, offset),
                        )?;
                    }
                }
                Channels::SyncAndOne {
                    set_input_cfd,
                    set_sync_offset,
                } => {
                    // The vendor's TTTR demo: the sync offset, then the CFD
                    // of channel 0 (the sync) and of channel 1 (the input).
                    lib.check("SetSyncOffset", set_sync_offset(i, s.sync_offset_ps))?;
                    lib.check("SetInputCFD", set_input_cfd(i, 0, sync_a, sync_b))?;
                    lib.check("SetInputCFD", set_input_cfd(i, 1, in_a, in_b))?;
                }
            }
            // A setting the library refuses is named with its value (the
            // PicoHarp 330's header bounds neither; its library checks).
            let refused = |what: String, code: c_int| {
                VendorError::Setting(format!(
                    "{what}: the {} library refused it ({}, error {code})",
                    lib.family.name(),
                    lib.error_text(code)
                ))
            };
            let code = (f.set_binning)(i, s.binning);
            if code < 0 {
                return Err(refused(
                    format!(
                        "binning code {} (bins of 2^{} base steps)",
                        s.binning, s.binning
                    ),
                    code,
                ));
            }
            let code = (f.set_offset)(i, offset);
            if code < 0 {
                return Err(refused(format!("T3 offset {} ns", s.t3_offset_ns), code));
            }
            let m = c_int::from(s.markers);
            if s.markers {
                // `SetMarkerEdges(devidx, me1, me2, me3, me4)`, each
                // EDGE_RISING 1 or EDGE_FALLING 0 (mhdefin.h, hhdefin.h).
                let e = c_int::from(s.markers_rising);
                lib.check("SetMarkerEdges", (f.set_marker_edges)(i, e, e, e, e))?;
            }
            lib.check("SetMarkerEnable", (f.set_marker_enable)(i, m, m, m, m))?;
            let mut resolution = 0.0;
            lib.check("GetResolution", (f.get_resolution)(i, &mut resolution))?;
            Ok(resolution)
        }
    }

    /// Sync rate (Hz) and per-input count rates (counts/s).
    pub fn rates(&self) -> Result<(i32, Vec<i32>), VendorError> {
        let (lib, i) = (&self.lib, self.info.index);
        let count_rate = |ch: c_int| {
            let mut r = 0;
            // SAFETY: one int out.
            lib.check("GetCountRate", unsafe {
                (lib.functions.get_count_rate)(i, ch, &mut r)
            })
            .map(|()| r)
        };
        match lib.functions.channels {
            Channels::Numbered { get_sync_rate, .. } => {
                let mut sync = 0;
                // SAFETY: one int out.
                lib.check("GetSyncRate", unsafe { get_sync_rate(i, &mut sync) })?;
                let rates = (0..self.info.inputs)
                    .map(count_rate)
                    .collect::<Result<_, _>>()?;
                Ok((sync, rates))
            }
            // PHLib: count rate 0 is the sync's, 1 the input's.
            Channels::SyncAndOne { .. } => Ok((count_rate(0)?, vec![count_rate(1)?])),
        }
    }

    /// The library's warnings about the current rates and settings, as
    /// its text (empty when none). Call after [`Device::rates`].
    pub fn warnings(&self) -> Result<String, VendorError> {
        let (lib, i) = (&self.lib, self.info.index);
        let mut bits = 0;
        // SAFETY: one int out.
        lib.check("GetWarnings", unsafe {
            (lib.functions.get_warnings)(i, &mut bits)
        })?;
        if bits == 0 {
            return Ok(String::new());
        }
        let mut buf = vec![0u8; 16384];
        // SAFETY: the header asks for a 16384-byte buffer.
        lib.check("GetWarningsText", unsafe {
            (lib.functions.get_warnings_text)(i, buf.as_mut_ptr().cast(), bits)
        })?;
        Ok(text(&buf))
    }

    /// Starts a measurement of `duration_ms` (the device stops by itself
    /// after it).
    pub fn start(&mut self, duration_ms: i32) -> Result<(), VendorError> {
        // SAFETY: plain arguments.
        self.lib.check("StartMeas", unsafe {
            (self.lib.functions.start_meas)(self.info.index, duration_ms)
        })
    }

    /// Stops the measurement.
    pub fn stop(&mut self) -> Result<(), VendorError> {
        // SAFETY: plain arguments.
        self.lib.check("StopMeas", unsafe {
            (self.lib.functions.stop_meas)(self.info.index)
        })
    }

    /// The status flags.
    pub fn flags(&self) -> Result<Flags, VendorError> {
        let mut flags = 0;
        // SAFETY: one int out.
        self.lib.check("GetFlags", unsafe {
            (self.lib.functions.get_flags)(self.info.index, &mut flags)
        })?;
        Ok(Flags(flags, self.lib.family))
    }

    /// Whether the measurement time has elapsed.
    pub fn finished(&self) -> Result<bool, VendorError> {
        let mut status = 0;
        // SAFETY: one int out.
        self.lib.check("CTCStatus", unsafe {
            (self.lib.functions.ctc_status)(self.info.index, &mut status)
        })?;
        Ok(status != 0)
    }

    /// Reads the records waiting in the FIFO into `buf` (resized to the
    /// family's read size) and returns how many there were.
    pub fn read_fifo(&mut self, buf: &mut Vec<u32>) -> Result<usize, VendorError> {
        let max = self.lib.family.fifo_read_max();
        buf.resize(max, 0);
        let mut n: c_int = 0;
        let i = self.info.index;
        // SAFETY: the buffer holds the family's TTREADMAX records.
        let code = unsafe {
            match self.lib.functions.read_fifo {
                ReadFifo::Fixed(read) => read(i, buf.as_mut_ptr(), &mut n),
                ReadFifo::Counted(read) => read(i, buf.as_mut_ptr(), max as c_int, &mut n),
            }
        };
        self.lib.check("ReadFiFo", code)?;
        let n = usize::try_from(n).unwrap_or(0).min(max);
        buf.truncate(n);
        Ok(n)
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: the index was opened by this handle.
        unsafe {
            (self.lib.functions.stop_meas)(self.info.index);
            (self.lib.functions.close_device)(self.info.index);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The software-error bits mean what each header says: 0x0020 is
    /// `FLAG_SOFTERROR` in th260defin.h but `FLAG_ACTIVE` (running) in
    /// hhdefin.h; PH330Lib's is 0x0080.
    #[test]
    fn software_errors_are_read_in_each_familys_own_bits() {
        let soft = |bits, family| {
            Flags(bits, family)
                .problems()
                .iter()
                .any(|p| p.contains("software error"))
        };
        assert!(soft(0x0020, Family::TimeHarp260));
        assert!(!soft(0x0020, Family::HydraHarp));
        assert!(!soft(0x0020, Family::PicoHarp330));
        assert!(soft(0x0080, Family::PicoHarp330));
        assert!(!soft(0x0080, Family::MultiHarp));
    }
}
