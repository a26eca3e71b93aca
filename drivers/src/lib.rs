//! Host side of acquisition: transports (USB, serial) that carry the
//! `firmware-protocol` byte stream, device discovery, and the streaming
//! pipeline that decodes tags and bins them into transient stacks.

/// Protocol version this host implementation speaks.
pub use firmware_protocol::PROTOCOL_VERSION;
