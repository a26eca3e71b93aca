//! Arbitrary bytes as a physics config file (TOML): an error naming the
//! file or a setup that passes its own validation.
#![no_main]
use libfuzzer_sys::fuzz_target;
use scatterscope::config::PhysicsOverrides;

#[path = "common/file.rs"]
mod file;

fuzz_target!(|data: &[u8]| {
    let path = file::write("physics.toml", data);
    let args = PhysicsOverrides { config: Some(path), ..Default::default() };
    if let Ok(setup) = args.resolve() {
        setup.validate().expect("a resolved setup is valid");
    }
});
