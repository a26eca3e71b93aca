//! A PicoQuant time tagger (MultiHarp, HydraHarp, TimeHarp 260, PicoHarp
//! 330, PicoHarp 300) through the vendor's
//! library as an acquisition source: its address and settings, the library
//! found and loaded, the device opened and set up, and its FIFO read in a
//! loop on its own thread, the records handed raw to the pipeline (which
//! records them in a PTU file and bins them as `bin` does). A FIFO overrun,
//! a device error or a device that disappears ends the run with what was
//! read; Ctrl-C ends it the same way.

use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use scatterscope_drivers::picoquant::{
    Device, DeviceInfo as DriverInfo, Family, Flags, Inputs, Settings, Trigger, VendorError,
    VendorLib,
};

use super::source::{
    Delivery, DeviceInfo, Layout, RateSample, RecordFormat, Source, SourceEnd, SourceError,
    SourceFacts, StartRequest, StopReason, Until,
};
use crate::events::Imaging;
use crate::formats::picoquant::records::RecordType;
use crate::formats::picoquant::writer::HeaderEntry;

/// FIFO reads that may wait for the writer and binner before the reader
/// stops reading (the device's own FIFO then buffers).
const QUEUE_DEPTH: usize = 8;
/// The longest measurement the libraries accept (100 h: `ACQTMAX`
/// 360000000 ms in phdefin.h and th260defin.h, as in the other families'
/// headers), for runs that end on Ctrl-C.
pub const MAX_MEASUREMENT_MS: i32 = 360_000_000;

