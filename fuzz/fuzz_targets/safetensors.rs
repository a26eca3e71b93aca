//! Arbitrary bytes as FFDNet weights (safetensors): refused with an error
//! or accepted with consistent tensor shapes, never a panic or a huge
//! allocation.
#![no_main]
use libfuzzer_sys::fuzz_target;
use scatterscope::denoise::ffdnet::weights::FfdnetWeights;

fuzz_target!(|data: &[u8]| {
    if let Ok(w) = FfdnetWeights::from_bytes(data, "fuzz") {
        assert!(w.arch.layers >= 2 && w.arch.channels >= 1);
    }
});
