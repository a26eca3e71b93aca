//! Frame payloads straight into their parsers (event batches, postcard
//! requests and responses), past the CRC that keeps random bytes out of
//! the frame target's payloads: refused or round-tripped, never a panic.
#![no_main]
use firmware_protocol::FrameKind;
use libfuzzer_sys::fuzz_target;

#[path = "common/payload.rs"]
mod payload;

fuzz_target!(|data: &[u8]| {
    let Some((&k, rest)) = data.split_first() else { return };
    let kind = [FrameKind::Request, FrameKind::Response, FrameKind::Events][usize::from(k) % 3];
    payload::check(kind, rest);
});
