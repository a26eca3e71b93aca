//! Arbitrary bytes as a .npy stack and its JSON sidecar (the first two
//! bytes give the sidecar's length; none when it is 0): refused with an
//! error or read; what reads either validates or is refused naming a field.
#![no_main]
use libfuzzer_sys::fuzz_target;
use scatterscope::stack::Stack;

#[path = "common/file.rs"]
mod file;

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let n = usize::from(u16::from_le_bytes([data[0], data[1]])).min(data.len() - 2);
    let (json, npy) = data[2..].split_at(n);
    let path = file::write("stack.npy", npy);
    let side = path.with_extension("json");
    if n > 0 {
        std::fs::write(&side, json).expect("scratch file writes");
    } else {
        let _ = std::fs::remove_file(&side);
    }
    if let Ok((values, Some(meta))) = Stack::read(&path) {
        if let Ok(stack) = Stack::from_parts(values, meta, &path) {
            assert!(stack.data.iter().all(|v| v.is_finite() && *v >= 0.0));
        }
    }
});
