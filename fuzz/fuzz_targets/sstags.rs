//! Arbitrary bytes as a raw tag file (.sstags): read and binned without a
//! panic; the photon accounting balances and the batch counts agree with
//! the binner. Files with a small sensor also go through `bin_file`, what
//! `scatterscope bin` runs (large sensors make large stacks by design).
#![no_main]
use libfuzzer_sys::fuzz_target;
use scatterscope::tags::binning::{Binner, FrameSelect, PixelMap, TimeWindow};
use scatterscope::tags::wire::bin_batch;
use scatterscope::formats::sstags::read_tag_file;

#[path = "common/file.rs"]
mod file;

fuzz_target!(|data: &[u8]| {
    let path = file::write("tags.sstags", data);
    let window = TimeWindow { start: 0.0, width: 1.0, bins: 8 };
    let mut binner = Binner::new(window, PixelMap::Channel { width: 4 }, None, FrameSelect::Sum);
    if read_tag_file(&path, |batch| {
        bin_batch(batch, &mut binner);
    })
    .is_ok()
    {
        let acc = binner.finish().1;
        assert!(acc.balances(), "{acc:?}");
    }
    let small = scatterscope::formats::sstags::TagFile::open(&path)
        .is_ok_and(|r| u32::from(r.header.pixels_x) * u32::from(r.header.pixels_y) <= 4096);
    if small {
        let spec = scatterscope::BinSpec {
            bins: Some(8),
            ..scatterscope::BinSpec::default()
        };
        if let Ok(b) = scatterscope::bin_file(&path, &spec) {
            assert!(b.accounting.balances(), "{:?}", b.accounting);
        }
    }
});
