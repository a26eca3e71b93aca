//! A per-process scratch file on tmpfs (or the temporary directory) for
//! readers that take a path.
use std::path::PathBuf;

pub fn write(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = if std::path::Path::new("/dev/shm").is_dir() {
        PathBuf::from("/dev/shm")
    } else {
        std::env::temp_dir()
    };
    let path = dir.join(format!("scatterscope-fuzz-{}-{name}", std::process::id()));
    std::fs::write(&path, bytes).expect("scratch file writes");
    path
}