/// Which PicoQuant device: `--device picoquant[:FAMILY][:SERIAL]`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PicoQuantSpec {
    /// The family (`None`: the first of [`Family::ALL`] whose library loads
    /// and has a device).
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
            "timeharp260" | "th260" => Some(Family::TimeHarp260),
            "picoharp330" | "ph330" => Some(Family::PicoHarp330),
            "picoharp" | "picoharp300" | "ph300" => Some(Family::PicoHarp300),
            other => {
                return Err(format!(
                    "unknown PicoQuant family `{other}`: use multiharp (mh), hydraharp (hh), timeharp260 (th260), picoharp330 (ph330) or picoharp (picoharp300, ph300), e.g. picoquant:multiharp:1045678"
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
    pub t3_offset_ns: Option<i32>,
}

impl SettingsRequest {
    /// The settings for `family`; an edge given for a HydraHarp, a zero
    /// cross for a MultiHarp or PicoHarp 330, a level or sync divider out
    /// of the family's range is an error naming the setting (a field of
    /// this request). The families differ as the vendors' headers do:
    /// mhlib.h sets inputs with `MH_SetSyncEdgeTrg` / `MH_SetInputEdgeTrg`
    /// (level and edge), hhlib.h with `HH_SetSyncCFD` / `HH_SetInputCFD`
    /// (level and zero cross), ph330lib.h with either (this driver sets
    /// edge triggers); levels and dividers as their `*defin.h` bound them.
    pub fn resolve(
        &self,
        family: Family,
        inputs: Inputs,
        markers: bool,
    ) -> Result<Settings, SourceError> {
        let mut s = Settings::default_for(family, inputs);
        let trigger = |base: Trigger,
                       level: Option<i32>,
                       rising: Option<bool>,
                       zc: Option<i32>,
                       [edge, zero_cross]: [&'static str; 2]|
         -> Result<Trigger, SourceError> {
            match (base, rising, zc) {
                (Trigger::Edge { .. }, _, Some(_)) => Err(SourceError::setting(
                    zero_cross,
                    format!(
                        "{zero_cross}: a {} input is driven with an edge trigger, not a CFD (set {edge})",
                        family.board(inputs)
                    ),
                )),
                (Trigger::Cfd { .. }, Some(_), _) => Err(SourceError::setting(
                    edge,
                    format!(
                        "{edge}: a {} input has a CFD, not an edge trigger (set {zero_cross})",
                        family.board(inputs)
                    ),
                )),
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
            ["sync_rising", "sync_zero_cross_mv"],
        )?;
        s.input_trigger = trigger(
            s.input_trigger,
            self.input_level_mv,
            self.input_rising,
            self.input_zero_cross_mv,
            ["input_rising", "input_zero_cross_mv"],
        )?;
        for (t, field, what) in [
            (s.sync_trigger, "sync_level_mv", "sync"),
            (s.input_trigger, "input_level_mv", "input"),
        ] {
            t.check(family, inputs, what)
                .map_err(|e| SourceError::setting(field, e.to_string()))?;
        }
        self.check_divider(family)?;
        s.sync_divider = self.sync_divider.unwrap_or(s.sync_divider);
        s.sync_offset_ps = self.sync_offset_ps.unwrap_or(s.sync_offset_ps);
        s.input_offsets_ps = self.input_offsets_ps.clone();
        s.binning = self.binning.unwrap_or(s.binning);
        s.t3_offset_ns = self.t3_offset_ns.unwrap_or(s.t3_offset_ns);
        s.markers = markers;
        s.markers_rising = self.markers_rising.unwrap_or(s.markers_rising);
        // The inputs' count is the device's to say; what the family cannot
        // take whatever it is, is refused here.
        s.check_family(family, i32::MAX)
            .map_err(|(field, e)| SourceError::setting(field, e.to_string()))?;
        Ok(s)
    }
}

/// A PicoQuant device as `--device picoquant...` names it, with its
/// settings: what [`super::open_device`] needs to open it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PicoQuantDevice {
    /// Which device.
    pub spec: PicoQuantSpec,
    /// The vendor library file (`None`: the environment variable, then the
    /// installer's locations).
    pub library: Option<PathBuf>,
    /// Input settings.
    pub settings: SettingsRequest,
    /// The scanner's image (its markers enabled); `None`: a point detector
    /// or channels.
    pub scan: Option<Imaging>,
}

impl SettingsRequest {
    /// Whether `family` takes the sync divider asked for (its header's
    /// `SYNCDIVMAX`).
    pub fn check_divider(&self, family: Family) -> Result<(), SourceError> {
        let max = family.sync_divider_max();
        match self.sync_divider {
            Some(d) if !(1..=max).contains(&d) => Err(SourceError::setting(
                "sync_divider",
                format!(
                    "sync divider {d}: a {} divides the sync by 1 to {max}",
                    family.name()
                ),
            )),
            Some(d) if family.sync_divider_powers_of_two() && !(d as u32).is_power_of_two() => {
                Err(SourceError::setting(
                    "sync_divider",
                    format!(
                        "sync divider {d}: a {} divides the sync by 1, 2, 4 or 8 (its manual's values)",
                        family.name()
                    ),
                ))
            }
            // The sync period is taken from PH_GetCountRate(0), and no
            // PHLib text (phdefin.h, phlib.h, the v3.0 demos, which set
            // `SyncDivider = 1` "READ MANUAL!") says whether that rate is
            // counted before or after the divider; if after, every macro
            // time and the one-period window would be off by the divider.
            // Refused until a vendor source settles it.
            Some(d) if d > 1 && family == Family::PicoHarp300 => Err(SourceError::setting(
                "sync_divider",
                format!(
                    "sync divider {d}: on a PicoHarp 300 the sync period comes from PH_GetCountRate(0), and no PHLib text says whether that rate is counted before or after the divider, so the macro times could be off by {d}; use 1"
                ),
            )),
            _ => Ok(()),
        }
    }
}

impl PicoQuantDevice {
    /// With the family named, whether it can take the settings asked for
    /// ([`SettingsRequest::resolve`]): checked before any library is
    /// loaded or device touched. Without a family, and a TimeHarp 260's
    /// triggers (Pico or Nano is the board's to say), at the start.
    pub fn check_settings(&self) -> Result<(), SourceError> {
        let Some(family) = self.spec.family else {
            return Ok(());
        };
        match family.inputs() {
            Some(inputs) => self
                .settings
                .resolve(family, inputs, self.scan.is_some())
                .map(|_| ()),
            // The board's kind of input is the device's to say; what the
            // family's header bounds whatever the board is checked now.
            None => {
                self.settings.check_divider(family)?;
                let r = &self.settings;
                let mut s = Settings::default_for(family, Inputs::Edge);
                s.binning = r.binning.unwrap_or(s.binning);
                s.t3_offset_ns = r.t3_offset_ns.unwrap_or(s.t3_offset_ns);
                s.input_offsets_ps = r.input_offsets_ps.clone();
                s.check_family(family, i32::MAX)
                    .map_err(|(field, e)| SourceError::setting(field, e.to_string()))
            }
        }
    }
}

impl std::fmt::Display for PicoQuantDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.spec.fmt(f)
    }
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

/// A PicoQuant device opened through its library, as an acquisition
/// [`Source`]: set up at the start, its FIFO read in a loop on a thread
/// of its own (reads handed to the pipeline in order), its rates read
/// every [`RATE_EVERY`] and its flags after every read.
pub struct PicoQuantSource {
    request: PicoQuantDevice,
    device: Option<Device>,
}

impl PicoQuantSource {
    /// Loads the library and opens the device `request` names.
    pub fn open(request: &PicoQuantDevice) -> Result<Self, VendorError> {
        let lib = load_library(&request.spec, request.library.as_deref())?;
        let device = Device::open(lib, request.spec.serial.as_deref())?;
        Ok(Self {
            request: request.clone(),
            device: Some(device),
        })
    }
}

/// How often the rates are read from the library during a run.
pub const RATE_EVERY: Duration = Duration::from_millis(100);

/// What the reader thread found besides records.
struct ReaderEnd {
    stop: StopReason,
    flag_notes: Vec<String>,
    /// The device's flags said it dropped counts.
    counts_dropped: bool,
    /// When the measurement started (after the device's own set-up).
    started: Instant,
}

/// From the reader thread to the pipeline.
enum FromReader {
    Records(Vec<u32>),
    Rates(RateSample),
}

/// The PTU header tags of a run with `settings` on `device`, as
/// PicoQuant's software names them.
fn ptu_tags(
    device: &DriverInfo,
    settings: &Settings,
    resolution_ps: f64,
) -> Vec<(String, HeaderEntry)> {
    let binning = 1i64 << settings.binning.clamp(0, 30);
    let mut tags = vec![
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
            // In ns, the unit the libraries take (a PicoHarp 300 was sent
            // the same offset in ps, `Family::offset_arg`).
            HeaderEntry::Int(i64::from(settings.t3_offset_ns)),
        ),
    ];
    match settings.input_trigger {
        Trigger::Edge { level_mv, rising } => {
            tags.push((
                "HWInpChan_TrgLevel".into(),
                HeaderEntry::Int(i64::from(level_mv)),
            ));
            tags.push((
                "HWInpChan_TrgEdge".into(),
                HeaderEntry::Int(i64::from(rising)),
            ));
        }
        Trigger::Cfd {
            level_mv,
            zero_cross_mv,
        } => {
            tags.push((
                "HWInpChan_CFDLevel".into(),
                HeaderEntry::Int(i64::from(level_mv)),
            ));
            tags.push((
                "HWInpChan_CFDZeroX".into(),
                HeaderEntry::Int(i64::from(zero_cross_mv)),
            ));
        }
    }
    if settings.markers {
        tags.push(("ImgHdr_Dimensions".into(), HeaderEntry::Int(3)));
        tags.push(("ImgHdr_Ident".into(), HeaderEntry::Int(9)));
    }
    tags
}

fn vendor(e: VendorError) -> SourceError {
    SourceError::Device(e.to_string())
}

impl Source for PicoQuantSource {
    fn start(&mut self, request: &StartRequest) -> Result<SourceFacts, SourceError> {
        request.refuse_micro_time_unit(
            "a micro-time unit in femtoseconds configures our own devices; a PicoQuant device takes a binning code N instead (unit = base resolution x 2^N)",
        )?;
        let device = self.device.as_mut().expect("started once");
        let family = device.family();
        let settings =
            self.request
                .settings
                .resolve(family, device.inputs(), self.request.scan.is_some())?;
        let resolution_ps = device.configure(&settings).map_err(vendor)?;
        // The libraries report valid rates 100-150 ms after a set-up.
        std::thread::sleep(Duration::from_millis(150));
        let (sync_rate, count_rates) = device.rates().map_err(vendor)?;
        let mut warnings: Vec<String> = device
            .warnings()
            .map_err(vendor)?
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .map(String::from)
            .collect();
        let info = device.info();
        if family == Family::TimeHarp260
            && device.inputs() == Inputs::Edge
            && info.library_version.trim().starts_with("3.1")
        {
            // TH260Lib 3.2's release notes: 3.1 inverted the Nano's input
            // edge setting.
            warnings.push(format!(
                "TH260Lib {} drives a TimeHarp 260 Nano's input edges inverted (TH260Lib 3.2's release notes); install 3.2 or newer, or give the opposite --input-edge",
                info.library_version.trim()
            ));
        }
        if sync_rate <= 0 {
            return Err(SourceError::setting(
                "sync_level_mv",
                format!(
                    "the sync rate is {sync_rate}/s: no laser sync reaches the device (check the cable and the sync level)"
                ),
            ));
        }
        let record_type = RecordType::from_code(device.t3_record_type())
            .expect("the family's record type is known");
        let info = device.info().clone();
        Ok(SourceFacts {
            device: DeviceInfo {
                link: self.request.spec.to_string(),
                model: info.model.clone(),
                serial: info.serial.clone(),
                version: info.version.clone(),
                library: Some(format!("{} {}", info.library, info.library_version)),
            },
            resolution_ps,
            sync_period_ps: 1e12 / f64::from(sync_rate),
            format: RecordFormat::T3(record_type),
            layout: Layout::Inputs {
                count: usize::try_from(info.inputs).unwrap_or(0),
                scan: self.request.scan,
            },
            rates_at_start: Some(RateSample {
                t_s: 0.0,
                sync_hz: f64::from(sync_rate),
                inputs: count_rates.iter().map(|&r| f64::from(r)).collect(),
            }),
            warnings,
            ptu_tags: ptu_tags(&info, &settings, resolution_ps),
        })
    }

    fn stream(&mut self, until: Until<'_>, sink: &mut dyn FnMut(Delivery<'_>)) -> SourceEnd {
        let Until { duration, stop } = until;
        let mut device = self.device.take().expect("streamed once");
        // Longer durations are refused with the request (ACQTMAX); the
        // conversion saturates instead of wrapping all the same.
        let duration_ms = duration.map_or(MAX_MEASUREMENT_MS, |d| {
            i32::try_from(d.as_millis())
                .unwrap_or(i32::MAX)
                .clamp(1, MAX_MEASUREMENT_MS)
        });
        let (full_tx, full_rx) = mpsc::sync_channel::<FromReader>(QUEUE_DEPTH);
        let (empty_tx, empty_rx) = mpsc::channel::<Vec<u32>>();
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
                let fail = |e: VendorError| StopReason::DeviceError(e.to_string());
                if let Err(e) = device.start(duration_ms) {
                    return ReaderEnd {
                        stop: fail(e),
                        flag_notes,
                        counts_dropped,
                        started: Instant::now(),
                    };
                }
                let measuring = Instant::now();
                let mut rates_read: Option<Instant> = None;
                let mut spare: Option<Vec<u32>> = None;
                let stop_reason = loop {
                    if stop.load(Ordering::Relaxed) {
                        break StopReason::Interrupted;
                    }
                    if rates_read.is_none_or(|t| t.elapsed() >= RATE_EVERY) {
                        rates_read = Some(Instant::now());
                        if let Ok((sync_hz, inputs)) = device.rates() {
                            let sample = RateSample {
                                t_s: measuring.elapsed().as_secs_f64(),
                                sync_hz: f64::from(sync_hz),
                                inputs: inputs.iter().map(|&r| f64::from(r)).collect(),
                            };
                            if full_tx.send(FromReader::Rates(sample)).is_err() {
                                break StopReason::Interrupted;
                            }
                        }
                    }
                    match device.flags() {
                        Ok(f) if f.fifo_full() => break StopReason::FifoOverrun,
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
                                break StopReason::FifoOverrun;
                            }
                            match device.finished() {
                                Ok(true) => break StopReason::Duration,
                                Ok(false) => std::thread::sleep(Duration::from_millis(1)),
                                Err(e) => break fail(e),
                            }
                        }
                        Ok(_) => {
                            if full_tx.send(FromReader::Records(buf)).is_err() {
                                break StopReason::Interrupted;
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
                    started: measuring,
                }
            });
            for message in full_rx {
                match message {
                    FromReader::Records(chunk) => {
                        sink(Delivery::Records(&chunk));
                        let _ = empty_tx.send(chunk);
                    }
                    FromReader::Rates(r) => sink(Delivery::Rates(&r)),
                }
            }
            reader.join().expect("the FIFO reader does not panic")
        });
        SourceEnd {
            fifo_overrun: end.stop == StopReason::FifoOverrun,
            elapsed: end.started.elapsed(),
            counts_dropped: end.counts_dropped,
            warnings: end.flag_notes,
            ..SourceEnd::ended(end.stop)
        }
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
            ("ph330", Some(Family::PicoHarp330), None),
            (
                "picoharp330:1045678",
                Some(Family::PicoHarp330),
                Some("1045678"),
            ),
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
        let mh = none
            .resolve(Family::MultiHarp, Inputs::Edge, false)
            .unwrap();
        assert_eq!(mh, Settings::default_for(Family::MultiHarp, Inputs::Edge));
        let req = SettingsRequest {
            sync_level_mv: Some(-80),
            sync_rising: Some(true),
            binning: Some(2),
            ..SettingsRequest::default()
        };
        let s = req.resolve(Family::MultiHarp, Inputs::Edge, true).unwrap();
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
            .resolve(Family::HydraHarp, Inputs::Cfd, false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("sync_rising") && e.contains("CFD"), "{e}");
        let zc = SettingsRequest {
            input_zero_cross_mv: Some(10),
            ..SettingsRequest::default()
        };
        let e = zc
            .resolve(Family::MultiHarp, Inputs::Edge, false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("input_zero_cross_mv"), "{e}");
        assert!(zc.resolve(Family::HydraHarp, Inputs::Cfd, false).is_ok());
    }
}
