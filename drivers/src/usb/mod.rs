//! USB time taggers: one vendor interface with a bulk OUT endpoint (host ->
//! device frames) and a bulk IN endpoint (device -> host frames).
//!
//! The transport is written against [`BulkIn`]/[`BulkOut`], which mirror
//! the endpoint semantics of `nusb`: the host submits IN transfers of a
//! fixed size, keeps several in flight so the device never waits for the
//! host, and a transfer completes when full or at a short packet. The nusb
//! backend, the optional rusb backend and the mock's in-process endpoints
//! all implement these traits, so the same reader code runs against all.

mod nusb_backend;
#[cfg(feature = "rusb")]
mod rusb_backend;

use std::collections::VecDeque;
use std::time::Duration;

use crate::link::{ByteReader, ByteWriter, Link, LinkError};

pub use nusb_backend::open_nusb;
#[cfg(feature = "rusb")]
pub use rusb_backend::open_rusb;

/// Bytes per IN transfer.
pub const TRANSFER_SIZE: usize = 64 * 1024;
/// IN transfers kept in flight.
pub const TRANSFERS_IN_FLIGHT: usize = 8;

/// Why a transfer failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TransferError {
    /// The device is gone.
    Disconnected,
    /// Anything else (stall, fault), with the backend's words.
    Failed(String),
}

/// A bulk IN endpoint.
pub trait BulkIn: Send {
    /// Queues a transfer of up to `len` bytes.
    fn submit(&mut self, len: usize);
    /// Transfers queued and not yet returned.
    fn pending(&self) -> usize;
    /// The oldest transfer once complete, or `None` after `timeout`.
    fn wait_next_complete(&mut self, timeout: Duration) -> Option<Result<Vec<u8>, TransferError>>;
}

/// A bulk OUT endpoint.
pub trait BulkOut: Send {
    /// Sends `data` and waits for the transfer to complete.
    fn write(&mut self, data: &[u8]) -> Result<(), TransferError>;
}

/// A link over a pair of bulk endpoints.
pub fn link(description: String, ep_in: Box<dyn BulkIn>, ep_out: Box<dyn BulkOut>) -> Link {
    Link {
        description,
        reader: Box::new(UsbReader {
            ep: ep_in,
            ready: VecDeque::new(),
        }),
        writer: Box::new(UsbWriter { ep: ep_out }),
    }
}

struct UsbReader {
    ep: Box<dyn BulkIn>,
    ready: VecDeque<Vec<u8>>,
}

impl ByteReader for UsbReader {
    fn read_chunk(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, LinkError> {
        if let Some(chunk) = self.ready.pop_front() {
            return Ok(Some(chunk));
        }
        while self.ep.pending() < TRANSFERS_IN_FLIGHT {
            self.ep.submit(TRANSFER_SIZE);
        }
        match self.ep.wait_next_complete(timeout) {
            None => Ok(None),
            Some(Ok(data)) if data.is_empty() => Ok(None),
            Some(Ok(data)) => Ok(Some(data)),
            Some(Err(TransferError::Disconnected)) => {
                Err(LinkError::Disconnected("USB device disconnected".into()))
            }
            Some(Err(TransferError::Failed(e))) => {
                Err(LinkError::Io(format!("USB IN transfer: {e}")))
            }
        }
    }
}

struct UsbWriter {
    ep: Box<dyn BulkOut>,
}

impl ByteWriter for UsbWriter {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.ep.write(bytes).map_err(|e| match e {
            TransferError::Disconnected => {
                LinkError::Disconnected("USB device disconnected".into())
            }
            TransferError::Failed(e) => LinkError::Io(format!("USB OUT transfer: {e}")),
        })
    }
}

/// Which USB device to open.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UsbSelector {
    /// Vendor id.
    pub vendor_id: u16,
    /// Product id.
    pub product_id: u16,
    /// Serial number, if several match.
    pub serial: Option<String>,
}

impl std::fmt::Display for UsbSelector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "usb:{:04x}:{:04x}", self.vendor_id, self.product_id)?;
        if let Some(s) = &self.serial {
            write!(f, ":{s}")?;
        }
        Ok(())
    }
}

impl std::str::FromStr for UsbSelector {
    type Err = String;

    /// `VID:PID[:SERIAL]` with hexadecimal ids.
    fn from_str(s: &str) -> Result<Self, String> {
        let mut parts = s.splitn(3, ':');
        let hex = |p: Option<&str>, what: &str| {
            let p = p.ok_or_else(|| {
                format!("`{s}`: missing {what} (expected VID:PID[:SERIAL] in hex)")
            })?;
            u16::from_str_radix(p.trim_start_matches("0x"), 16)
                .map_err(|_| format!("`{s}`: {what} `{p}` is not a 16-bit hexadecimal number"))
        };
        Ok(Self {
            vendor_id: hex(parts.next(), "vendor id")?,
            product_id: hex(parts.next(), "product id")?,
            serial: parts.next().map(str::to_string),
        })
    }
}
