//! Nothing lost, round four: the defects an independent run of bad and
//! odd inputs found in the decay maps and the recorded-file readers (each
//! failed before its fix). A laser frequency no laser has is refused or
//! overruled by the file's other statement of it, with the cure named;
//! an `.sdt` block whose zip member fails its CRC-32 is refused; values
//! without a range are refused before any output grows. Files are made
//! from the documented layouts (`common/bh_files.rs`; a PTU tag's value
//! patched in place, `PQTTTR` tag layout: 32-byte name, index, type,
//! 8-byte value).

#[path = "common/bh_files.rs"]
mod bh_files;
#[path = "common/command.rs"]
mod command;

use std::path::{Path, PathBuf};

use bh_files::{SdtBlock, SdtMeasurement, sdt_file, sdt_file_zipped};
use command::{run, text};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// An `.sdt` FLIM image of 3 x 2 pixels and 64 time points (a decay in
/// every pixel), its StopInfo holding `sync_rates` (min, max).
fn sdt_image(dir: &Path, name: &str, sync_rates: (f32, f32)) -> PathBuf {
    sdt_image_of(dir, name, sync_rates, (3, 2))
}

/// [`sdt_image`] of `size` (columns, rows) pixels.
fn sdt_image_of(dir: &Path, name: &str, sync_rates: (f32, f32), size: (i32, i32)) -> PathBuf {
    let path = dir.join(name);
    let mut m = SdtMeasurement::spc150(12.5e-9, 1, 64, size);
    m.sync_rates = sync_rates;
    let values: Vec<f64> = (0..(size.0 * size.1) as usize * 64)
        .map(|i| {
            let t = (i % 64) as f64;
            if t < 8.0 {
                0.0
            } else {
                (400.0 * (-(t - 8.0) / 10.0).exp()).round()
            }
        })
        .collect();
    let block = SdtBlock {
        values,
        item: 2,
        zipped: false,
        contents: 0x60,
        measurement: 0,
    };
    std::fs::write(&path, sdt_file(&[m], &[block])).unwrap();
    path
}

#[test]
fn an_sdt_whose_stop_info_holds_no_laser_rate_asks_for_one() {
    let dir = tempfile::tempdir().unwrap();
    // The two kinds of nonsense real SPC-150 files (revision 14) hold.
    for (i, rates) in [(-1.16e7, 3.9e-42), (2.0e-41, 8.96e20)]
        .into_iter()
        .enumerate()
    {
        let path = sdt_image(dir.path(), "bad.sdt", rates);
        let out = dir.path().join(format!("maps{i}"));
        let r = run(&["lifetime", s(&path), "--out", s(&out)]);
        let t = text(&r);
        assert!(!r.status.success(), "{t}");
        assert!(
            t.contains("states no laser frequency that can be used")
                && t.contains("MEASURE_INFO.StopInfo.max_sync_rate")
                && t.contains("--frequency"),
            "{t}"
        );
        assert!(!out.join("maps.ome.tif").exists());
        let r = run(&[
            "lifetime",
            s(&path),
            "--frequency",
            "80e6",
            "--out",
            s(&out),
        ]);
        assert!(r.status.success(), "{}", text(&r));
        // `bin` keeps no rate the file does not state, and says why.
        let binned = dir.path().join(format!("bin{i}"));
        let r = run(&["bin", s(&path), "--npy", "--out", s(&binned)]);
        assert!(r.status.success(), "{}", text(&r));
        let meta = std::fs::read_to_string(binned.join("stack.json")).unwrap();
        assert!(!meta.contains("laser_frequency_hz"), "{meta}");
        assert!(meta.contains("is not the laser's rate"), "{meta}");
    }
    // A file that states its rate maps at it.
    let path = sdt_image(dir.path(), "good.sdt", (80e6, 80e6));
    let out = dir.path().join("good");
    let r = run(&["lifetime", s(&path), "--out", s(&out)]);
    let t = text(&r);
    assert!(r.status.success() && t.contains("of 80.000000 MHz"), "{t}");
}

#[test]
fn a_frequency_no_laser_has_is_refused_by_value() {
    let dir = tempfile::tempdir().unwrap();
    let path = sdt_image(dir.path(), "good.sdt", (80e6, 80e6));
    for (given, words) in [
        ("1e300", "outside the repetition rates"),
        ("1e-300", "outside the repetition rates"),
        ("80", "80.000000 MHz is 80e6"),
    ] {
        let out = dir.path().join("maps");
        let r = run(&["lifetime", s(&path), "--frequency", given, "--out", s(&out)]);
        let t = text(&r);
        assert!(!r.status.success() && t.contains(words), "{given}: {t}");
        assert!(!out.join("maps.ome.tif").exists());
    }
}

