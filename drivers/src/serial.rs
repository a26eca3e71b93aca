//! Serial ports (USB-CDC time taggers, UARTs, and the mock's
//! pseudo-terminal) through `serialport`.

use std::io::{ErrorKind, Read, Write};
use std::time::Duration;

use serialport::SerialPort;

use crate::link::{ByteReader, ByteWriter, Link, LinkError};

/// Line rate used when opening a port (ignored by USB-CDC and pty devices).
pub const DEFAULT_BAUD: u32 = 3_000_000;

/// Opens `path` as a raw serial port.
pub fn open(path: &str, baud: u32) -> Result<Link, LinkError> {
    // The builder's default timeout is 0 ms (every read fails at once);
    // the reader sets its own per call.
    let port = serialport::new(path, baud)
        .timeout(Duration::from_millis(50))
        .open()
        .map_err(|e| LinkError::Io(format!("opening serial port {path}: {e}")))?;
    let writer = port
        .try_clone()
        .map_err(|e| LinkError::Io(format!("cloning serial port {path}: {e}")))?;
    Ok(Link {
        description: format!("serial:{path}"),
        reader: Box::new(SerialReader {
            port,
            buf: vec![0; 1 << 16],
        }),
        writer: Box::new(SerialWriter { port: writer }),
    })
}

struct SerialReader {
    port: Box<dyn SerialPort>,
    buf: Vec<u8>,
}

impl ByteReader for SerialReader {
    fn read_chunk(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, LinkError> {
        self.port
            .set_timeout(timeout)
            .map_err(|e| LinkError::Io(e.to_string()))?;
        match self.port.read(&mut self.buf) {
            // A closed pty master (unplugged device) reads as 0 bytes or
            // BrokenPipe.
            Ok(0) => Err(LinkError::Disconnected("serial port closed".into())),
            Ok(n) => Ok(Some(self.buf[..n].to_vec())),
            Err(e) if e.kind() == ErrorKind::TimedOut || e.kind() == ErrorKind::Interrupted => {
                Ok(None)
            }
            Err(e) if e.kind() == ErrorKind::BrokenPipe => {
                Err(LinkError::Disconnected(e.to_string()))
            }
            Err(e) => Err(LinkError::Io(e.to_string())),
        }
    }
}

struct SerialWriter {
    port: Box<dyn SerialPort>,
}

impl ByteWriter for SerialWriter {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.port
            .write_all(bytes)
            .and_then(|()| self.port.flush())
            .map_err(|e| match e.kind() {
                ErrorKind::BrokenPipe => LinkError::Disconnected(e.to_string()),
                _ => LinkError::Io(e.to_string()),
            })
    }
}
