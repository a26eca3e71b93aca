//! Why a device cannot be opened: its own module, so that the devices'
//! openers (`device`, `mock`) share it without importing each other.

use scatterscope_drivers::LinkError;

/// Why a device cannot be opened.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// Transport failure.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The vendor's library or its device.
    #[error(transparent)]
    Vendor(#[from] scatterscope_drivers::picoquant::VendorError),
    /// The mock's scene or physics is unusable.
    #[error("the mock's scene or physics: {0}")]
    Mock(String),
    /// A device that cannot be opened as asked.
    #[error("{0}")]
    Usage(String),
    /// A recording that cannot be played back as asked.
    #[error(transparent)]
    Replay(super::source::SourceError),
    /// A setting the device's family cannot take, refused before it is
    /// opened.
    #[error(transparent)]
    Setting(super::source::SourceError),
    /// The sensor exceeds what the wire protocol addresses.
    #[error(
        "the sensor is {width} x {height} pixels; the protocol addresses at most {max} pixels (256 x 256)"
    )]
    SensorTooLarge {
        /// Columns.
        width: usize,
        /// Rows.
        height: usize,
        /// The protocol's limit.
        max: usize,
    },
    /// The pseudo-terminal could not be created.
    #[error("creating the mock's pseudo-terminal: {0}")]
    Pty(std::io::Error),
}
