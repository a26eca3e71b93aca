//! Python with the packages `scripts/fetch_python_deps.sh` installs under
//! `target/pydeps` (numpy, ptufile, OpenEXR, ...): independent readers the
//! tests check our files against.

use std::path::Path;
use std::process::Command;

/// Runs `script` with `args` as `sys.argv[1:]`; panics with its stderr
/// when it fails, else returns its stdout.
pub fn python(script: &str, args: &[&Path]) -> String {
    let pydeps = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/pydeps");
    let out = Command::new("python3")
        .arg("-c")
        .arg(script)
        .args(args)
        .env("PYTHONPATH", &pydeps)
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}
