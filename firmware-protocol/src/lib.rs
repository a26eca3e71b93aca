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
