//! Nothing lost, round two: the cases an independent bad-input run found
//! on the command line (each failed before its fix). Outputs are checked
//! against each other and every input before a device opens; user numbers
//! are bounded before they are converted; every reader of counts shares
//! the same limits; a MATLAB file is held to what its read allocates;
//! output says what is true (channel names in time order, empty bins as
//! ranges, hints that name the cure, no files from a refused run).

#[path = "common/command.rs"]
mod command;
#[path = "common/pydeps.rs"]
mod pydeps;

use command::{run, text};
use std::path::Path;
use std::time::{Duration, Instant};

use ndarray::Array3;
use scatterscope::stack::{Stack, StackMeta};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The names in `dir`, sorted.
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// A short mock recording to play back (a PTU of a 7 x 7 sensor).
fn recording(dir: &Path) -> std::path::PathBuf {
    let ptu = dir.join("rec.ptu");
    let r = run(&[
        "acquire",
        "--size",
        "7",
        "--duration",
        "300ms",
        "--ptu",
        s(&ptu),
        "--out",
        s(&dir.join("made")),
    ]);
    assert!(r.status.success(), "{}", text(&r));
    ptu
}

/// A 5 s mock acquisition with `extra` flags into `out`, which must be
/// refused (exit 1) before it acquires; its text.
fn refused_before_the_run(extra: &[&str], out: &Path) -> String {
    let t = Instant::now();
    let mut args = vec![
        "acquire",
        "--size",
        "7",
        "--duration",
        "5s",
        "--out",
        s(out),
    ];
    args.extend_from_slice(extra);
    let r = run(&args);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(
        t.elapsed() < Duration::from_secs(4),
        "acquired first: {}",
        text(&r)
    );
    assert!(!text(&r).contains("DOES NOT BALANCE"), "{}", text(&r));
    text(&r)
}

#[test]
fn two_outputs_by_two_spellings_of_one_file_are_refused_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let x = dir.path().join("X");
    let dotted = dir.path().join(".").join("X");
    for (ptu, tags) in [(&x, &x), (&x, &dotted)] {
        let t =
            refused_before_the_run(&["--ptu", s(ptu), "--tags", s(tags)], &dir.path().join("o"));
        assert!(t.contains("are the same file"), "{t}");
        assert!(names(dir.path()).is_empty(), "{:?}", names(dir.path()));
    }
    // The recording replayed is an input: not an output too.
    let rec = recording(dir.path());
    let before = std::fs::read(&rec).unwrap();
    let r = run(&[
        "acquire",
        "--device",
        &format!("replay:{}", s(&rec)),
        "--ptu",
        s(&dir.path().join(".").join("rec.ptu")),
        "--out",
        s(&dir.path().join("o")),
    ]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(
        text(&r).contains("the recording replayed: refusing to write over an input"),
        "{}",
        text(&r)
    );
    assert_eq!(std::fs::read(&rec).unwrap(), before);
    assert!(!dir.path().join("o").exists());
}

#[test]
fn an_output_that_cannot_be_written_is_refused_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    for bad in ["/proc/x.ptu", "/dev/null/x.ptu"] {
        let t = refused_before_the_run(&["--ptu", bad], &out);
        assert!(
            t.contains(&format!("the PTU recording {bad} cannot be written")),
            "{t}"
        );
        assert!(t.contains("hint: --ptu"), "{t}");
        assert!(!out.exists());
    }
}

#[test]
fn a_replay_speed_past_its_bounds_is_refused_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let rec = recording(dir.path());
    for speed in ["1e-300", "5e-324", "0", "1e300", "NaN"] {
        let r = run(&[
            "acquire",
            "--device",
            &format!("replay:{}", s(&rec)),
            "--speed",
            speed,
            "--out",
            s(&dir.path().join("o")),
        ]);
        assert_eq!(r.status.code(), Some(1), "--speed {speed}: {}", text(&r));
        assert!(
            text(&r).contains("give a factor from 0.001 to 1e6")
                && text(&r).contains("hint: set it with --speed"),
            "{}",
            text(&r)
        );
    }
}

#[test]
fn a_refused_mock_run_leaves_no_files_and_its_hint_names_the_cure() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let r = run(&[
        "acquire",
        "--size",
        "64",
        "--duration",
        "5s",
        "--ptu",
        s(&out.join("m.ptu")),
        "--out",
        s(&out),
    ]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    let t = text(&r);
    assert!(t.contains("64 x 64 = 4096 pixels"), "{t}");
    assert!(!t.contains("set it with --ptu"), "{t}");
    assert!(t.contains("hint: --tags records every pixel"), "{t}");
    assert!(!out.exists(), "{:?}", names(dir.path()));
}

#[test]
fn a_replayed_scan_lists_its_empty_bins_as_ranges_on_a_short_line() {
    let dir = tempfile::tempdir().unwrap();
    let rec = recording(dir.path());
    let r = run(&[
        "acquire",
        "--device",
        &format!("replay:{}", s(&rec)),
        "--speed",
        "100",
        "--out",
        s(&dir.path().join("o")),
    ]);
    assert!(r.status.success(), "{}", text(&r));
    let line = text(&r)
        .lines()
        .find(|l| l.contains("bins are empty"))
        .map(str::to_string)
        .unwrap_or_else(|| panic!("{}", text(&r)));
    assert!(line.len() < 200, "{} characters: {line}", line.len());
    assert!(line.contains('-'), "{line}");
}

