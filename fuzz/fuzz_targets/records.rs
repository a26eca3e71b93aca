//! Arbitrary records through a decoder (the first byte picks the record
//! type) and the binner: no panic, no
//! overflow, and the photon accounting always balances.
//!
//! The binners (their 64 KiB micro-time tables) are built once and cloned
//! per input, so a run costs the decoding, not the set-up.
#![no_main]
use std::sync::LazyLock;

use libfuzzer_sys::fuzz_target;
use scatterscope::tags::binning::{Binner, FrameSelect, PixelMap, TimeWindow};
use scatterscope::events::Imaging;
use scatterscope::formats::picoquant::records::{Decoder, RecordType};

static BINNERS: LazyLock<Vec<(RecordType, Binner)>> = LazyLock::new(|| {
    let img = Imaging {
        pixels_x: 8,
        pixels_y: 8,
        line_start: 1,
        line_stop: 2,
        frame: 4,
        bidirectional: true,
    };
    let window = TimeWindow { start: 0.0, width: 64.0, bins: 16 };
    RecordType::ALL
        .iter()
        .map(|&rt| (rt, Binner::new(window, PixelMap::Scan(img), None, FrameSelect::All)))
        .collect()
});

fuzz_target!(|data: &[u8]| {
    // First byte: the record type; the rest: records.
    let Some((&pick, records)) = data.split_first() else { return };
    let (rt, binner) = &BINNERS[usize::from(pick) % BINNERS.len()];
    let mut d = Decoder::new(*rt);
    let mut b = binner.clone();
    for c in records.chunks_exact(4) {
        b.push(d.decode(u32::from_le_bytes([c[0], c[1], c[2], c[3]])));
    }
    let acc = b.finish().1;
    assert!(acc.balances(), "{acc:?}");
    assert_eq!(acc.records, (records.len() / 4) as u64);
});
