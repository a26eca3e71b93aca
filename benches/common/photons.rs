//! The synthetic photon stream both tag benchmarks bin: a 256 x 256
//! sensor, 1 ps micro times within the 120 ps the paper's bins cover,
//! about one photon per 20 syncs (so wrap records now and then).

use firmware_protocol::{BatchEncoder, Event};

/// Encodes `n` photons into full event batches, handing each finished
/// batch payload to `on_batch`.
pub fn batches(n: u64, mut on_batch: impl FnMut(&[u8])) {
    let mut enc = BatchEncoder::new();
    let mut payload = Vec::new();
    let (mut sync, mut state) = (0u64, 0x9E37_79B9_7F4A_7C15u64);
    for _ in 0..n {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        sync += state % 40;
        if !enc.has_room(2) {
            payload.clear();
            enc.finish_batch(&mut payload);
            on_batch(&payload);
        }
        enc.push(Event::Photon {
            pixel: (state >> 24) as u16,
            micro: (state >> 44) as u32 % 120,
            sync,
        })
        .unwrap();
    }
    payload.clear();
    enc.finish_batch(&mut payload);
    on_batch(&payload);
}
