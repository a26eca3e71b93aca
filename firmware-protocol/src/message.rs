//! Control messages: requests from the host, responses from the device.
//! Encoded with postcard (serde), carried in Request/Response frames. Every
//! request has an `id` that its response echoes.

use alloc::string::String;
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

/// A request with the id its response will carry.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RequestFrame {
    /// Chosen by the host; echoed in the response.
    pub id: u16,
    /// What the host asks.
    pub request: Request,
}

/// Host -> device commands.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum Request {
    /// Who are you? Answered with [`Response::Identity`].
    Identify,
    /// Set acquisition parameters (only while stopped). Answered with the
    /// configuration the device actually applied.
    Configure(Config),
    /// Start streaming event batches (batch numbering restarts at 0).
    Start,
    /// Stop streaming. Answered after the last batch with the totals.
    Stop,
    /// Counters and FIFO state.
    Status,
}

/// A response with the id of its request.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ResponseFrame {
    /// The request's id.
    pub id: u16,
    /// The answer.
    pub response: Response,
}

/// Device -> host answers.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum Response {
    /// Answer to Identify.
    Identity(Identity),
    /// Answer to Configure: the applied configuration.
    Configured(Config),
    /// Answer to Start.
    Started,
    /// Answer to Stop, sent after the last batch.
    Stopped(Totals),
    /// Answer to Status.
    Status(Status),
    /// The request was refused.
    Error(DeviceError),
}

/// What the device is.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Identity {
    /// Model name.
    pub model: String,
    /// Serial number.
    pub serial: String,
    /// Firmware version (major, minor, patch).
    pub firmware: [u16; 3],
    /// Wire protocol version ([`crate::PROTOCOL_VERSION`]).
    pub protocol_version: u16,
    /// Sensor columns.
    pub pixels_x: u16,
    /// Sensor rows.
    pub pixels_y: u16,
    /// Input channels (pixels of a SPAD array; 1 for a single detector).
    pub channels: u16,
    /// Finest micro-time step of the TDC, femtoseconds.
    pub tdc_resolution_fs: u32,
    /// Laser sync period, femtoseconds (0 if no sync is connected).
    pub sync_period_fs: u64,
}

/// Region of interest on the sensor, in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Roi {
    /// First column.
    pub x: u16,
    /// First row.
    pub y: u16,
    /// Columns.
    pub width: u16,
    /// Rows.
    pub height: u16,
}

/// Acquisition parameters.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Config {
    /// Keep one laser sync in `sync_divider` (1 = every sync).
    pub sync_divider: u16,
    /// Micro-time unit of the records, femtoseconds; a multiple of the TDC
    /// resolution.
    pub resolution_fs: u32,
    /// Micro times at or beyond this many units are not recorded (0 = the
    /// whole sync period).
    pub time_window: u32,
    /// Only photons inside this region are recorded (full sensor if `None`).
    pub roi: Option<Roi>,
    /// Stop by itself after this many milliseconds (0 = run until Stop).
    pub exposure_ms: u32,
}

/// Counts of a finished (or running) acquisition, as the device saw them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Totals {
    /// Event batches sent.
    pub batches: u32,
    /// Photon records sent in those batches.
    pub photons_sent: u64,
    /// Photons detected but dropped because the FIFO was full (each drop
    /// is also announced by a lost record in the stream).
    pub photons_lost: u64,
}

/// Device state.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Status {
    /// Streaming?
    pub running: bool,
    /// Counters since Start.
    pub totals: Totals,
    /// Records waiting in the FIFO.
    pub fifo_fill: u32,
    /// FIFO capacity in records.
    pub fifo_capacity: u32,
    /// Malformed requests received since power-up.
    pub request_errors: u32,
}

/// Why the device refused a request.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum DeviceError {
    /// The request frame did not decode.
    Malformed,
    /// Configure while running.
    Busy,
    /// A configuration field is out of range.
    InvalidConfig {
        /// Field name as in [`Config`].
        field: String,
        /// Why.
        reason: String,
    },
}

impl core::fmt::Display for DeviceError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            DeviceError::Malformed => write!(f, "device could not decode the request"),
            DeviceError::Busy => write!(f, "device is acquiring; stop it first"),
            DeviceError::InvalidConfig { field, reason } => {
                write!(f, "device refused config field `{field}`: {reason}")
            }
        }
    }
}

/// Encodes a message payload.
pub fn to_payload<T: Serialize>(msg: &T) -> Result<Vec<u8>, postcard::Error> {
    postcard::to_allocvec(msg)
}

/// Decodes a message payload (trailing bytes are an error).
pub fn from_payload<'a, T: Deserialize<'a>>(payload: &'a [u8]) -> Result<T, postcard::Error> {
    let (msg, rest) = postcard::take_from_bytes(payload)?;
    if rest.is_empty() {
        Ok(msg)
    } else {
        Err(postcard::Error::DeserializeBadEncoding)
    }
}
