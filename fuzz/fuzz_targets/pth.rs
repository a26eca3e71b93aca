//! Arbitrary bytes as a PyTorch checkpoint (.pth: zip + pickle): refused
//! with an error or converted to safetensors that the weights loader
//! accepts.
#![no_main]
use libfuzzer_sys::fuzz_target;
use scatterscope::denoise::ffdnet::pth::import_ffdnet_gray;
use scatterscope::denoise::ffdnet::weights::FfdnetWeights;

fuzz_target!(|data: &[u8]| {
    if let Ok(st) = import_ffdnet_gray(data, std::path::Path::new("fuzz.pth")) {
        FfdnetWeights::from_bytes(&st, "fuzz.pth").expect("imported weights load");
    }
});
