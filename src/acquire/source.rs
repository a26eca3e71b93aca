//! The one interface every acquisition source implements: our own devices
//! on the wire protocol (the mocks included) and PicoQuant devices through
//! the vendor's library. A source says what it is ([`SourceFacts`]), then
//! streams what its device sends ([`Delivery`]) into the pipeline's stages
//! until the duration, a stop request or the device's own end, and says how
//! it ended ([`SourceEnd`]). Everything downstream (binning, recordings,
//! the ledger, progress) is the pipeline's ([`super::pipeline`]).

use std::sync::atomic::AtomicBool;
use std::time::Duration;

use firmware_protocol::{Config, EventBatch, Identity, Totals};
use serde::{Deserialize, Serialize};

use super::ledger::{Ledger, Transit};
use crate::events::Imaging;
use crate::formats::picoquant::records::RecordType;
use crate::formats::picoquant::writer::HeaderEntry;

/// What the device is, as the summary and the record name it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeviceInfo {
    /// The address or link it was opened on.
    pub link: String,
    /// Model.
    pub model: String,
    /// Serial number.
    pub serial: String,
    /// Firmware or hardware version.
    pub version: String,
    /// The vendor library file and its version, for devices driven through
    /// one.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub library: Option<String>,
}

/// How the device's records come.
#[derive(Debug, Clone, PartialEq)]
pub enum RecordFormat {
    /// Event batches of the project's wire protocol, from a device of this
    /// identity with this configuration applied.
    Wire {
        /// What the device said it is.
        identity: Identity,
        /// The configuration it applied.
        config: Config,
    },
    /// PicoQuant T3 records of this type.
    T3(RecordType),
}

/// What its pixels are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Layout {
    /// A sensor array: the record's pixel number, row-major.
    Sensor {
        /// Columns.
        width: usize,
        /// Rows.
        height: usize,
    },
    /// Inputs of a point detector (or several), possibly clocked by a
    /// scanner's markers.
    Inputs {
        /// How many inputs.
        count: usize,
        /// The scanner's image, when its markers are enabled.
        scan: Option<Imaging>,
    },
}

/// The count rates of a device at one moment of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RateSample {
    /// Seconds since the measurement started.
    pub t_s: f64,
    /// Sync rate, Hz (as the device counts it, before any divider).
    pub sync_hz: f64,
    /// Count rate of each input, counts/s.
    pub inputs: Vec<f64>,
}

/// What a started source tells the pipeline before its first record.
#[derive(Debug, Clone)]
pub struct SourceFacts {
    /// The device.
    pub device: DeviceInfo,
    /// Micro-time unit of the records, ps.
    pub resolution_ps: f64,
    /// The laser's period, ps: the unit of the records' macro time.
    pub sync_period_ps: f64,
    /// How the records come.
    pub format: RecordFormat,
    /// What the pixels are.
    pub layout: Layout,
    /// The rates read before the start, when the device reports them.
    pub rates_at_start: Option<RateSample>,
    /// What the device or its library warned about at the start.
    pub warnings: Vec<String>,
    /// Header tags a PTU of this run carries, as PicoQuant's software names
    /// them (the device's settings).
    pub ptu_tags: Vec<(String, HeaderEntry)>,
}

/// One thing the device sent, in the order it came.
#[derive(Debug, Clone, Copy)]
pub enum Delivery<'a> {
    /// An accepted event batch (wire protocol): its payload as sent, and
    /// parsed.
    Batch {
        /// The payload, byte for byte.
        payload: &'a [u8],
        /// The same, parsed.
        batch: &'a EventBatch<'a>,
    },
    /// Records of one FIFO read, as the device wrote them (T3).
    Records(&'a [u32]),
    /// The device's count rates, read during the run.
    Rates(&'a RateSample),
    /// Nothing new; how the link is doing (frames that failed their checks
    /// so far), so that progress shows while no light comes.
    Idle {
        /// Frames rejected by their checks so far.
        damaged_frames: u64,
    },
}

/// Why an acquisition ended.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// The planned duration elapsed.
    Duration,
    /// The user asked (Ctrl-C or SIGTERM).
    Interrupted,
    /// The device stopped by itself (its exposure or photon quota).
    DeviceStopped,
    /// The link ended: the device is gone.
    Disconnected(String),
    /// The device did not confirm Stop in time.
    NoStopAnswer,
    /// The device's FIFO overran: records after it were lost in the device.
    FifoOverrun,
    /// A library call failed mid-run (the vendor's text), or a recording
    /// played back could not be read on.
    DeviceError(String),
    /// A recording played back reached its end.
    EndOfRecording,
}

