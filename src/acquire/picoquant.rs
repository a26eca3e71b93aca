//! An acquisition from a PicoQuant time tagger (MultiHarp, HydraHarp)
//! through the vendor's library: the device opened and set up, its FIFO read
//! in a loop on its own thread, every record streamed raw into a PTU file
//! and decoded into the same binner `bin` uses, and a ledger of where every
//! record went. A FIFO overrun, a device error or a device that disappears
//! ends the run with what was read saved and the reason in the ledger;
//! Ctrl-C ends it the same way.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use scatterscope_drivers::picoquant::{
    Device, DeviceInfo, Family, Flags, Settings, Trigger, VendorError, VendorLib,
};
use serde::Serialize;

use crate::formats::picoquant::records::{Decoder, RecordType};
use crate::formats::picoquant::writer::{Completion, HeaderEntry, PtuWriter, WriterHeader};
use crate::formats::png::{SheetScale, write_contact_sheet};
use crate::stack::{Stack, StackMeta};
use crate::tags::Imaging;
use crate::tags::bin_file::{BinSpec, window_and_map};
use crate::tags::binning::{Accounting, Binner};

/// FIFO reads that may wait for the writer and binner before the reader
/// stops reading (the device's own FIFO then buffers).
const QUEUE_DEPTH: usize = 8;
/// How often the progress callback runs.
const PROGRESS_EVERY: Duration = Duration::from_millis(200);
/// The longest measurement the libraries accept (100 h), for runs that end
/// on Ctrl-C.
const MAX_MEASUREMENT_MS: i32 = 360_000_000;

/// Which PicoQuant device: `--device picoquant[:FAMILY][:SERIAL]`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PicoQuantSpec {
    /// The family (`None`: MultiHarp, else HydraHarp, whichever library
    /// loads and has a device).
    pub family: Option<Family>,
    /// The serial number (`None`: the first device).
    pub serial: Option<String>,
}

impl PicoQuantSpec {
    /// Parses what follows `picoquant` in a device address: empty,
    /// `:FAMILY`, `:FAMILY:SERIAL` or `::SERIAL`.
    pub fn parse(rest: &str) -> Result<Self, String> {
        let mut parts = rest.split(':');
        let family = match parts.next().unwrap_or("") {
            "" => None,
            "multiharp" | "mh" => Some(Family::MultiHarp),
            "hydraharp" | "hh" => Some(Family::HydraHarp),
            other => {
                return Err(format!(
                    "unknown PicoQuant family `{other}`: use multiharp (mh) or hydraharp (hh), e.g. picoquant:multiharp:1045678"
                ));
            }
        };
        let serial = parts.next().filter(|s| !s.is_empty()).map(String::from);
        if parts.next().is_some() {
            return Err("a PicoQuant address is picoquant[:FAMILY][:SERIAL]".into());
        }
        Ok(Self { family, serial })
    }
}

impl std::fmt::Display for PicoQuantSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "picoquant")?;
        match (&self.family, &self.serial) {
            (None, None) => Ok(()),
            (Some(fam), None) => write!(f, ":{}", fam.name()),
            (fam, Some(s)) => write!(f, ":{}:{s}", fam.map_or("", Family::name)),
        }
    }
}

/// Input settings as a user gives them; unset fields take the family's
/// defaults (the vendor demos' values).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SettingsRequest {
    /// Sync divider.
    pub sync_divider: Option<i32>,
    /// Sync trigger or CFD level, mV.
    pub sync_level_mv: Option<i32>,
    /// Sync edge (MultiHarp): rising if true.
    pub sync_rising: Option<bool>,
    /// Sync CFD zero cross, mV (HydraHarp).
    pub sync_zero_cross_mv: Option<i32>,
    /// Sync channel offset, ps.
    pub sync_offset_ps: Option<i32>,
    /// Input trigger or CFD level, mV.
    pub input_level_mv: Option<i32>,
    /// Input edge (MultiHarp): rising if true.
    pub input_rising: Option<bool>,
    /// Input CFD zero cross, mV (HydraHarp).
    pub input_zero_cross_mv: Option<i32>,
    /// The scan markers' active edge: rising if true (default rising).
    pub markers_rising: Option<bool>,
    /// Per-input offsets, ps.
    pub input_offsets_ps: Vec<i32>,
    /// Binning code (micro-time unit = base resolution x 2^binning).
    pub binning: Option<i32>,
    /// T3 offset, ns (the unit the vendor's libraries take).
    pub offset_ns: Option<i32>,
}