/// The byte offset of PTU tag `name`'s 8-byte value in `bytes`.
fn ptu_tag_value(bytes: &[u8], name: &str) -> usize {
    let mut ident = [0u8; 32];
    ident[..name.len()].copy_from_slice(name.as_bytes());
    let at = bytes
        .windows(32)
        .position(|w| w == ident)
        .unwrap_or_else(|| panic!("tag {name}"));
    at + 40
}

/// A mock acquisition's PTU (80 MHz, its records timed by a 12.5 ns sync
/// period) with `TTResult_SyncRate` set to `rate`.
fn ptu_with_sync_rate(dir: &Path, rate: i64) -> PathBuf {
    let ptu = dir.join("rec.ptu");
    if !ptu.exists() {
        let r = run(&[
            "acquire",
            "--size",
            "4",
            "--duration",
            "200ms",
            "--ptu",
            s(&ptu),
            "--out",
            s(&dir.join("acq")),
        ]);
        assert!(r.status.success(), "{}", text(&r));
    }
    let mut bytes = std::fs::read(&ptu).unwrap();
    let at = ptu_tag_value(&bytes, "TTResult_SyncRate");
    bytes[at..at + 8].copy_from_slice(&rate.to_le_bytes());
    let patched = dir.join(format!("rate-{rate}.ptu"));
    std::fs::write(&patched, bytes).unwrap();
    patched
}

#[test]
fn a_ptu_whose_sync_rate_contradicts_its_period_is_mapped_at_the_period() {
    let dir = tempfile::tempdir().unwrap();
    for (rate, words) in [
        (1, "TTResult_SyncRate, 1 Hz lies outside"),
        (1 << 62, "lies outside the repetition rates"),
        (40_000_000, "TTResult_SyncRate (40.000000 MHz) contradicts"),
    ] {
        let path = ptu_with_sync_rate(dir.path(), rate);
        let out = dir.path().join(format!("maps-{rate}"));
        let r = run(&["lifetime", s(&path), "--out", s(&out)]);
        let t = text(&r);
        assert!(r.status.success(), "{t}");
        assert!(t.contains(words), "{rate}: {t}");
        let period = ptu_tag_value(&std::fs::read(&path).unwrap(), "MeasDesc_GlobalResolution");
        let bytes = std::fs::read(&path).unwrap();
        let hz = 1.0 / f64::from_le_bytes(bytes[period..period + 8].try_into().unwrap());
        assert!(
            t.contains(&format!("of {:.6} MHz", hz * 1e-6)),
            "{rate}: {t}"
        );
    }
}

#[test]
fn a_zipped_sdt_block_that_fails_its_crc_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let m = SdtMeasurement::spc150(12.5e-9, 1, 16, (3, 2));
    let values: Vec<f64> = (0..6 * 16).map(|i| (i * 37 % 251) as f64).collect();
    let block = SdtBlock {
        values: values.clone(),
        item: 2,
        zipped: true,
        contents: 0x60,
        measurement: 0,
    };
    let mut bytes = sdt_file_zipped(&[m], &[block], zip::CompressionMethod::Stored);
    // The stored member holds the points as they are: flip one bit of one.
    let raw: Vec<u8> = values
        .iter()
        .flat_map(|&v| (v as u16).to_le_bytes())
        .collect();
    let at = bytes
        .windows(raw.len())
        .position(|w| w == raw)
        .expect("the stored points");
    let path = dir.path().join("intact.sdt");
    std::fs::write(&path, &bytes).unwrap();
    let r = run(&["bin", s(&path), "--npy", "--out", s(&dir.path().join("a"))]);
    assert!(r.status.success(), "{}", text(&r));
    bytes[at + 40] ^= 0x40;
    let path = dir.path().join("flipped.sdt");
    std::fs::write(&path, &bytes).unwrap();
    let out = dir.path().join("b");
    for cmd in ["bin", "lifetime"] {
        let r = run(&[cmd, s(&path), "--out", s(&out)]);
        let t = text(&r);
        assert!(!r.status.success(), "{cmd}: {t}");
        assert!(
            t.contains("data block 0") && t.contains("CRC-32"),
            "{cmd}: {t}"
        );
    }
    assert!(!out.exists() || std::fs::read_dir(&out).unwrap().next().is_none());
}

