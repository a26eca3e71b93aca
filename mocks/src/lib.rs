//! Emulated time-taggers: the firmware side of `firmware-protocol`, emitting
//! photons sampled from the ST-PSF of `scatterscope-physics`, so that every
//! layer of the host is tested without hardware.

/// Protocol version the emulated firmware speaks.
pub use firmware_protocol::PROTOCOL_VERSION;
