//! Nothing lost, through the command line: no command writes over a file it
//! reads (by any spelling), no input blocks (FIFOs and devices refused at
//! once), results that are empty or doubtful end with a `warning:` line and
//! exit status 4, and a batch manifest is read bounded.

#[path = "common/command.rs"]
mod command;
use command::{run, text};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use scatterscope::formats::picoquant::writer::write_synthetic_t3;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn convert_onto_its_own_input_by_any_spelling_leaves_it_byte_identical() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("o");
    std::fs::create_dir(&o).unwrap();
    let rec = o.join("rec.ptu");
    write_synthetic_t3(&rec, 100_000).unwrap();
    let before = std::fs::read(&rec).unwrap();
    let hard = o.join("hard.ptu");
    std::fs::hard_link(&rec, &hard).unwrap();
    let soft = o.join("soft.ptu");
    std::os::unix::fs::symlink(&rec, &soft).unwrap();
    let absolute = std::path::absolute(&rec).unwrap();
    let cases: [(&str, PathBuf, PathBuf); 4] = [
        ("relative", rec.clone(), o.join(".").join("rec.ptu")),
        ("absolute", rec.clone(), absolute),
        ("symlink", rec.clone(), soft),
        ("hard link", hard, rec.clone()),
    ];
    for (how, input, output) in cases {
        let r = run(&["convert", s(&input), "--out", s(&output)]);
        assert_eq!(r.status.code(), Some(1), "{how}: {}", text(&r));
        assert!(text(&r).contains("same file"), "{how}: {}", text(&r));
        assert_eq!(
            std::fs::read(&rec).unwrap(),
            before,
            "{how}: the input changed"
        );
    }
    // A command whose output is named as its input: refused by identity.
    let r = run(&[
        "simulate",
        "--scene",
        "disks",
        "--size",
        "32",
        "--out",
        s(&o),
    ]);
    assert!(r.status.success(), "{}", text(&r));
    std::fs::rename(o.join("counts.exr"), o.join("reconstruction.exr")).unwrap();
    let before = std::fs::read(o.join("reconstruction.exr")).unwrap();
    let r = run(&[
        "reconstruct",
        s(&o.join("reconstruction.exr")),
        "--method",
        "rl-sum",
        "--out",
        s(&o),
    ]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(
        text(&r).contains("is an input of this command"),
        "{}",
        text(&r)
    );
    assert_eq!(std::fs::read(o.join("reconstruction.exr")).unwrap(), before);
}

#[test]
fn a_fifo_as_any_input_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = |name: &str| {
        let p = dir.path().join(name);
        assert!(Command::new("mkfifo").arg(&p).status().unwrap().success());
        p.to_str().unwrap().to_string()
    };
    let (ptu, tags, npy, toml) = (
        fifo("pipe.ptu"),
        fifo("pipe.sstags"),
        fifo("pipe.npy"),
        fifo("pipe.toml"),
    );
    let out = dir.path().join("out");
    let o = s(&out);
    let converted = dir.path().join("c.ptu");
    let cases: Vec<Vec<&str>> = vec![
        vec!["info", &ptu],
        vec!["bin", &ptu, "--out", o],
        vec!["convert", &ptu, "--out", s(&converted)],
        vec!["simulate", "--irf-from", &ptu, "--out", o],
        vec![
            "acquire",
            "--t0-from",
            &tags,
            "--duration",
            "100ms",
            "--out",
            o,
        ],
        vec!["reconstruct", &npy, "--out", o],
        vec!["batch", &toml, "--out", o],
    ];
    for args in cases {
        let t = Instant::now();
        let r = run(&args);
        assert!(
            t.elapsed() < Duration::from_secs(5),
            "{args:?} took {:?}",
            t.elapsed()
        );
        assert_eq!(r.status.code(), Some(1), "{args:?}: {}", text(&r));
        assert!(
            text(&r).contains("FIFO") && text(&r).contains("pipe"),
            "{args:?}: {}",
            text(&r)
        );
    }
}

