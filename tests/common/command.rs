//! The command-line program the tests run, and what they read back from
//! it: one place that names it, runs it and turns its output into text.
//! (Each test file uses some of these, hence the `dead_code` allowances.)

use std::ffi::OsStr;
use std::path::Path;
use std::process::{Command, Output};

/// The program built for this test run.
pub const PROGRAM: &str = env!("CARGO_BIN_EXE_scatterscope");

/// A 16 x 16 sensor over 3 cm: a mock acquisition small enough for a test.
#[allow(dead_code)]
pub const SMALL_SENSOR: [&str; 4] = ["--size", "16", "--fov", "3cm"];

/// A `scatterscope` command with no arguments yet.
pub fn scatterscope() -> Command {
    Command::new(PROGRAM)
}

/// Runs the program with `args` in the test's environment.
#[allow(dead_code)]
pub fn run<S: AsRef<OsStr>>(args: &[S]) -> Output {
    scatterscope().args(args).output().expect("binary runs")
}

/// Runs the program with `args` apart from the user's set-up: no weights
/// variable and an empty data directory (so the prior is the embedded
/// one), no cache folder, no backtraces in its errors.
#[allow(dead_code)]
pub fn run_isolated<S: AsRef<OsStr>>(args: &[S]) -> Output {
    run_with_data_dir(args, Path::new("/nonexistent/scatterscope-test-data"))
}

/// [`run_isolated`] with `data_dir` as the data directory.
#[allow(dead_code)]
pub fn run_with_data_dir<S: AsRef<OsStr>>(args: &[S], data_dir: &Path) -> Output {
    scatterscope()
        .args(args)
        .env_remove("SCATTERSCOPE_FFDNET_WEIGHTS")
        .env("SCATTERSCOPE_DATA_DIR", data_dir)
        .env("SCATTERSCOPE_CACHE_DIR", "")
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("binary runs")
}

/// Standard output and standard error, apart.
#[allow(dead_code)]
pub fn streams(o: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Standard output then standard error, as one text.
#[allow(dead_code)]
pub fn text(o: &Output) -> String {
    let (out, err) = streams(o);
    out + &err
}

/// A JSON file the program wrote.
#[allow(dead_code)]
pub fn json(path: &Path) -> serde_json::Value {
    let text =
        std::fs::read_to_string(path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("parsing {}: {e}", path.display()))
}

/// Runs `simulate` of the disks scene on a `size` x `size` sensor at the
/// paper's pixel pitch (6.25 cm at 32 pixels) with `extra` flags into
/// `out`, apart from the user's set-up; its counts stack is
/// `out/counts.exr`.
#[allow(dead_code)]
pub fn simulate_disks(out: &Path, size: usize, extra: &[&str]) -> Output {
    let (size, fov) = (
        size.to_string(),
        format!("{}cm", 50.0 * size as f64 / 256.0),
    );
    let scene = [
        "simulate", "--scene", "disks", "--size", &size, "--fov", &fov,
    ];
    let mut args: Vec<&OsStr> = scene.iter().chain(extra).map(OsStr::new).collect();
    args.extend([OsStr::new("--out"), out.as_os_str()]);
    run_isolated(&args)
}

/// Waits (up to a minute: a loaded machine may take a while) until the
/// recording `path` is being written: its temporary (`.NAME.partial-...`
/// beside it) or the finished file exists.
#[allow(dead_code)]
pub fn wait_for_recording(path: &Path) {
    let name = path.file_name().expect("a file name").to_string_lossy();
    let dir = path.parent().expect("a folder");
    let prefix = format!(".{name}{}", scatterscope::files::output::PARTIAL_MARKER);
    let started = std::time::Instant::now();
    let writing = || {
        path.exists()
            || std::fs::read_dir(dir).is_ok_and(|mut entries| {
                entries
                    .any(|e| e.is_ok_and(|e| e.file_name().to_string_lossy().starts_with(&prefix)))
            })
    };
    while !writing() {
        assert!(
            started.elapsed() < std::time::Duration::from_secs(60),
            "{} was not started within a minute",
            path.display()
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Records a small mock acquisition's tags into `dir/run.sstags` (its
/// stack in `dir/acq`); the tag file.
#[allow(dead_code)]
pub fn mock_tags(dir: &Path) -> std::path::PathBuf {
    let tags = dir.join("run.sstags");
    let acq = dir.join("acq");
    let (t, a) = (tags.to_str().unwrap(), acq.to_str().unwrap());
    let args = [
        &["acquire", "--device", "mock", "--tags", t][..],
        &SMALL_SENSOR,
        &["--out", a],
    ]
    .concat();
    let r = run(&args);
    assert!(r.status.success(), "{}", text(&r));
    tags
}