#[test]
fn reconstruct_refuses_a_stack_without_light_for_every_method() {
    let dir = tempfile::tempdir().unwrap();
    let zero = dir.path().join("zero.npy");
    let meta = StackMeta::measured(0.0, 16.0, 4, "test".into(), None);
    Stack::new(Array3::zeros((4, 8, 8)), meta.clone())
        .save(&zero)
        .unwrap();
    for method in ["auto", "rl-stack", "rl-sum", "pnp"] {
        let out = dir.path().join(method);
        let r = run(&[
            "reconstruct",
            s(&zero),
            "--method",
            method,
            "--size",
            "8",
            "--out",
            s(&out),
        ]);
        assert_eq!(r.status.code(), Some(1), "{method}: {}", text(&r));
        assert!(
            text(&r).contains("all 256 values are 0: no photon was recorded"),
            "{method}: {}",
            text(&r)
        );
        assert!(!out.exists(), "{method}");
    }
}

/// `hidden` on `scan` (a 60 cm scan through an inch of slab, 16 ps bins)
/// into `out`: refused (exit 1) with `words`, nothing written.
fn hidden_refuses(scan: &Path, out: &Path, words: &str) {
    let r = run(&[
        "hidden",
        s(scan),
        "--scan-side",
        "60cm",
        "--slab-thickness",
        "1in",
        "--bin-width",
        "16ps",
        "--out",
        s(out),
    ]);
    assert_eq!(r.status.code(), Some(1), "{}: {}", scan.display(), text(&r));
    assert!(text(&r).contains(words), "{}: {}", scan.display(), text(&r));
    assert!(!out.exists(), "{}", scan.display());
}

#[test]
fn hidden_shares_the_count_limits_of_every_reader() {
    let dir = tempfile::tempdir().unwrap();
    let meta = StackMeta::measured(0.0, 16.0, 8, "test".into(), None);
    let mut counts = Array3::<f32>::from_elem((8, 4, 4), 3.0);
    for (name, fill, words) in [
        ("max", f32::MAX, "more than any measurement counts"),
        ("e30", 1e30, "more than any measurement counts"),
        ("two63", 2f32.powi(63), "more than any measurement counts"),
        ("tiny", 1e-45, "less than one photon"),
    ] {
        let scan = dir.path().join(format!("{name}.npy"));
        if name == "max" {
            counts[(3, 1, 2)] = fill;
        } else {
            counts.fill(fill);
        }
        Stack::new(counts.clone(), meta.clone())
            .save(&scan)
            .unwrap();
        hidden_refuses(&scan, &dir.path().join(format!("out-{name}")), words);
    }
}

#[test]
#[ignore = "needs h5py under target/pydeps (scripts/fetch_python_deps.sh)"]
fn a_mat_bomb_is_refused_before_a_gigabyte() {
    let dir = tempfile::tempdir().unwrap();
    let bomb = dir.path().join("bomb.mat");
    let empty = dir.path().join("empty.mat");
    let absurd = dir.path().join("absurd.mat");
    pydeps::python(
        r#"
import sys, numpy as np, h5py
with h5py.File(sys.argv[1], "w") as f:
    d = f.create_dataset("meas", shape=(512, 512, 1200), dtype="f4", chunks=(64, 64, 1200),
                         compression="gzip", compression_opts=9, fillvalue=0)
    z = np.zeros((64, 64, 1200), np.float32); z[0, 0, 0] = 1
    for i in range(0, 512, 64):
        for j in range(0, 512, 64):
            d[i:i + 64, j:j + 64, :] = z
with h5py.File(sys.argv[2], "w") as f:
    f.create_dataset("meas", shape=(4096, 4096, 4096), dtype="f4", chunks=(64, 64, 64))
with h5py.File(sys.argv[3], "w") as f:
    f.create_dataset("meas", data=np.full((16, 16, 64), 2.0**63))
"#,
        &[s(&bomb), s(&empty), s(&absurd)],
    );
    assert!(std::fs::metadata(&bomb).unwrap().len() < 2 << 20);
    for (scan, words) in [
        (&bomb, "more than 64 times its size"),
        (&empty, "more than 64 times its size"),
        (&absurd, "more than any measurement counts"),
    ] {
        let t = Instant::now();
        hidden_refuses(scan, &dir.path().join("out"), words);
        assert!(t.elapsed() < Duration::from_secs(10));
    }
    // Every child so far, at its peak (ru_maxrss, KiB).
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage) };
    assert!(
        usage.ru_maxrss < 1 << 20,
        "a child peaked at {} KiB",
        usage.ru_maxrss
    );
}

#[test]
#[ignore = "needs OpenEXR under target/pydeps (scripts/fetch_python_deps.sh)"]
fn an_exr_of_3125_bins_comes_back_in_time_order_from_openexr() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("long.exr");
    let bins = 3125;
    let meta = StackMeta::measured(0.0, 4.0, bins, "test".into(), None);
    // Bin k holds k in every pixel: a reader's order shows in the values.
    let counts = Array3::from_shape_fn((bins, 2, 3), |(k, _, _)| k as f32);
    Stack::new(counts, meta).save(&path).unwrap();
    let out = pydeps::python(
        r#"
import sys, OpenEXR
with OpenEXR.File(sys.argv[1]) as f:
    channels = f.parts[0].channels
    names = list(channels.keys())
    print(",".join(str(int(channels[n].pixels[0, 0])) for n in names))
    print(names[0], names[999], names[1000], names[-1])
"#,
        &[s(&path)],
    );
    let mut lines = out.lines();
    let values: Vec<usize> = lines
        .next()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(values, (0..bins).collect::<Vec<_>>());
    assert_eq!(lines.next().unwrap(), "t0000 t0999 t1000 t3124");
    // And our own reader, by number.
    let back = Stack::load(&path).unwrap();
    assert_eq!(back.data[(1000, 1, 2)], 1000.0);
}
