//! Emulated time-taggers: the firmware side of `firmware-protocol`, emitting
//! photons sampled from the ST-PSF of a scene, so that every layer of the
//! host is tested without hardware.
//!
//! - [`emitter`]: photons from the ST-PSF (pixel, micro time, sync count),
//!   dark counts, deterministic under a seed.
//! - [`firmware`]: the device state machine: requests, FIFO with overflow
//!   records, batching, fault injection, and the true counts ([`Truth`]).
//! - [`usb`]: in-process bulk IN/OUT endpoints (the host's USB reader runs
//!   unchanged against them).
//! - [`pty`]: the device behind a real pseudo-terminal, opened by the host
//!   with `serialport` like a USB-CDC device.

#![warn(missing_docs)]

pub mod emitter;
pub mod firmware;
pub mod pty;
pub mod usb;

pub use emitter::{Emitter, EmitterOptions};
pub use firmware::{Faults, MockDevice, MockHandle, MockOptions, Truth};

/// Protocol version the emulated firmware speaks.
pub use firmware_protocol::PROTOCOL_VERSION;

/// The device side of a transport.
pub trait DevicePort: Send {
    /// Waits up to `timeout` for bytes from the host; `Ok(None)` if none.
    fn recv(&mut self, timeout: std::time::Duration) -> Result<Option<Vec<u8>>, PortClosed>;
    /// Offers `bytes` to the host. `Ok(false)` means the endpoint buffer is
    /// full right now (nothing was sent; try again later).
    fn send(&mut self, bytes: &[u8]) -> Result<bool, PortClosed>;
}

/// The host side went away.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("host closed the link")]
pub struct PortClosed;
