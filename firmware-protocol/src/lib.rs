//! Wire protocol between the scatterscope host and time-tagger firmware.
//!
//! `no_std` with `alloc`, so the same crate builds for the firmware. The
//! protocol is data types plus their encodings, nothing else:
//!
//! - [`frame`]: sync word, kind, length, payload, CRC-32C; a decoder that
//!   resynchronises after garbage and counts what it discarded.
//! - [`message`]: request/response control messages (postcard + serde).
//! - [`record`]: the fixed-width 64-bit event records.
//! - [`batch`]: event batches with a sequence number and photon offset, so
//!   the host can tell exactly how many photons a missing batch carried.
//!
//! `PROTOCOL.md` beside this crate's manifest is the specification a
//! firmware author implements from.

#![warn(missing_docs)]
#![no_std]
#![forbid(unsafe_code)]

extern crate alloc;

pub mod batch;
pub mod frame;
pub mod message;
pub mod record;

pub use batch::{BatchEncoder, BatchError, BatchHeader, EventBatch};
pub use frame::{Frame, FrameDecoder, FrameKind, FrameStats, encode_frame};
pub use message::{
    Config, DeviceError, Identity, Request, RequestFrame, Response, ResponseFrame, Roi, Status,
    Totals,
};
pub use message::{from_payload, to_payload};
pub use postcard::Error as PayloadError;
pub use record::{Event, RecordError};

/// Version of the wire protocol spoken by this crate. A host refuses a
/// device whose [`Identity::protocol_version`] differs.
pub const PROTOCOL_VERSION: u16 = 1;

/// A frame from the device with its payload parsed by kind: the one
/// dispatch that every host-side reader of device frames (the live
/// pipeline, the raw tag file reader) shares.
#[derive(Debug, Clone, PartialEq)]
pub enum FromDevice<'a> {
    /// An event batch whose header and record area parse.
    Events(EventBatch<'a>),
    /// A control response.
    Response(ResponseFrame),
    /// An events frame whose payload does not parse as a batch.
    MalformedBatch(BatchError),
    /// A request frame (devices never send one) or a response whose
    /// payload does not parse.
    Stray,
}

impl<'a> FromDevice<'a> {
    /// Parses `frame` (CRC already checked) by its kind.
    pub fn parse(frame: Frame<'a>) -> Self {
        match frame.kind {
            FrameKind::Events => match EventBatch::parse(frame.payload) {
                Ok(b) => FromDevice::Events(b),
                Err(e) => FromDevice::MalformedBatch(e),
            },
            FrameKind::Response => match from_payload::<ResponseFrame>(frame.payload) {
                Ok(r) => FromDevice::Response(r),
                Err(_) => FromDevice::Stray,
            },
            FrameKind::Request => FromDevice::Stray,
        }
    }
}