impl StopReason {
    /// Why the acquisition ended, in words for the summary.
    pub fn describe(&self) -> String {
        match self {
            Self::Duration => "the planned duration elapsed".into(),
            Self::Interrupted => "interrupted (Ctrl-C or SIGTERM)".into(),
            Self::DeviceStopped => {
                "the device stopped by itself (its exposure or photon quota)".into()
            }
            Self::Disconnected(e) => format!("the device disconnected: {e}"),
            Self::NoStopAnswer => "the device did not confirm Stop in time".into(),
            Self::FifoOverrun => "FIFO overrun: the device lost records and stopped (lower the count rate, or read faster)".into(),
            Self::DeviceError(e) => format!("device error: {e}"),
            Self::EndOfRecording => "the recording reached its end".into(),
        }
    }

    /// Whether the run reached its planned end (the recordings say
    /// complete) rather than being cut short.
    pub fn is_planned_end(&self) -> bool {
        matches!(
            self,
            Self::Duration | Self::DeviceStopped | Self::EndOfRecording
        )
    }
}

/// How a source's stream ended, and what only the source knows.
#[derive(Debug, Clone)]
pub struct SourceEnd {
    /// Why.
    pub stop: StopReason,
    /// From the start of the measurement to its last record.
    pub elapsed: Duration,
    /// The device's own totals, when it sends them.
    pub totals: Option<Totals>,
    /// Photons the device detected, from its totals.
    pub detected: Option<u64>,
    /// Photons it reported losing, when it counts them (else the pipeline
    /// counts the loss records it sent).
    pub lost_in_device: Option<u64>,
    /// Its FIFO overran (how many records it lost it does not say).
    pub fifo_overrun: bool,
    /// It dropped counts before its FIFO (how many it does not say).
    pub counts_dropped: bool,
    /// The transport's losses and repairs, for a link of our own.
    pub transit: Option<Transit>,
    /// What its flags or the link said during the run, each once.
    pub warnings: Vec<String>,
}

impl SourceEnd {
    /// An end for `stop` with nothing else known yet: no time, no totals,
    /// no loss, no transport; a source fills in what it learns.
    pub fn ended(stop: StopReason) -> Self {
        Self {
            stop,
            elapsed: Duration::ZERO,
            totals: None,
            detected: None,
            lost_in_device: None,
            fifo_overrun: false,
            counts_dropped: false,
            transit: None,
            warnings: Vec::new(),
        }
    }
}

/// What a mock (or any source that knows its truth) adds after the run.
#[derive(Debug, Clone, Default)]
pub struct SourceReport {
    /// Lines for the summary (the mock's own counts).
    pub notes: Vec<String>,
    /// The light budget that puts the stack in the scene's units.
    pub light_budget: Option<f64>,
    /// The seed that makes the same photons again.
    pub seed: Option<u64>,
}

/// Why a source could not start or stream.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The device: its control exchange, transport or library.
    #[error("{0}")]
    Device(String),
    /// The request does not fit the device.
    #[error("{0}")]
    Plan(String),
    /// A setting of the request or the source does not fit; `name` is the
    /// library's name for it (the command line's hints name its flag).
    #[error("{message}")]
    Setting {
        /// The setting (`resolution_fs`, `speed`, `sync_level_mv`, ...).
        name: &'static str,
        /// What is wrong, with the value.
        message: String,
    },
}

impl SourceError {
    /// An error about the setting `name`.
    pub fn setting(name: &'static str, message: impl Into<String>) -> Self {
        Self::Setting {
            name,
            message: message.into(),
        }
    }
}

/// Everything the pipeline asks of a source at the start.
#[derive(Debug, Clone, Default)]
pub struct StartRequest {
    /// Micro-time unit to configure, fs (`None`: the device's own).
    pub resolution_fs: Option<u32>,
}

impl StartRequest {
    /// Refuses a micro-time unit, which only our own devices configure;
    /// `instead` says what this source takes.
    pub fn refuse_micro_time_unit(&self, instead: &str) -> Result<(), SourceError> {
        match self.resolution_fs {
            Some(_) => Err(SourceError::setting("resolution_fs", instead)),
            None => Ok(()),
        }
    }
}

/// When a stream ends, besides the device's own end: after `duration`
/// (none: no limit) or once `stop` is set (Ctrl-C, a caller's request).
#[derive(Debug, Clone, Copy)]
pub struct Until<'a> {
    /// How long to stream.
    pub duration: Option<Duration>,
    /// Set to end the stream early.
    pub stop: &'a AtomicBool,
}

/// An acquisition source.
pub trait Source {
    /// Identifies and configures the device; what the pipeline needs.
    fn start(&mut self, request: &StartRequest) -> Result<SourceFacts, SourceError>;

    /// Streams until `until` or the device's own end, handing
    /// every delivery to `sink` on the caller's thread, in order.
    fn stream(&mut self, until: Until<'_>, sink: &mut dyn FnMut(Delivery<'_>)) -> SourceEnd;

    /// What the source adds once the pipeline has placed every photon of
    /// `ledger` (the pixels `region` binned, the run ended by `stop`): a
    /// mock compares them with its truth.
    fn report(
        &self,
        _ledger: &Ledger,
        _region: Option<crate::tags::binning::Region>,
        _stop: &StopReason,
    ) -> SourceReport {
        SourceReport::default()
    }
}