impl SettingsRequest {
    /// The settings for `family`; an edge given for a HydraHarp or a zero
    /// cross for a MultiHarp is an error naming the flag.
    pub fn resolve(&self, family: Family, markers: bool) -> Result<Settings, VendorError> {
        let mut s = Settings::default_for(family);
        let trigger = |base: Trigger,
                       level: Option<i32>,
                       rising: Option<bool>,
                       zc: Option<i32>,
                       what: &str|
         -> Result<Trigger, VendorError> {
            match (base, rising, zc) {
                (Trigger::Edge { .. }, _, Some(_)) => Err(VendorError::Setting(format!(
                    "--{what}-zero-cross: a MultiHarp input has an edge trigger (use --{what}-edge)"
                ))),
                (Trigger::Cfd { .. }, Some(_), _) => Err(VendorError::Setting(format!(
                    "--{what}-edge: a HydraHarp input has a CFD (use --{what}-zero-cross)"
                ))),
                (
                    Trigger::Edge {
                        level_mv,
                        rising: r,
                    },
                    _,
                    _,
                ) => Ok(Trigger::Edge {
                    level_mv: level.unwrap_or(level_mv),
                    rising: rising.unwrap_or(r),
                }),
                (
                    Trigger::Cfd {
                        level_mv,
                        zero_cross_mv,
                    },
                    _,
                    _,
                ) => Ok(Trigger::Cfd {
                    level_mv: level.unwrap_or(level_mv),
                    zero_cross_mv: zc.unwrap_or(zero_cross_mv),
                }),
            }
        };
        s.sync_trigger = trigger(
            s.sync_trigger,
            self.sync_level_mv,
            self.sync_rising,
            self.sync_zero_cross_mv,
            "sync",
        )?;
        s.input_trigger = trigger(
            s.input_trigger,
            self.input_level_mv,
            self.input_rising,
            self.input_zero_cross_mv,
            "input",
        )?;
        s.sync_divider = self.sync_divider.unwrap_or(s.sync_divider);
        s.sync_offset_ps = self.sync_offset_ps.unwrap_or(s.sync_offset_ps);
        s.input_offsets_ps = self.input_offsets_ps.clone();
        s.binning = self.binning.unwrap_or(s.binning);
        s.offset_ns = self.offset_ns.unwrap_or(s.offset_ns);
        s.markers = markers;
        s.markers_rising = self.markers_rising.unwrap_or(s.markers_rising);
        Ok(s)
    }
}

/// One acquisition from a PicoQuant device.
#[derive(Debug, Clone)]
pub struct PicoQuantJob {
    /// Which device.
    pub spec: PicoQuantSpec,
    /// The vendor library file (`None`: the environment variable, then the
    /// installer's locations).
    pub library: Option<PathBuf>,
    /// Input settings.
    pub settings: SettingsRequest,
    /// Measurement time (`None`: until Ctrl-C, at most 100 h).
    pub duration: Option<Duration>,
    /// The stack's window and pixels, as for `bin`.
    pub bin: BinSpec,
    /// The scanner's image (its markers enabled); `None`: a point detector
    /// or channels.
    pub scan: Option<Imaging>,
    /// Write every record to this PTU file (`None`: no PTU).
    pub ptu: Option<PathBuf>,
    /// The software, for the PTU header.
    pub software: String,
    /// Output directory (created if missing).
    pub out: PathBuf,
}

/// Why a PicoQuant acquisition ended.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PicoQuantStop {
    /// The measurement time elapsed.
    Duration,
    /// Ctrl-C or SIGTERM.
    Interrupted,
    /// The device's FIFO overran: records after it were lost in the device.
    FifoOverrun,
    /// A library call failed mid-run (the device's text).
    DeviceError(String),
}

impl PicoQuantStop {
    /// In words.
    pub fn describe(&self) -> String {
        match self {
            Self::Duration => "the measurement time elapsed".into(),
            Self::Interrupted => "interrupted (Ctrl-C or SIGTERM)".into(),
            Self::FifoOverrun => "FIFO overrun: the device lost records and stopped (lower the count rate, or read faster)".into(),
            Self::DeviceError(e) => format!("device error: {e}"),
        }
    }
}

