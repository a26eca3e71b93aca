//! Arbitrary records through every decoder and the binner: no panic, no
//! overflow, and the photon accounting always balances.
#![no_main]
use libfuzzer_sys::fuzz_target;
use scatterscope::tags::binning::{Binner, FrameSelect, PixelMap, TimeWindow};
use scatterscope::tags::picoquant::Imaging;
use scatterscope::tags::picoquant::records::{Decoder, RecordType};

fuzz_target!(|data: &[u8]| {
    let img = Imaging { pixels_x: 8, pixels_y: 8, line_start: 1, line_stop: 2, frame: 4, bidirectional: true };
    for rt in RecordType::ALL {
        let mut d = Decoder::new(rt);
        let window = TimeWindow { start: 0.0, width: 64.0, bins: 16 };
        let mut b = Binner::new(window, PixelMap::Scan(img), None, FrameSelect::All);
        for c in data.chunks_exact(4) {
            b.push(d.decode(u32::from_le_bytes([c[0], c[1], c[2], c[3]])));
        }
        assert!(b.finish().1.balances());
    }
});
