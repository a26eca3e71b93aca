//! The pure-Rust `nusb` backend.

use std::time::Duration;

use nusb::MaybeFuture;
use nusb::descriptors::TransferType;
use nusb::transfer::{Bulk, Direction, In, Out};

use super::{BulkIn, BulkOut, TransferError, UsbSelector, link};
use crate::link::{Link, LinkError};

/// Time allowed for one OUT transfer (a request frame).
const OUT_TIMEOUT: Duration = Duration::from_secs(2);

/// Opens the first device matching `sel`, claims interface 0 and uses its
/// first bulk IN and bulk OUT endpoints.
pub fn open_nusb(sel: &UsbSelector) -> Result<Link, LinkError> {
    let io = |what: &str, e: nusb::Error| LinkError::Io(format!("{sel}: {what}: {e}"));
    let info = nusb::list_devices()
        .wait()
        .map_err(|e| io("listing USB devices", e))?
        .find(|d| {
            d.vendor_id() == sel.vendor_id
                && d.product_id() == sel.product_id
                && sel
                    .serial
                    .as_deref()
                    .is_none_or(|s| d.serial_number() == Some(s))
        })
        .ok_or_else(|| LinkError::Io(format!("{sel}: no such USB device is connected")))?;
    let device = info.open().wait().map_err(|e| io("opening", e))?;
    let interface = device
        .claim_interface(0)
        .wait()
        .map_err(|e| io("claiming interface 0", e))?;
    let (mut addr_in, mut addr_out) = (None, None);
    if let Some(desc) = interface.descriptor() {
        for ep in desc.endpoints() {
            if ep.transfer_type() == TransferType::Bulk {
                match ep.direction() {
                    Direction::In => addr_in = addr_in.or(Some(ep.address())),
                    Direction::Out => addr_out = addr_out.or(Some(ep.address())),
                }
            }
        }
    }
    let (Some(addr_in), Some(addr_out)) = (addr_in, addr_out) else {
        return Err(LinkError::Io(format!(
            "{sel}: interface 0 has no bulk IN/OUT endpoint pair"
        )));
    };
    let ep_in = interface
        .endpoint::<Bulk, In>(addr_in)
        .map_err(|e| io("bulk IN endpoint", e))?;
    let ep_out = interface
        .endpoint::<Bulk, Out>(addr_out)
        .map_err(|e| io("bulk OUT endpoint", e))?;
    Ok(link(
        sel.to_string(),
        Box::new(NusbIn(ep_in)),
        Box::new(NusbOut(ep_out)),
    ))
}

fn transfer_error(e: nusb::transfer::TransferError) -> TransferError {
    match e {
        nusb::transfer::TransferError::Disconnected => TransferError::Disconnected,
        other => TransferError::Failed(other.to_string()),
    }
}

struct NusbIn(nusb::Endpoint<Bulk, In>);

impl BulkIn for NusbIn {
    fn submit(&mut self, len: usize) {
        let buf = self.0.allocate(len);
        self.0.submit(buf);
    }

    fn pending(&self) -> usize {
        self.0.pending()
    }

    fn wait_next_complete(&mut self, timeout: Duration) -> Option<Result<Vec<u8>, TransferError>> {
        let c = self.0.wait_next_complete(timeout)?;
        Some(match c.status {
            Ok(()) => Ok(c.buffer[..c.actual_len.min(c.buffer.len())].to_vec()),
            Err(e) => Err(transfer_error(e)),
        })
    }
}

struct NusbOut(nusb::Endpoint<Bulk, Out>);

impl BulkOut for NusbOut {
    fn write(&mut self, data: &[u8]) -> Result<(), TransferError> {
        let c = self.0.transfer_blocking(data.to_vec().into(), OUT_TIMEOUT);
        c.status.map_err(transfer_error)
    }
}