/// Where every record went.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct PicoQuantLedger {
    /// Records read from the device's FIFO.
    pub records_read: u64,
    /// Records decoded by the binner (equal to the above).
    pub records_decoded: u64,
    /// Photon records.
    pub photons: u64,
    /// Photons in a stack bin.
    pub binned: u64,
    /// Photons outside the time window.
    pub outside_window: u64,
    /// Photons on other channels than the one selected.
    pub other_channel: u64,
    /// Photons outside the scanned image.
    pub outside_region: u64,
    /// Marker records.
    pub markers: u64,
    /// Frames seen (scans).
    pub frames: u64,
    /// Records written to the PTU file.
    pub records_in_ptu: u64,
    /// Whether the device's FIFO overran (it lost records, how many it
    /// does not say).
    pub fifo_overrun: bool,
    /// Whether the device dropped counts before its FIFO (MultiHarp's
    /// `FLAG_CNTS_DROPPED`; how many it does not say).
    pub counts_dropped: bool,
}

impl PicoQuantLedger {
    fn from(
        read: u64,
        acc: &Accounting,
        ptu: u64,
        fifo_overrun: bool,
        counts_dropped: bool,
    ) -> Self {
        Self {
            records_read: read,
            records_decoded: acc.records,
            photons: acc.received,
            binned: acc.binned,
            outside_window: acc.outside_window,
            other_channel: acc.other_channel,
            outside_region: acc.outside_region + acc.over_budget,
            markers: acc.markers,
            frames: acc.frames,
            records_in_ptu: ptu,
            fifo_overrun,
            counts_dropped,
        }
    }

    /// Whether the device lost photons it detected (an overrun or dropped
    /// counts): then no ledger of what was read says what was detected.
    pub fn lost_in_device(&self) -> bool {
        self.fifo_overrun || self.counts_dropped
    }

    /// Whether every record read is decoded and every photon in one place
    /// (and, with `ptu`, every record in the PTU).
    pub fn balances(&self, ptu: bool) -> bool {
        self.records_read == self.records_decoded
            && self.photons
                == self.binned + self.outside_window + self.other_channel + self.outside_region
            && (!ptu || self.records_in_ptu == self.records_read)
    }

    /// A table for the terminal.
    pub fn table(&self, ptu: bool) -> Vec<String> {
        let line = |name: &str, v: String| format!("  {name:<28} {v:>14}");
        let mut t = vec![
            line("records read from the FIFO", self.records_read.to_string()),
            line("  photons", self.photons.to_string()),
            line("    binned", self.binned.to_string()),
            line(
                "    outside the time window",
                self.outside_window.to_string(),
            ),
            line("    on other channels", self.other_channel.to_string()),
            line("    outside the image", self.outside_region.to_string()),
            line("  markers", self.markers.to_string()),
            line("records in the PTU file", self.records_in_ptu.to_string()),
            line(
                "lost in the device (FIFO)",
                if self.fifo_overrun {
                    "yes, count unknown".into()
                } else {
                    "0".into()
                },
            ),
            line(
                "dropped in the device",
                if self.counts_dropped {
                    "yes, count unknown".into()
                } else {
                    "0".into()
                },
            ),
        ];
        t.push(match (self.balances(ptu), self.lost_in_device()) {
            (true, false) => "  balance: every record read is accounted for".into(),
            (true, true) => "  balance: every record read is accounted for, but the device lost photons it detected (how many it does not say): this is not the whole measurement".into(),
            (false, _) => "  balance: DOES NOT BALANCE (please report)".into(),
        });
        t
    }
}

/// The PTU file of an acquisition.
#[derive(Debug, Clone, Serialize)]
pub struct PtuOutcome {
    /// The file.
    pub path: PathBuf,
    /// Records in it.
    pub records: u64,
    /// Why writing it stopped early, if it did (the stack is still saved).
    pub error: Option<String>,
}

