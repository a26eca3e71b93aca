//! Python with the packages `scripts/fetch_python_deps.sh` installs under
//! `target/pydeps` (numpy, ptufile, OpenEXR, playwright, ...): independent
//! readers the tests check our files against.

use std::ffi::OsStr;
use std::path::Path;
use std::process::Command;

/// The start of a script that reads PTU files with ptufile and keeps what
/// ptufile warns in the list `warned` (it warns through `logging`).
#[allow(dead_code)]
pub const PTUFILE_WARNINGS: &str = r#"
import logging, sys
import ptufile
warned = []
class Catch(logging.Handler):
    def emit(self, record):
        warned.append(record.getMessage())
logging.getLogger("ptufile").addHandler(Catch())
"#;

/// Runs the inline `script` with `args` as `sys.argv[1:]`; panics with its
/// output when it fails, else returns its stdout.
#[allow(dead_code)]
pub fn python<S: AsRef<OsStr>>(script: &str, args: &[S]) -> String {
    checked(Command::new("python3").arg("-c").arg(script).args(args))
}

/// Runs the script file `path` (relative to the repository) with `args`;
/// as [`python`].
#[allow(dead_code)]
pub fn python_file<S: AsRef<OsStr>>(path: &str, args: &[S]) -> String {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join(path);
    checked(Command::new("python3").arg(script).args(args))
}

fn checked(command: &mut Command) -> String {
    let pydeps = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/pydeps");
    let out = command
        .env("PYTHONPATH", &pydeps)
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}
