//! The byte pipe between host and device, split into a reading and a
//! writing half so the reader thread streams while control requests go out.

use std::time::Duration;

/// Why a transport stopped working.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The device went away (unplugged, port closed, mock ended).
    #[error("device disconnected ({0})")]
    Disconnected(String),
    /// Any other transport failure.
    #[error("{0}")]
    Io(String),
}

/// The receiving half of a link.
pub trait ByteReader: Send {
    /// Waits up to `timeout` for bytes; `Ok(None)` if none came.
    fn read_chunk(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, LinkError>;
}

/// The sending half of a link.
pub trait ByteWriter: Send {
    /// Sends all of `bytes`.
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError>;
}

/// An opened transport.
pub struct Link {
    /// What it is connected to, for messages and metadata.
    pub description: String,
    /// Device -> host bytes.
    pub reader: Box<dyn ByteReader>,
    /// Host -> device bytes.
    pub writer: Box<dyn ByteWriter>,
}

impl std::fmt::Debug for Link {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Link")
            .field("description", &self.description)
            .finish()
    }
}
