//! The libusb backend (`rusb`, feature `rusb`). libusb's synchronous API
//! has one transfer in flight; it is here for platforms where nusb is not
//! an option, and CI builds it.

use std::time::Duration;

use rusb::UsbContext;

use super::{BulkIn, BulkOut, TransferError, UsbSelector, link};
use crate::link::{Link, LinkError};

/// Opens the first device matching `sel` through libusb.
pub fn open_rusb(sel: &UsbSelector) -> Result<Link, LinkError> {
    let io = |what: &str, e: rusb::Error| LinkError::Io(format!("{sel}: {what}: {e}"));
    // Never the global context: without /sys/bus/usb it panics.
    let ctx = rusb::Context::new().map_err(|e| io("starting libusb", e))?;
    let devices = ctx.devices().map_err(|e| io("listing USB devices", e))?;
    for device in devices.iter() {
        let Ok(desc) = device.device_descriptor() else {
            continue;
        };
        if desc.vendor_id() != sel.vendor_id || desc.product_id() != sel.product_id {
            continue;
        }
        let handle = device.open().map_err(|e| io("opening", e))?;
        if let Some(want) = &sel.serial {
            let got = handle
                .read_serial_number_string_ascii(&desc)
                .unwrap_or_default();
            if &got != want {
                continue;
            }
        }
        let config = device
            .active_config_descriptor()
            .map_err(|e| io("configuration", e))?;
        let (mut ep_in, mut ep_out) = (None, None);
        if let Some(intf) = config.interfaces().find(|i| i.number() == 0)
            && let Some(alt) = intf.descriptors().next()
        {
            for ep in alt.endpoint_descriptors() {
                if ep.transfer_type() == rusb::TransferType::Bulk {
                    match ep.direction() {
                        rusb::Direction::In => ep_in = ep_in.or(Some(ep.address())),
                        rusb::Direction::Out => ep_out = ep_out.or(Some(ep.address())),
                    }
                }
            }
        }
        let (Some(ep_in), Some(ep_out)) = (ep_in, ep_out) else {
            return Err(LinkError::Io(format!(
                "{sel}: interface 0 has no bulk IN/OUT endpoint pair"
            )));
        };
        handle
            .claim_interface(0)
            .map_err(|e| io("claiming interface 0", e))?;
        let handle = std::sync::Arc::new(handle);
        return Ok(link(
            format!("{sel} (libusb)"),
            Box::new(RusbIn {
                handle: handle.clone(),
                ep: ep_in,
                queued: 0,
            }),
            Box::new(RusbOut { handle, ep: ep_out }),
        ));
    }
    Err(LinkError::Io(format!(
        "{sel}: no such USB device is connected"
    )))
}

fn transfer_error(e: rusb::Error) -> TransferError {
    match e {
        rusb::Error::NoDevice => TransferError::Disconnected,
        other => TransferError::Failed(other.to_string()),
    }
}

struct RusbIn {
    handle: std::sync::Arc<rusb::DeviceHandle<rusb::Context>>,
    ep: u8,
    /// Transfers "submitted": with the synchronous API each is run when
    /// waited for.
    queued: usize,
}

impl BulkIn for RusbIn {
    fn submit(&mut self, _len: usize) {
        self.queued += 1;
    }

    fn pending(&self) -> usize {
        self.queued
    }

    fn wait_next_complete(&mut self, timeout: Duration) -> Option<Result<Vec<u8>, TransferError>> {
        let mut buf = vec![0; super::TRANSFER_SIZE];
        match self.handle.read_bulk(self.ep, &mut buf, timeout) {
            Ok(n) => {
                buf.truncate(n);
                Some(Ok(buf))
            }
            Err(rusb::Error::Timeout) => None,
            Err(e) => Some(Err(transfer_error(e))),
        }
    }
}

struct RusbOut {
    handle: std::sync::Arc<rusb::DeviceHandle<rusb::Context>>,
    ep: u8,
}

impl BulkOut for RusbOut {
    fn write(&mut self, data: &[u8]) -> Result<(), TransferError> {
        self.handle
            .write_bulk(self.ep, data, Duration::from_secs(2))
            .map(|_| ())
            .map_err(transfer_error)
    }
}
