//! Arbitrary bytes into the PTU tagged-header parser: errors, never panics.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = scatterscope::formats::picoquant::ptu::parse(&mut &data[..]);
});