#[test]
fn a_batch_manifest_that_is_a_device_or_huge_is_refused_in_under_a_second() {
    let dir = tempfile::tempdir().unwrap();
    let big = dir.path().join("big.toml");
    std::fs::File::create(&big)
        .unwrap()
        .set_len(10 << 30)
        .unwrap();
    for (manifest, words) in [
        ("/dev/zero", "not a regular file"),
        (s(&big), "batch manifest"),
    ] {
        let t = Instant::now();
        let r = run(&["batch", manifest, "--out", s(&dir.path().join("o"))]);
        assert!(
            t.elapsed() < Duration::from_secs(1),
            "{manifest}: {:?}",
            t.elapsed()
        );
        assert_eq!(r.status.code(), Some(1), "{}", text(&r));
        assert!(text(&r).contains(words), "{}", text(&r));
    }
    let usage =
        nix::sys::resource::getrusage(nix::sys::resource::UsageWho::RUSAGE_CHILDREN).unwrap();
    assert!(usage.max_rss() < 50 << 10, "peak {} KiB", usage.max_rss());
}

#[test]
fn an_empty_stack_is_written_with_a_warning_and_exit_status_4() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec.ptu");
    write_synthetic_t3(&rec, 10_000).unwrap();
    for flags in [vec!["--channel", "99"], vec!["--t-start", "1e15"]] {
        let out = dir.path().join("out");
        let mut args = vec!["bin", s(&rec), "--out", s(&out)];
        args.extend(&flags);
        let r = run(&args);
        let all = text(&r);
        assert_eq!(r.status.code(), Some(4), "{flags:?}: {all}");
        let warning = all
            .lines()
            .find(|l| l.starts_with("warning: the stack is empty"))
            .unwrap_or_else(|| panic!("{flags:?}: {all}"));
        assert!(warning.contains("10000 photons"), "{warning}");
        assert!(out.join("stack.exr").exists());
    }
}

fn shared(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel)
}

#[test]
#[ignore = "needs ../shared/data/cdt-scenes"]
fn hidden_warns_of_a_scan_shorter_than_the_depth_and_of_an_empty_volume() {
    let dir = tempfile::tempdir().unwrap();
    let scan = shared("cdt-scenes/letter_s.mat");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "hidden",
            s(&scan),
            "--scan-side",
            "63.6cm",
            "--bin-width",
            "16ps",
            "--out",
            s(dir.path()),
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    let r = run(&["--slab-thickness", "1in", "--depth", "3m"]);
    assert_eq!(r.status.code(), Some(4), "{}", text(&r));
    assert!(
        text(&r).contains("letter_s.mat: the scan holds 512 bins after time zero")
            && text(&r).contains("the depth asked is 3 m"),
        "{}",
        text(&r)
    );
    let r = run(&["--slab-thickness", "1000m"]);
    assert_eq!(r.status.code(), Some(4), "{}", text(&r));
    assert!(text(&r).contains("volume is all zero"), "{}", text(&r));
    // The shared scan at its published settings: no warning.
    let r = run(&["--slab-thickness", "1in"]);
    assert_eq!(r.status.code(), Some(0), "{}", text(&r));
}

#[test]
#[ignore = "needs ../shared/data/cdt-calibration"]
fn a_slab_fit_with_swapped_thicknesses_warns_and_writes_no_medium_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| shared(&format!("cdt-calibration/{name}.mat"));
    let (irf, thin, thick) = (
        d("capture_direct"),
        d("capture_1_0_inch"),
        d("capture_4_0_inch"),
    );
    let thin_as_thick = format!("{}=4in", s(&thin));
    let thick_as_thin = format!("{}=1in", s(&thick));
    let r = run(&[
        "calibrate-slab",
        "--irf-from",
        s(&irf),
        "--bin-width",
        "8ps",
        "--refractive-index",
        "1.12",
        "--capture",
        &thin_as_thick,
        "--capture",
        &thick_as_thin,
        "--out",
        s(dir.path()),
    ]);
    let all = text(&r);
    assert_eq!(r.status.code(), Some(4), "{all}");
    assert!(all.contains("warning: chi2/dof = "), "{all}");
    assert!(dir.path().join("fit.csv").exists());
    assert!(!dir.path().join("material.toml").exists());
}

