//! Arbitrary bytes into the legacy HydraHarp header parser.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = scatterscope::tags::picoquant::legacy::parse_hydraharp(&mut &data[..]);
});
