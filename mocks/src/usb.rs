//! In-process USB: a bulk IN endpoint (device -> host) and a bulk OUT
//! endpoint (host -> device) with the semantics the host's USB reader
//! relies on: data moves in packets of [`MAX_PACKET`] bytes, every device
//! write ends with a short (or zero-length) packet, an IN transfer completes
//! when it is full or at a short packet, and the endpoint buffer is finite,
//! so a host that does not read leaves the device unable to send.

use std::collections::VecDeque;
use std::time::Duration;

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, TrySendError, bounded, unbounded};
use scatterscope_drivers::usb::{BulkIn, BulkOut, TransferError};

use crate::{DevicePort, PortClosed};

/// High-speed bulk packet size.
pub const MAX_PACKET: usize = 512;

/// Creates a connected endpoint pair; the IN endpoint buffers up to
/// `buffer_packets` packets.
pub fn endpoints(buffer_packets: usize) -> (UsbDevicePort, UsbHostIn, UsbHostOut) {
    let (in_tx, in_rx) = bounded(buffer_packets.max(2));
    let (out_tx, out_rx) = unbounded();
    (
        UsbDevicePort { in_tx, out_rx },
        UsbHostIn {
            rx: in_rx,
            requested: VecDeque::new(),
        },
        UsbHostOut { tx: out_tx },
    )
}

/// The device's side of both endpoints.
pub struct UsbDevicePort {
    in_tx: Sender<Vec<u8>>,
    out_rx: Receiver<Vec<u8>>,
}

impl DevicePort for UsbDevicePort {
    fn recv(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, PortClosed> {
        let r = if timeout.is_zero() {
            self.out_rx.try_recv().map_err(|e| match e {
                crossbeam_channel::TryRecvError::Empty => RecvTimeoutError::Timeout,
                crossbeam_channel::TryRecvError::Disconnected => RecvTimeoutError::Disconnected,
            })
        } else {
            self.out_rx.recv_timeout(timeout)
        };
        match r {
            Ok(b) => Ok(Some(b)),
            Err(RecvTimeoutError::Timeout) => Ok(None),
            Err(RecvTimeoutError::Disconnected) => Err(PortClosed),
        }
    }

    fn send(&mut self, bytes: &[u8]) -> Result<bool, PortClosed> {
        // All packets of the write or none: a frame is never half-queued.
        let packets = bytes.len() / MAX_PACKET + 1;
        let cap = self.in_tx.capacity().unwrap_or(usize::MAX);
        if self.in_tx.len() + packets > cap {
            // A host that went away shows at the next recv().
            return Ok(false);
        }
        // Full packets, then a short one (zero-length if the write is a
        // multiple of the packet size).
        let mut chunks = bytes
            .chunks(MAX_PACKET)
            .map(<[u8]>::to_vec)
            .collect::<Vec<_>>();
        if bytes.len().is_multiple_of(MAX_PACKET) {
            chunks.push(Vec::new());
        }
        for c in chunks {
            match self.in_tx.try_send(c) {
                Ok(()) => {}
                Err(TrySendError::Disconnected(_)) => return Err(PortClosed),
                Err(TrySendError::Full(_)) => {
                    unreachable!("room was checked and only this thread sends")
                }
            }
        }
        Ok(true)
    }
}

/// The host's bulk IN endpoint.
pub struct UsbHostIn {
    rx: Receiver<Vec<u8>>,
    requested: VecDeque<usize>,
}

impl BulkIn for UsbHostIn {
    fn submit(&mut self, len: usize) {
        self.requested.push_back(len);
    }

    fn pending(&self) -> usize {
        self.requested.len()
    }

    fn wait_next_complete(&mut self, timeout: Duration) -> Option<Result<Vec<u8>, TransferError>> {
        let len = *self.requested.front()?;
        let first = match self.rx.recv_timeout(timeout) {
            Ok(p) => p,
            Err(RecvTimeoutError::Timeout) => return None,
            Err(RecvTimeoutError::Disconnected) => {
                self.requested.pop_front();
                return Some(Err(TransferError::Disconnected));
            }
        };
        let mut data = first;
        // The device queues whole writes, so the rest of this one is there.
        while data.len().is_multiple_of(MAX_PACKET) && !data.is_empty() && data.len() < len {
            match self.rx.recv() {
                Ok(p) => {
                    let short = p.len() < MAX_PACKET;
                    data.extend_from_slice(&p);
                    if short {
                        break;
                    }
                }
                Err(_) => break,
            }
        }
        self.requested.pop_front();
        Some(Ok(data))
    }
}

/// The host's bulk OUT endpoint.
pub struct UsbHostOut {
    tx: Sender<Vec<u8>>,
}

impl BulkOut for UsbHostOut {
    fn write(&mut self, data: &[u8]) -> Result<(), TransferError> {
        self.tx
            .send(data.to_vec())
            .map_err(|_| TransferError::Disconnected)
    }
}