/// A finished PicoQuant acquisition.
#[derive(Debug, Clone, Serialize)]
pub struct PicoQuantAcquisition {
    /// What the device is.
    pub device: DeviceInfo,
    /// Micro-time unit, ps.
    pub resolution_ps: f64,
    /// Sync rate at the start, Hz.
    pub sync_rate_hz: f64,
    /// Count rates per input at the start, counts/s.
    pub count_rates: Vec<i32>,
    /// The rates read during the run, every [`RATE_EVERY`].
    pub rates_during_run: Vec<RateSample>,
    /// The library's warnings at the start and any flags seen during the run.
    pub warnings: Vec<String>,
    /// Why it ended.
    pub stop: PicoQuantStop,
    /// Where every record went.
    pub ledger: PicoQuantLedger,
    /// The PTU file, if one was asked for.
    pub ptu: Option<PtuOutcome>,
    /// Seconds from start to the last record.
    pub elapsed_s: f64,
    /// Records read per second.
    pub records_per_s: f64,
    /// The files written.
    pub files: Vec<PathBuf>,
    /// The binned stack.
    #[serde(skip)]
    pub stack: Option<Stack>,
}

impl PicoQuantAcquisition {
    /// The summary lines the CLI prints.
    pub fn summary(&self) -> Vec<String> {
        let d = &self.device;
        let mut lines = vec![
            format!(
                "{} serial {} (library {} {}), {:.0} ps micro-time unit, sync {:.3} MHz",
                d.model,
                d.serial,
                d.library,
                d.library_version,
                self.resolution_ps,
                self.sync_rate_hz / 1e6
            ),
            format!(
                "count rates at the start: {}",
                self.count_rates
                    .iter()
                    .enumerate()
                    .map(|(i, r)| format!("input {i} {r}/s"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ];
        lines.extend(self.warnings.iter().map(|w| format!("warning: {w}")));
        lines.push(format!(
            "ended: {} after {:.2} s ({:.1} M records/s)",
            self.stop.describe(),
            self.elapsed_s,
            self.records_per_s / 1e6
        ));
        lines.extend(self.ledger.table(self.ptu_complete()));
        if let Some(p) = &self.ptu {
            lines.push(match &p.error {
                None => format!("PTU: {} ({} records)", p.path.display(), p.records),
                Some(e) => format!(
                    "PTU INCOMPLETE: {} was handed the first {} records: {e}",
                    p.path.display(),
                    p.records
                ),
            });
        }
        lines
    }

    /// Whether a PTU file was written to the end.
    fn ptu_complete(&self) -> bool {
        self.ptu.as_ref().is_some_and(|p| p.error.is_none())
    }

    /// Ok when everything read was saved; else why not (the stack is
    /// saved either way).
    pub fn verdict(&self) -> Result<(), String> {
        if let Some(PtuOutcome { error: Some(e), .. }) = &self.ptu {
            return Err(format!("the PTU file is incomplete: {e}"));
        }
        if !self.ledger.balances(self.ptu_complete()) {
            return Err("the record ledger does not balance".into());
        }
        if self.ledger.counts_dropped {
            return Err(
                "the device dropped counts (its flags say so; how many it does not say): the stack and PTU hold what it sent".into(),
            );
        }
        match &self.stop {
            PicoQuantStop::FifoOverrun => Err(self.stop.describe()),
            PicoQuantStop::DeviceError(e) => Err(format!(
                "the device failed mid-run ({e}); what was read is saved"
            )),
            _ => Ok(()),
        }
    }
}

/// Why a PicoQuant acquisition could not run.
#[derive(Debug, thiserror::Error)]
pub enum PicoQuantError {
    /// The library or the device.
    #[error(transparent)]
    Vendor(#[from] VendorError),
    /// The window or pixels do not fit.
    #[error("{0}")]
    Spec(String),
    /// An output could not be written.
    #[error("{0}")]
    Output(String),
}

/// Loads the library for `spec` (the family given, else MultiHarp, else
/// HydraHarp: the first that loads).
pub fn load_library(
    spec: &PicoQuantSpec,
    library: Option<&Path>,
) -> Result<std::sync::Arc<VendorLib>, VendorError> {
    match spec.family {
        Some(f) => VendorLib::load(f, library),
        None => {
            let mut errors = Vec::new();
            for f in Family::ALL {
                match VendorLib::load(f, library) {
                    Ok(lib) if library.is_some() || !lib.list().is_empty() => return Ok(lib),
                    Ok(_) => errors.push(format!("{} library loaded, no device", f.name())),
                    Err(e) => errors.push(e.to_string()),
                }
            }
            Err(VendorError::Setting(errors.join("\n")))
        }
    }
}

/// The PicoQuant devices the installed libraries (or `library`) can open,
/// as `devices` lists them, and a note per library that did not load.
pub fn list_picoquant(library: Option<&Path>) -> (Vec<(String, String)>, Vec<String>) {
    let mut found = Vec::new();
    let mut notes = Vec::new();
    for family in Family::ALL {
        match VendorLib::load(family, library) {
            Ok(lib) => {
                for (_, serial) in lib.list() {
                    found.push((
                        PicoQuantSpec {
                            family: Some(family),
                            serial: Some(serial.clone()),
                        }
                        .to_string(),
                        format!(
                            "PicoQuant {} (library {}, version {})",
                            family.name(),
                            lib.path().display(),
                            lib.version()
                        ),
                    ));
                }
            }
            Err(e) => notes.push(e.to_string()),
        }
        if library.is_some() && !found.is_empty() {
            break;
        }
    }
    (found, notes)
}

/// Progress of a running acquisition.
#[derive(Debug, Clone)]
pub struct PicoQuantProgress {
    /// Since the start.
    pub elapsed: Duration,
    /// Records read so far.
    pub records: u64,
    /// The latest rates read from the device: sync (Hz) and each input
    /// (counts/s).
    pub rates: Option<(i32, Vec<i32>)>,
}

/// How often the rates are read from the library during a run.
pub const RATE_EVERY: Duration = Duration::from_millis(100);

/// The device's rates at one moment of a run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RateSample {
    /// Seconds since the measurement started.
    pub t_s: f64,
    /// Sync rate, Hz.
    pub sync_hz: i32,
    /// Count rate of each input, counts/s.
    pub inputs: Vec<i32>,
}

/// The reader thread's end.
struct ReaderEnd {
    stop: PicoQuantStop,
    flag_notes: Vec<String>,
    /// The device's flags said it dropped counts.
    counts_dropped: bool,
    /// The rates read during the run, every [`RATE_EVERY`].
    rates: Vec<RateSample>,
    /// When the measurement started (after the device's own set-up).
    started: Instant,
}

/// The PTU header of an acquisition: the measurement's settings as
/// PicoQuant's software names them.
fn header(
    device: &DeviceInfo,
    settings: &Settings,
    resolution_ps: f64,
    sync_hz: f64,
    job: &PicoQuantJob,
) -> WriterHeader {
    let binning = 1i64 << settings.binning.clamp(0, 30);
    let mut extra = vec![
        (
            "HW_SerialNo".to_string(),
            HeaderEntry::Text(device.serial.clone()),
        ),
        ("HW_PartNo".into(), HeaderEntry::Text(device.part.clone())),
        (
            "HW_Version".into(),
            HeaderEntry::Text(device.version.clone()),
        ),
        (
            "HW_InpChannels".into(),
            HeaderEntry::Int(i64::from(device.inputs) + 1),
        ),
        (
            "HWSync_Divider".into(),
            HeaderEntry::Int(i64::from(settings.sync_divider)),
        ),
        (
            "HWSync_Offset".into(),
            HeaderEntry::Int(i64::from(settings.sync_offset_ps)),
        ),
        (
            "HW_BaseResolution".into(),
            HeaderEntry::Float(resolution_ps / binning as f64 * 1e-12),
        ),
        ("MeasDesc_BinningFactor".into(), HeaderEntry::Int(binning)),
        (
            "MeasDesc_Offset".into(),
            // In the unit the device was programmed in (ns), as the
            // library reports it.
            HeaderEntry::Int(i64::from(settings.offset_ns)),
        ),
        (
            "CreatorSW_Name".into(),
            HeaderEntry::Text(job.software.clone()),
        ),
    ];
    match settings.input_trigger {
        Trigger::Edge { level_mv, rising } => {
            extra.push((
                "HWInpChan_TrgLevel".into(),
                HeaderEntry::Int(i64::from(level_mv)),
            ));
            extra.push((
                "HWInpChan_TrgEdge".into(),
                HeaderEntry::Int(i64::from(rising)),
            ));
        }
        Trigger::Cfd {
            level_mv,
            zero_cross_mv,
        } => {
            extra.push((
                "HWInpChan_CFDLevel".into(),
                HeaderEntry::Int(i64::from(level_mv)),
            ));
            extra.push((
                "HWInpChan_CFDZeroX".into(),
                HeaderEntry::Int(i64::from(zero_cross_mv)),
            ));
        }
    }
    if let Some(d) = job.duration {
        extra.push((
            "MeasDesc_AcquisitionTime".into(),
            HeaderEntry::Int(d.as_millis() as i64),
        ));
    }
    if job.scan.is_some() {
        extra.push(("ImgHdr_Dimensions".into(), HeaderEntry::Int(3)));
        extra.push(("ImgHdr_Ident".into(), HeaderEntry::Int(9)));
    }
    WriterHeader {
        resolution_s: resolution_ps * 1e-12,
        sync_rate_hz: sync_hz,
        device: device.model.clone(),
        imaging: job.scan,
        extra,
    }
}

impl PicoQuantJob {
    /// Runs the acquisition; `stop` ends it early (Ctrl-C); `on_progress`
    /// sees its progress.
    pub fn run(
        &self,
        stop: &AtomicBool,
        mut on_progress: impl FnMut(PicoQuantProgress),
    ) -> Result<PicoQuantAcquisition, PicoQuantError> {
        let lib = load_library(&self.spec, self.library.as_deref())?;
        let family = lib.family();
        let mut device = Device::open(lib, self.spec.serial.as_deref())?;
        let settings = self.settings.resolve(family, self.scan.is_some())?;
        let resolution_ps = device.configure(&settings)?;
        // The libraries report valid rates 100-150 ms after a set-up.
        std::thread::sleep(Duration::from_millis(150));
        let (sync_rate, count_rates) = device.rates()?;
        let mut warnings: Vec<String> = device
            .warnings()?
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .map(String::from)
            .collect();
        if sync_rate <= 0 {
            return Err(PicoQuantError::Spec(format!(
                "the sync rate is {sync_rate}/s: no laser sync reaches the device (check the cable and --sync-level)"
            )));
        }
        let sync_hz = f64::from(sync_rate);
        let record_type = RecordType::from_code(family.t3_record_type())
            .expect("the family's record type is known");
        let (window, map) = window_and_map(&self.bin, resolution_ps, 1e12 / sync_hz, self.scan)
            .map_err(|e| PicoQuantError::Spec(e.to_string()))?;
        std::fs::create_dir_all(&self.out)
            .map_err(|e| PicoQuantError::Output(format!("{}: {e}", self.out.display())))?;
        let info = device.info().clone();
        let mut ptu_error = None;
        let mut writer = match &self.ptu {
            Some(path) => {
                let h = header(&info, &settings, resolution_ps, sync_hz, self);
                match PtuWriter::create_recording(path, record_type, &h) {
                    Ok(w) => Some(w),
                    Err(e) => {
                        ptu_error = Some(format!("creating {}: {e}", path.display()));
                        None
                    }
                }
            }
            None => None,
        };

        let duration_ms = self.duration.map_or(MAX_MEASUREMENT_MS, |d| {
            (d.as_millis() as i32).clamp(1, MAX_MEASUREMENT_MS)
        });
        let (full_tx, full_rx) = mpsc::sync_channel::<Vec<u32>>(QUEUE_DEPTH);
        let (empty_tx, empty_rx) = mpsc::channel::<Vec<u32>>();
        let started = Instant::now();
        let mut binner = Binner::new(window, map, self.bin.channel, self.bin.frames);
        let mut decoder = Decoder::new(record_type);
        let mut records_read = 0u64;
        let mut records_before_error = 0u64;
        let latest_rates: std::sync::Mutex<Option<(i32, Vec<i32>)>> = std::sync::Mutex::new(None);
        let latest_rates = &latest_rates;
        let end = std::thread::scope(|scope| {
            let reader = scope.spawn(move || {
                let mut flag_notes: Vec<String> = Vec::new();
                let mut counts_dropped = false;
                // What the flags say besides an overrun, each said once.
                let mut note_flags = |f: Flags, notes: &mut Vec<String>| {
                    counts_dropped |= f.counts_dropped();
                    for p in f.problems() {
                        if !notes.iter().any(|n| n == p) {
                            notes.push(p.to_string());
                        }
                    }
                };
                let mut rates = Vec::new();
                let fail = |e: VendorError| PicoQuantStop::DeviceError(e.to_string());
                if let Err(e) = device.start(duration_ms) {
                    return ReaderEnd {
                        stop: fail(e),
                        flag_notes,
                        counts_dropped,
                        rates,
                        started: Instant::now(),
                    };
                }
                let measuring = Instant::now();
                let mut rates_read: Option<Instant> = None;
                let mut spare: Option<Vec<u32>> = None;
                let stop_reason = loop {
                    if stop.load(Ordering::Relaxed) {
                        break PicoQuantStop::Interrupted;
                    }
                    if rates_read.is_none_or(|t| t.elapsed() >= RATE_EVERY) {
                        rates_read = Some(Instant::now());
                        if let Ok((sync_hz, inputs)) = device.rates() {
                            *latest_rates.lock().unwrap_or_else(|e| e.into_inner()) =
                                Some((sync_hz, inputs.clone()));
                            rates.push(RateSample {
                                t_s: measuring.elapsed().as_secs_f64(),
                                sync_hz,
                                inputs,
                            });
                        }
                    }
                    match device.flags() {
                        Ok(f) if f.fifo_full() => break PicoQuantStop::FifoOverrun,
                        Ok(f) => note_flags(f, &mut flag_notes),
                        Err(e) => break fail(e),
                    }
                    let mut buf = spare
                        .take()
                        .or_else(|| empty_rx.try_recv().ok())
                        .unwrap_or_default();
                    match device.read_fifo(&mut buf) {
                        Ok(0) => {
                            spare = Some(buf);
                            // An overrun shows in the flags after the last
                            // records; the measurement then reads as finished.
                            if device.flags().is_ok_and(|f| f.fifo_full()) {
                                break PicoQuantStop::FifoOverrun;
                            }
                            match device.finished() {
                                Ok(true) => break PicoQuantStop::Duration,
                                Ok(false) => std::thread::sleep(Duration::from_millis(1)),
                                Err(e) => break fail(e),
                            }
                        }
                        Ok(_) => {
                            if full_tx.send(buf).is_err() {
                                break PicoQuantStop::Interrupted;
                            }
                        }
                        Err(e) => break fail(e),
                    }
                };
                // The flags once more: a drop during the last read.
                if let Ok(f) = device.flags() {
                    note_flags(f, &mut flag_notes);
                }
                // Stop, then close (on drop): the device's own end.
                let _ = device.stop();
                drop(device);
                ReaderEnd {
                    stop: stop_reason,
                    flag_notes,
                    counts_dropped,
                    rates,
                    started: measuring,
                }
            });
            let mut last = Instant::now();
            for chunk in full_rx {
                records_read += chunk.len() as u64;
                if let Some(w) = writer.as_mut()
                    && let Err(e) = w.write_records(&chunk)
                {
                    ptu_error = Some(format!(
                        "writing {}: {e}",
                        self.ptu.as_deref().unwrap_or(Path::new("")).display()
                    ));
                    // Handed over before the failing read (some may still
                    // have been in the writer's buffer).
                    records_before_error = w.records() - chunk.len() as u64;
                    writer = None;
                }
                binner.bulk(|sink| decoder.decode_all(&chunk, sink));
                let _ = empty_tx.send(chunk);
                if last.elapsed() >= PROGRESS_EVERY {
                    last = Instant::now();
                    on_progress(PicoQuantProgress {
                        elapsed: started.elapsed(),
                        records: records_read,
                        rates: latest_rates
                            .lock()
                            .unwrap_or_else(|e| e.into_inner())
                            .clone(),
                    });
                }
            }
            reader.join().expect("the FIFO reader does not panic")
        });
        let elapsed_s = end.started.elapsed().as_secs_f64();
        warnings.extend(end.flag_notes);
        let mut records_in_ptu = records_before_error;
        let mut ptu = None;
        if let Some(path) = &self.ptu {
            if let Some(w) = writer {
                records_in_ptu = w.records();
                let completion = if end.stop == PicoQuantStop::Duration {
                    Completion::Complete
                } else {
                    Completion::Interrupted
                };
                if let Err(e) = w.finish_as(completion) {
                    ptu_error = Some(format!("closing {}: {e}", path.display()));
                }
            }
            ptu = Some(PtuOutcome {
                path: path.clone(),
                records: records_in_ptu,
                error: ptu_error,
            });
        }
        let (stacks, acc) = binner.finish();
        let ledger = PicoQuantLedger::from(
            records_read,
            &acc,
            records_in_ptu,
            end.stop == PicoQuantStop::FifoOverrun,
            end.counts_dropped,
        );
        let source = format!(
            "{} serial {} ({})",
            info.model,
            info.serial,
            record_type.name()
        );
        let stack = Stack::from_counts(
            stacks[0].view(),
            StackMeta::measured(
                window.start_ps(resolution_ps),
                window.width_ps(resolution_ps),
                window.bins,
                source,
                None,
            ),
        );
        let mut done = PicoQuantAcquisition {
            device: info,
            resolution_ps,
            sync_rate_hz: sync_hz,
            count_rates,
            rates_during_run: end.rates,
            warnings,
            stop: end.stop,
            ledger,
            ptu,
            elapsed_s,
            records_per_s: records_read as f64 / elapsed_s.max(1e-9),
            files: Vec::new(),
            stack: None,
        };
        done.files = self.write(&done, &stack)?;
        done.stack = Some(stack);
        Ok(done)
    }

    /// Writes the stack, its contact sheet and `acquisition.json`.
    fn write(
        &self,
        done: &PicoQuantAcquisition,
        stack: &Stack,
    ) -> Result<Vec<PathBuf>, PicoQuantError> {
        let out_err = |e: String| PicoQuantError::Output(e);
        let exr = self.out.join("stack.exr");
        stack.save(&exr).map_err(|e| out_err(e.to_string()))?;
        let png = self.out.join("stack.png");
        write_contact_sheet(stack, SheetScale::Shared, &png).map_err(|e| out_err(e.to_string()))?;
        let json = self.out.join("acquisition.json");
        let text = serde_json::to_string_pretty(done).expect("the record serialises");
        crate::files::write_atomic(&json, text)
            .map_err(|e| out_err(format!("{}: {e}", json.display())))?;
        let mut files = vec![exr, png, json];
        if let Some(p) = &done.ptu {
            files.push(p.path.clone());
        }
        Ok(files)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_parse_and_print_back() {
        for (text, family, serial) in [
            ("", None, None),
            ("multiharp", Some(Family::MultiHarp), None),
            ("hh", Some(Family::HydraHarp), None),
            (
                "hydraharp:1045678",
                Some(Family::HydraHarp),
                Some("1045678"),
            ),
            (":1045678", None, Some("1045678")),
        ] {
            let spec = PicoQuantSpec::parse(text).unwrap();
            assert_eq!(spec.family, family, "{text}");
            assert_eq!(spec.serial.as_deref(), serial, "{text}");
            let printed = spec.to_string();
            let rest = printed.strip_prefix("picoquant").unwrap();
            let rest = rest.strip_prefix(':').unwrap_or(rest);
            assert_eq!(PicoQuantSpec::parse(rest).unwrap(), spec, "{printed}");
        }
        let e = PicoQuantSpec::parse("timeharp").unwrap_err();
        assert!(e.contains("timeharp") && e.contains("multiharp"), "{e}");
        assert!(PicoQuantSpec::parse("mh:1:2").is_err());
    }

    #[test]
    fn settings_take_the_family_defaults_and_refuse_the_other_familys_fields() {
        let none = SettingsRequest::default();
        let mh = none.resolve(Family::MultiHarp, false).unwrap();
        assert_eq!(mh, Settings::default_for(Family::MultiHarp));
        let req = SettingsRequest {
            sync_level_mv: Some(-80),
            sync_rising: Some(true),
            binning: Some(2),
            ..SettingsRequest::default()
        };
        let s = req.resolve(Family::MultiHarp, true).unwrap();
        assert_eq!(
            s.sync_trigger,
            Trigger::Edge {
                level_mv: -80,
                rising: true
            }
        );
        assert_eq!(s.binning, 2);
        assert!(s.markers);
        let e = req
            .resolve(Family::HydraHarp, false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("--sync-edge") && e.contains("CFD"), "{e}");
        let zc = SettingsRequest {
            input_zero_cross_mv: Some(10),
            ..SettingsRequest::default()
        };
        let e = zc
            .resolve(Family::MultiHarp, false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("--input-zero-cross"), "{e}");
        assert!(zc.resolve(Family::HydraHarp, false).is_ok());
    }

    #[test]
    fn the_ledger_balances_only_when_every_record_is_placed() {
        let acc = Accounting {
            records: 10,
            received: 8,
            binned: 5,
            outside_window: 2,
            other_channel: 1,
            ..Accounting::default()
        };
        let l = PicoQuantLedger::from(10, &acc, 10, false, false);
        assert!(l.balances(true));
        assert!(!PicoQuantLedger::from(11, &acc, 10, false, false).balances(false));
        assert!(!PicoQuantLedger::from(10, &acc, 9, false, false).balances(true));
        assert!(PicoQuantLedger::from(10, &acc, 9, false, false).balances(false));
    }
}
