//! Arbitrary bytes as an OpenEXR stack: an error or values, never a panic;
//! a stack that validates holds only finite non-negative values.
#![no_main]
use libfuzzer_sys::fuzz_target;
use scatterscope::stack::Stack;

#[path = "common/file.rs"]
mod file;

fuzz_target!(|data: &[u8]| {
    let path = file::write("stack.exr", data);
    if let Ok((values, Some(meta))) = Stack::read(&path) {
        if let Ok(stack) = Stack::from_parts(values, meta, &path) {
            assert!(stack.data.iter().all(|v| v.is_finite() && *v >= 0.0));
        }
    }
});