#[test]
fn implausible_files_are_refused_naming_the_field_and_value() {
    use scatterscope::calibrate::histogram::TimeHistogram;
    use scatterscope::events::Imaging;
    use scatterscope::formats::picoquant::records::RecordType;
    use scatterscope::formats::picoquant::writer::{PtuWriter, WriterHeader};
    use scatterscope::stack::{Stack, StackMeta, ValueKind};
    let dir = tempfile::tempdir().unwrap();
    // A scan whose line start and stop are the same marker.
    let ptu = dir.path().join("scan.ptu");
    let img = Imaging {
        pixels_x: 4,
        pixels_y: 4,
        line_start: 1,
        line_stop: 1,
        frame: 0,
        bidirectional: false,
    };
    let h = WriterHeader {
        resolution_s: 4e-12,
        sync_rate_hz: 80e6,
        device: "test".into(),
        imaging: Some(img),
        extra: Vec::new(),
    };
    PtuWriter::create(&ptu, RecordType::GenericT3, &h)
        .unwrap()
        .finish()
        .unwrap();
    let e = scatterscope::formats::picoquant::open(&ptu)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("scan.ptu") && e.contains("both marker 1"), "{e}");
    // Histograms with no photon, or more than any measurement counts.
    let src = Path::new("capture.mat");
    let e = TimeHistogram::new(vec![0.0; 50], 8.0, 0.0, src)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("capture.mat") && e.contains("all 50 values are 0: no photon was recorded"),
        "{e}"
    );
    let e = TimeHistogram::new(vec![1.0, 1e300], 8.0, 0.0, src)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bin 1 holds 1e300, more than any measurement counts"),
        "{e}"
    );
    // Sidecars with bins out of order, or of a version not known.
    let npy = dir.path().join("s.npy");
    let meta = StackMeta::measured(0.0, 10.0, 3, "test".into(), None);
    Stack::new(ndarray::Array3::from_elem((3, 2, 2), 1.0), meta)
        .save(&npy)
        .unwrap();
    let side = dir.path().join("s.json");
    let json = std::fs::read_to_string(&side).unwrap();
    for (from, to, words) in [
        ("\"version\": 1", "\"version\": 99", "metadata version 99"),
        (
            "20.0",
            "10.0",
            "bin_starts_ps[2] = 10 ps does not come after",
        ),
        ("20.0", "5.0", "bin_starts_ps[2] = 5 ps does not come after"),
    ] {
        assert!(json.contains(from), "{json}");
        std::fs::write(&side, json.replacen(from, to, 1)).unwrap();
        let e = Stack::load(&npy).unwrap_err().to_string();
        assert!(e.contains(words) && e.contains("s.npy"), "{words}: {e}");
    }
    let _ = ValueKind::Counts;
}

#[test]
fn a_whole_count_past_2_to_the_53_is_named_as_implausible_not_as_fractional() {
    let counts = ndarray::Array2::from_elem((2, 2), 3e38);
    let e = scatterscope::poisson::thinning::thin_halves(&counts, 1, "the counts")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("3e38 photons, more than any measurement counts"),
        "{e}"
    );
}

#[test]
fn picoquant_flags_given_to_another_device_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let ptu = dir.path().join("rec.ptu");
    let r = run(&[
        "acquire",
        "--device",
        "mock",
        "--duration",
        "100ms",
        "--ptu",
        s(&ptu),
        "--t3-offset",
        "10ns",
        "--out",
        s(&dir.path().join("o")),
    ]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(
        text(&r).contains("--t3-offset set a PicoQuant device"),
        "{}",
        text(&r)
    );
    assert!(!ptu.exists() && !dir.path().join("o").exists());
}
