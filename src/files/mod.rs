//! How the library touches the file system: every file input passes one
//! gate ([`input`]: regular files only, opened without blocking, their
//! identity remembered), and every output is written whole or not at all
//! ([`output`]: a temporary name in the destination folder, then a rename),
//! never over a file the process has read; a run that names several files
//! checks them together before it starts ([`plan`]).

pub mod input;
pub mod output;
pub mod plan;

pub use input::{FileId, ReadError, open_input, open_regular, read_bounded};

/// Bytes an unprivileged writer may still put on the file system that
/// holds `path` (or its folder, for a file not yet written); `None` where
/// the system does not say.
pub fn free_bytes(path: &std::path::Path) -> Option<u64> {
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        let dir = match path.parent() {
            Some(p) if !path.is_dir() => {
                if p.as_os_str().is_empty() {
                    std::path::Path::new(".")
                } else {
                    p
                }
            }
            _ => path,
        };
        let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
        let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
        // SAFETY: `c` is a NUL-terminated path and `st` a valid buffer for
        // the call to fill.
        let rc = unsafe { libc::statvfs(c.as_ptr(), &mut st) };
        // fsblkcnt_t and c_ulong are 64 bits on 64-bit Linux, narrower on
        // some other unixes: widened where they are not.
        #[allow(clippy::useless_conversion)]
        let (blocks, size) = (u64::from(st.f_bavail), u64::from(st.f_frsize));
        (rc == 0).then(|| blocks.saturating_mul(size))
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        None
    }
}
pub use output::{AtomicFile, Completion, write_atomic};
pub use plan::{FilePlan, PlanError};
