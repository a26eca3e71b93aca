//! The firmware protocol's frame decoder fed arbitrary bytes in arbitrary
//! chunks: the frames found and the statistics do not depend on how the
//! bytes were cut, and every frame's payload passes the payload checks.
#![no_main]
use firmware_protocol::{FrameDecoder, FrameKind, FrameStats};
use libfuzzer_sys::fuzz_target;

#[path = "common/payload.rs"]
mod payload;

fn decode(bytes: &[u8], cuts: &[u8]) -> (Vec<(u8, Vec<u8>)>, FrameStats) {
    let mut decoder = FrameDecoder::new();
    let mut frames = Vec::new();
    let mut rest = bytes;
    let mut cut = cuts.iter().cycle();
    while !rest.is_empty() {
        let n = match cut.next() {
            Some(&c) => (usize::from(c) + 1).min(rest.len()),
            None => rest.len(),
        };
        decoder.push_with(&rest[..n], |f| frames.push((f.kind as u8, f.payload.to_vec())));
        rest = &rest[n..];
    }
    decoder.end_stream();
    decoder.push_with(&[], |f| frames.push((f.kind as u8, f.payload.to_vec())));
    (frames, decoder.stats())
}

fuzz_target!(|data: &[u8]| {
    // First byte: how many of the next bytes give the chunk lengths.
    let Some((&n, rest)) = data.split_first() else { return };
    let (cuts, bytes) = rest.split_at((usize::from(n) % 16).min(rest.len()));
    let whole = decode(bytes, &[]);
    assert_eq!(whole, decode(bytes, cuts), "chunking changed the frames");
    assert_eq!(whole.1.frames, whole.0.len() as u64);
    for (kind, payload) in &whole.0 {
        let kind = FrameKind::from_byte(*kind).expect("the decoder returns known kinds only");
        payload::check(kind, payload);
    }
});