#[test]
fn values_without_a_range_are_refused_before_any_output() {
    let dir = tempfile::tempdir().unwrap();
    let path = sdt_image(dir.path(), "good.sdt", (80e6, 80e6));
    let reference = sdt_image(dir.path(), "reference.sdt", (80e6, 80e6));
    let cases: [(&[&str], &str); 5] = [
        (&["--onset", "1e300"], "onset 1e300 ps"),
        (&["--onset", "20000"], "onset 20000 ps"),
        (
            &["--harmonics", "65536"],
            "harmonic 65536: give harmonics from 1 to 32",
        ),
        (&["--harmonics", "1,1"], "harmonic 1 given twice"),
        (
            &[
                "--reference",
                s(&reference),
                "--reference-lifetime",
                "1e300",
            ],
            "lifetime 1e300 ps",
        ),
    ];
    for (extra, words) in cases {
        let out = dir.path().join("maps");
        let mut args = vec!["lifetime", s(&path), "--out", s(&out)];
        args.extend_from_slice(extra);
        let r = run(&args);
        let t = text(&r);
        assert!(!r.status.success(), "{extra:?}: {t}");
        assert!(t.contains(words), "{extra:?}: {t}");
        assert!(!out.join("maps.ome.tif").exists(), "{extra:?}");
    }
}

#[test]
fn the_phasor_maps_are_inside_the_memory_budget() {
    let dir = tempfile::tempdir().unwrap();
    // 256 x 256 pixels: the block is 8 MB; 32 harmonics' maps 108 MB.
    let path = sdt_image_of(dir.path(), "big.sdt", (80e6, 80e6), (256, 256));
    let out = dir.path().join("maps");
    let all: Vec<String> = (1..=32).map(|h| h.to_string()).collect();
    let harmonics = all.join(",");
    let r = run(&[
        "lifetime",
        s(&path),
        "--harmonics",
        &harmonics,
        "--memory-limit",
        "64MiB",
        "--no-figures",
        "--out",
        s(&out),
    ]);
    let t = text(&r);
    assert!(!r.status.success(), "{t}");
    assert!(
        t.contains("the decay maps of 256 x 256 pixels at 32 harmonics"),
        "{t}"
    );
    assert!(!out.join("maps.ome.tif").exists());
    let r = run(&[
        "lifetime",
        s(&path),
        "--memory-limit",
        "64MiB",
        "--no-figures",
        "--out",
        s(&out),
    ]);
    assert!(r.status.success(), "{}", text(&r));
}

#[test]
fn a_stack_whose_pitch_contradicts_its_setup_is_refused_by_field() {
    let dir = tempfile::tempdir().unwrap();
    let sim = dir.path().join("sim");
    let r = run(&[
        "simulate",
        "--preset",
        "paper",
        "--size",
        "32",
        "--fov",
        "6.25cm",
        "--npy",
        "--out",
        s(&sim),
    ]);
    assert!(r.status.success(), "{}", text(&r));
    let json = sim.join("counts.json");
    let meta = std::fs::read_to_string(&json).unwrap();
    let bad = meta.replace("\"pixel_pitch_cm\": 0.1953125", "\"pixel_pitch_cm\": 0.5");
    assert_ne!(meta, bad, "{meta}");
    std::fs::write(&json, bad).unwrap();
    let r = run(&[
        "reconstruct",
        s(&sim.join("counts.npy")),
        "--out",
        s(&dir.path().join("rec")),
    ]);
    let t = text(&r);
    assert!(!r.status.success(), "{t}");
    assert!(
        t.contains("pixel_pitch_cm = 0.5 contradicts setup.sensor"),
        "{t}"
    );
}

#[test]
fn a_medium_no_light_crosses_as_modelled_is_refused_by_field() {
    let dir = tempfile::tempdir().unwrap();
    for (flag, value, words) in [
        ("--n", "0.5", "refractive_index = 0.5"),
        ("--mu-s", "0", "mu_s_per_cm = 0"),
        ("--g", "1", "g = 1"),
    ] {
        let r = run(&[
            "simulate",
            "--preset",
            "paper",
            "--size",
            "16",
            flag,
            value,
            "--out",
            s(&dir.path().join("x")),
        ]);
        let t = text(&r);
        assert!(!r.status.success(), "{flag} {value}: {t}");
        assert!(t.contains(words), "{flag} {value}: {t}");
    }
    // No slab at all is a model the diffusion approximation does not hold
    // for: reconstructed, and said.
    let sim = dir.path().join("thin");
    let r = run(&[
        "simulate",
        "--preset",
        "paper",
        "--size",
        "16",
        "--fov",
        "3cm",
        "--thickness",
        "0",
        "--t-start",
        "1ps",
        "--bin-width",
        "1ps",
        "--bins",
        "8",
        "--npy",
        "--out",
        s(&sim),
    ]);
    assert!(r.status.success(), "{}", text(&r));
    let r = run(&[
        "reconstruct",
        s(&sim.join("counts.npy")),
        "--method",
        "rl-sum",
        "--out",
        s(&dir.path().join("rec")),
    ]);
    let t = text(&r);
    assert!(t.contains("(thin-slab)"), "{t}");
}
