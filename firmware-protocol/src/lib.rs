//! Wire protocol between the scatterscope host and time-tagger firmware.
//!
//! `no_std` so that the same crate builds for the firmware. The framing,
//! commands and event records are specified in `PROTOCOL.md` beside this
//! crate's manifest as they are implemented; this crate depends on nothing
//! else of the workspace.
#![no_std]

/// Version of the wire protocol spoken by this crate.
pub const PROTOCOL_VERSION: u16 = 1;
