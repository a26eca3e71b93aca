//! Host side of acquisition: transports that carry the `firmware-protocol`
//! byte stream, device discovery, the control client, and the streaming
//! pipeline that turns received bytes into checked event batches with exact
//! loss accounting.
//!
//! - [`link`]: the byte-pipe traits every transport implements.
//! - [`serial`]: serial ports and USB-CDC devices (`serialport`).
//! - [`usb`]: USB bulk endpoints (`nusb`; `rusb` behind the `rusb` feature),
//!   with several transfers in flight.
//! - [`picoquant`]: PicoQuant time taggers (MultiHarp, HydraHarp) through
//!   the vendor's library, loaded at run time.
//! - [`discovery`]: lists serial ports and known USB time taggers.
//! - [`client`]: request/response control (identify, configure, start, stop).
//! - [`pipeline`]: reader thread -> frame decoder -> batch checks -> consumer,
//!   on bounded channels, its [`pipeline::LinkAccounting`], and the
//!   [`pipeline::BatchRecorder`] the host's tag file writer implements.

#![warn(missing_docs)]

pub mod client;
pub mod discovery;
pub mod link;
pub mod picoquant;
pub mod pipeline;
pub mod serial;
pub mod usb;

/// Protocol version this host implementation speaks.
pub use firmware_protocol::PROTOCOL_VERSION;
pub use link::{ByteReader, ByteWriter, Link, LinkError};
