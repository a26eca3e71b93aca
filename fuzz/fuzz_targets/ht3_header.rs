//! Arbitrary bytes into the legacy HydraHarp and PicoHarp header parsers.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = scatterscope::formats::picoquant::legacy::parse_hydraharp(&mut &data[..]);
    let _ = scatterscope::formats::picoquant::legacy::parse_picoharp(&mut &data[..]);
});
