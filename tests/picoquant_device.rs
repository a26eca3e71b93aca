//! `acquire --device picoquant` against the stand-in vendor library
//! (`mocks/picoquant`), loaded through the same run-time loader as
//! PicoQuant's MHLib and HHLib: the PTU it writes reads back into the same
//! stack, fault modes land in the ledger with the totals of what the device
//! delivered, scans bin into the scanner's image, a missing library or an
//! unwritable PTU is a clear error with the stack kept; and `convert` to
//! PTU is lossless.

#[path = "common/command.rs"]
mod command;
use command::{json, text};
#[path = "common/ptu_tags.rs"]
mod ptu_tags;
#[path = "common/pydeps.rs"]
mod pydeps;
#[path = "common/shared_data.rs"]
mod shared_data;
#[path = "common/standin.rs"]
mod standin;

use std::path::Path;

use ptu_tags::ptu_tags;
use scatterscope::events::Tag;
use scatterscope::formats::picoquant::open;
use scatterscope::formats::sstags::TagFile;
use scatterscope::stack::Stack;
use standin::{scatterscope_pq, standin_library, truth};

/// Acquires from the stand-in; returns the output folder's path and the
/// command's output.
fn acquire(
    dir: &Path,
    device: &str,
    mock: &str,
    extra: &[&str],
) -> (std::path::PathBuf, std::process::Output) {
    let out = dir.join("acq");
    let lib = standin_library();
    let mut args = vec![
        "acquire",
        "--device",
        device,
        "--vendor-lib",
        lib.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    // 300 ms unless the caller gives its own duration.
    if !extra.contains(&"--duration") {
        args.extend(["--duration", "300ms"]);
    }
    args.extend_from_slice(extra);
    let o = scatterscope_pq(&args, mock);
    (out, o)
}

/// Every family the stand-in models, with its board setting
/// (`SCATTERSCOPE_PQ_MOCK`): the TimeHarp 260 as a Pico and as a Nano.
const BOARDS: [(&str, &str); 6] = [
    ("multiharp", ""),
    ("hydraharp", ""),
    ("timeharp260", "th260=pico"),
    ("timeharp260", "th260=nano"),
    ("picoharp330", ""),
    ("picoharp", ""),
];

#[test]
fn acquisition_ptu_bins_back_into_the_same_stack_for_every_family() {
    for (family, board) in BOARDS {
        let dir = tempfile::tempdir().unwrap();
        let truth_file = dir.path().join("truth.json");
        let mock = format!("truth={},{board}", truth_file.display());
        let (out, o) = acquire(dir.path(), &format!("picoquant:{family}"), &mock, &[]);
        assert!(o.status.success(), "{family}: {}", text(&o));
        let record = json(&out.join("acquisition.json"));
        let t = truth(&truth_file);
        let ledger = &record["ledger"];
        assert_eq!(ledger["records"], t["records"], "{family}");
        assert_eq!(ledger["photons"], t["photons"], "{family}");
        assert_eq!(ledger["recordings"][0]["records"], t["records"], "{family}");
        assert!(t["photons"].as_u64().unwrap() > 100_000, "{family}: {t}");
        assert_eq!(record["stop"], "duration");
        let binned = out.join("binned");
        let b = command::scatterscope()
            .args(["bin", out.join("acquisition.ptu").to_str().unwrap()])
            .args(["--out", binned.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(b.status.success(), "{}", text(&b));
        let live = Stack::load(&out.join("stack.exr")).unwrap();
        let again = Stack::load(&binned.join("stack.exr")).unwrap();
        assert_eq!(live.data.dim(), again.data.dim(), "{family}");
        assert_eq!(live.data, again.data, "{family}: bin for bin");
        assert_eq!(
            live.data.sum() as u64,
            ledger["binned"].as_u64().unwrap(),
            "{family}"
        );
    }
}

#[test]
fn every_fault_mode_ends_the_run_with_the_ledger_balanced_and_the_stack_saved() {
    let cases = [
        ("overrun", "FIFO overrun", "fifo_overrun"),
        ("error", "ERROR_USB_BULKRD_FAIL", "device_error"),
        ("vanish", "ERROR_USB_VCMD_FAIL", "device_error"),
    ];
    for (fault, words, stop) in cases {
        let dir = tempfile::tempdir().unwrap();
        let truth_file = dir.path().join("truth.json");
        let mock = format!(
            "rate=max,fault={fault}@300000,truth={}",
            truth_file.display()
        );
        let (out, o) = acquire(dir.path(), "picoquant", &mock, &[]);
        let all = text(&o);
        assert!(!o.status.success(), "{fault}: a fault is a failure: {all}");
        assert!(all.contains(words), "{fault}: {all}");
        let record = json(&out.join("acquisition.json"));
        let stop_value = &record["stop"];
        let stop_name = stop_value.as_str().map(String::from).unwrap_or_else(|| {
            stop_value
                .as_object()
                .unwrap()
                .keys()
                .next()
                .unwrap()
                .clone()
        });
        assert_eq!(stop_name, stop, "{fault}");
        let t = truth(&truth_file);
        let ledger = &record["ledger"];
        assert_eq!(t["records"], 300_000, "{fault}: the stand-in delivered");
        assert_eq!(ledger["records"], t["records"], "{fault}");
        assert_eq!(ledger["records"], t["records"], "{fault}");
        assert_eq!(ledger["photons"], t["photons"], "{fault}");
        assert_eq!(ledger["recordings"][0]["records"], t["records"], "{fault}");
        let photons = ledger["photons"].as_u64().unwrap();
        let placed: u64 = [
            "binned",
            "outside_window",
            "other_channel",
            "outside_region",
        ]
        .iter()
        .map(|k| ledger[*k].as_u64().unwrap())
        .sum();
        assert_eq!(placed, photons, "{fault}: every photon in one place");
        assert_eq!(ledger["fifo_overrun"], fault == "overrun");
        let stack = Stack::load(&out.join("stack.exr")).unwrap();
        assert_eq!(stack.data.sum() as u64, ledger["binned"].as_u64().unwrap());
        assert_eq!(ptu_tags(&out.join("acquisition.ptu")).len() as u64, {
            // Tags decoded from the PTU: photons and markers (overflows
            // carry none).
            photons + ledger["markers"].as_u64().unwrap()
        });
    }
}

/// A scanner's frames are drawn anew (Poisson), and with a drift the
/// scene moves: the stand-in no longer repeats one frame bit for bit, so
/// what depends on frames is tested.
#[test]
fn a_scans_frames_differ_and_a_drift_moves_the_image() {
    use scatterscope::tags::bin_file::{BinSpec, bin_file};
    use scatterscope::tags::binning::FrameSelect;
    let dir = tempfile::tempdir().unwrap();
    let (out, o) = acquire(
        dir.path(),
        "picoquant:multiharp",
        "scan=16x12,drift=1,rate=2e7",
        &["--scan", "16x12", "--duration", "100ms"],
    );
    assert!(o.status.success(), "{}", text(&o));
    let binned = bin_file(
        &out.join("acquisition.ptu"),
        &BinSpec {
            frames: FrameSelect::All,
            ..BinSpec::default()
        },
    )
    .unwrap();
    let frames: Vec<ndarray::Array2<f32>> = binned
        .stacks
        .iter()
        .map(|s| s.data.sum_axis(ndarray::Axis(0)))
        .collect();
    assert!(frames.len() >= 4, "{} frames", frames.len());
    for pair in frames.windows(2) {
        assert_ne!(pair[0], pair[1], "two frames identical count for count");
    }
    // The bright bar (a fifth of the way across) moves one point a frame.
    let centroid = |f: &ndarray::Array2<f32>| {
        let (mut sx, mut n) = (0.0f64, 0.0f64);
        for ((_, x), &c) in f.indexed_iter() {
            sx += x as f64 * f64::from(c);
            n += f64::from(c);
        }
        sx / n
    };
    let (c0, c3) = (centroid(&frames[0]), centroid(&frames[3]));
    assert!(c3 > c0 + 1.5, "centroid {c0} then {c3}");
}

#[test]
fn a_scanned_acquisition_bins_into_the_scanners_image() {
    let dir = tempfile::tempdir().unwrap();
    let truth_file = dir.path().join("truth.json");
    let mock = format!("scan=16x12,truth={}", truth_file.display());
    let (out, o) = acquire(
        dir.path(),
        "picoquant:hydraharp",
        &mock,
        &["--scan", "16x12", "--bins", "200", "--bin-width", "8ps"],
    );
    assert!(o.status.success(), "{}", text(&o));
    let t = truth(&truth_file);
    // Set, not left to the library's defaults: the markers' edges (rising
    // unless --marker-edge says) and every input enabled.
    assert_eq!(t["marker_edges"], serde_json::json!([1, 1, 1, 1]), "{t}");
    assert_eq!(
        t["inputs_enabled"],
        serde_json::json!([true, true, true, true]),
        "{t}"
    );
    let expected: Vec<u64> = t["pixel_photons"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    assert_eq!(expected.len(), 16 * 12);
    let stack = Stack::load(&out.join("stack.exr")).unwrap();
    assert_eq!(stack.data.dim().1, 12, "rows are lines");
    assert_eq!(stack.data.dim().2, 16, "columns are points of a line");
    let record = json(&out.join("acquisition.json"));
    assert_eq!(
        record["ledger"]["outside_window"], 0,
        "the window holds every photon"
    );
    assert_eq!(
        record["ledger"]["outside_region"], 0,
        "the scan ends on whole frames"
    );
    for y in 0..12 {
        for x in 0..16 {
            let got = stack.data.slice(ndarray::s![.., y, x]).sum() as u64;
            assert_eq!(got, expected[y * 16 + x], "pixel ({x}, {y})");
        }
    }
    assert!(
        expected.iter().max() > expected.iter().min(),
        "the scene has structure"
    );
}

#[test]
fn without_a_vendor_library_the_message_names_the_files_and_the_install() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("acq");
    // Empty variables are unset, not paths: the installer's places are
    // searched, as without them.
    let o = command::scatterscope()
        .args(["acquire", "--device", "picoquant", "--duration", "100ms"])
        .args(["--out", out.to_str().unwrap()])
        .env("SCATTERSCOPE_MHLIB", "")
        .env("SCATTERSCOPE_HHLIB", "")
        .output()
        .unwrap();
    let all = text(&o);
    assert!(!o.status.success(), "{all}");
    for words in ["libmh150.so", "libhh400.so", "install", "--vendor-lib"] {
        assert!(all.contains(words), "`{words}` missing: {all}");
    }
    assert!(!out.join("stack.exr").exists());
    let d = command::scatterscope()
        .args(["devices", "--picoquant"])
        .env_remove("SCATTERSCOPE_MHLIB")
        .env_remove("SCATTERSCOPE_HHLIB")
        .output()
        .unwrap();
    assert!(!d.status.success(), "{}", text(&d));
    assert!(
        text(&d).contains("/usr/local/lib64/mh150/mhlib.so"),
        "{}",
        text(&d)
    );
    let plain = command::scatterscope()
        .arg("devices")
        .env_remove("SCATTERSCOPE_MHLIB")
        .env_remove("SCATTERSCOPE_HHLIB")
        .output()
        .unwrap();
    assert!(
        plain.status.success(),
        "plain `devices` still lists the rest"
    );
    assert!(text(&plain).contains("mock-serial"));
}

#[test]
fn devices_lists_the_standin_devices() {
    let lib = standin_library();
    let o = scatterscope_pq(
        &["devices", "--json", "--vendor-lib", lib.to_str().unwrap()],
        "devices=2",
    );
    assert!(o.status.success(), "{}", text(&o));
    let list: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let addresses: Vec<&str> = list
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["address"].as_str().unwrap())
        .collect();
    assert!(
        addresses.contains(&"picoquant:multiharp:1000001"),
        "{addresses:?}"
    );
    assert!(
        addresses.contains(&"picoquant:multiharp:1000002"),
        "{addresses:?}"
    );
}

#[test]
fn settings_of_the_other_family_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let (_, o) = acquire(
        dir.path(),
        "picoquant:hydraharp",
        "",
        &["--sync-edge", "rising"],
    );
    assert!(!o.status.success());
    assert!(text(&o).contains("--sync-edge"), "{}", text(&o));
    let (_, o) = acquire(
        dir.path(),
        "picoquant:multiharp",
        "",
        &["--input-level", "-5000"],
    );
    assert!(!o.status.success());
    assert!(text(&o).contains("-5000 mV"), "{}", text(&o));
}

#[test]
fn an_unwritable_ptu_is_refused_before_the_device_is_touched() {
    for (target, words) in [
        // A device is never renamed over: outputs go to regular files.
        ("/dev/full", "not a regular file"),
        (
            "/nonexistent/dir/a.ptu",
            "its folder /nonexistent/dir does not exist",
        ),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let (out, o) = acquire(dir.path(), "picoquant", "", &["--ptu", target]);
        let all = text(&o);
        assert_eq!(o.status.code(), Some(1), "{target}: {all}");
        assert!(
            all.contains(words) && all.contains(target) && all.contains("hint: --ptu"),
            "{target}: {all}"
        );
        // Nothing acquired, nothing written.
        assert!(!all.contains("ended:"), "{target}: {all}");
        assert!(!out.exists(), "{target}");
    }
}

/// Photons, markers and syncs of a PicoQuant file, as (kind, channel or
/// bits, macro time, micro time).
fn tag_tuples(tags: &[Tag]) -> Vec<(u8, u16, u64, u32)> {
    tags.iter()
        .map(|t| match *t {
            Tag::Photon {
                channel,
                macro_time,
                micro_time,
            } => (0, channel, macro_time, micro_time),
            Tag::Marker { bits, macro_time } => (1, u16::from(bits), macro_time, 0),
            Tag::Sync { macro_time } => (2, 0, macro_time, 0),
        })
        .collect()
}

#[test]
fn a_mock_tag_file_converts_to_ptu_photon_for_photon() {
    let dir = tempfile::tempdir().unwrap();
    let tags = dir.path().join("m.sstags");
    let ptu = dir.path().join("m.ptu");
    let run = |args: &[&str]| {
        let o = command::scatterscope().args(args).output().unwrap();
        assert!(o.status.success(), "{args:?}: {}", text(&o));
        o
    };
    run(&[
        "acquire",
        "--size",
        "7",
        "--duration",
        "300ms",
        "--tags",
        tags.to_str().unwrap(),
        "--out",
        dir.path().join("acq").to_str().unwrap(),
    ]);
    run(&[
        "convert",
        tags.to_str().unwrap(),
        "--out",
        ptu.to_str().unwrap(),
    ]);
    let mut from_tags = Vec::new();
    TagFile::open(&tags)
        .unwrap()
        .read(|batch| {
            for e in batch.events() {
                match e.unwrap() {
                    firmware_protocol::Event::Photon { pixel, micro, sync } => {
                        from_tags.push((0u8, pixel, sync, micro))
                    }
                    firmware_protocol::Event::Marker { bits, sync } => {
                        from_tags.push((1, u16::from(bits), sync, 0))
                    }
                    firmware_protocol::Event::Lost { .. } => {}
                }
            }
        })
        .unwrap();
    let from_ptu = tag_tuples(&ptu_tags(&ptu));
    assert!(from_tags.len() > 10_000, "{}", from_tags.len());
    assert_eq!(from_ptu, from_tags);
    // A sensor too large for T3 channels is refused, naming why.
    let big = dir.path().join("big.sstags");
    run(&[
        "acquire",
        "--duration",
        "100ms",
        "--tags",
        big.to_str().unwrap(),
        "--out",
        dir.path().join("acq2").to_str().unwrap(),
    ]);
    let o = command::scatterscope()
        .args(["convert", big.to_str().unwrap(), "--out"])
        .arg(dir.path().join("big.ptu"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(text(&o).contains("63 input channels"), "{}", text(&o));
}

#[test]
#[ignore = "needs ../shared/data/picoquant-sample-data"]
fn the_shared_picoquant_samples_convert_to_ptu_photon_for_photon() {
    let dir = tempfile::tempdir().unwrap();
    for rel in [
        "hydraharp/v10_t3.ptu",
        "hydraharp/v20.ht3",
        "hydraharp/v20_t2.ptu",
        "hydraharp/v20_t3.ptu",
        "picoharp/v30_t2.ptu",
    ] {
        let input = shared_data::shared_data(&format!("picoquant-sample-data/{rel}"));
        let out = dir.path().join(format!("{}.ptu", rel.replace('/', "_")));
        let c = scatterscope::tags::recorded::convert_to_ptu(
            &input,
            &out,
            false,
            &Default::default(),
            &Default::default(),
        )
        .unwrap();
        let (a, b) = (ptu_tags(&input), ptu_tags(&out));
        assert!(!a.is_empty(), "{rel}");
        assert_eq!(tag_tuples(&a), tag_tuples(&b), "{rel}");
        assert_eq!(c.photons + c.markers + c.syncs, a.len() as u64, "{rel}");
        let (ia, _) = open(&input).unwrap();
        let (ib, _) = open(&out).unwrap();
        assert_eq!(ia.record_type, ib.record_type, "{rel}");
        assert_eq!(ia.resolution_s, ib.resolution_s, "{rel}");
        // Every header tag of a PTU input is kept, name, index, type and
        // value byte for byte, but the ones the conversion must change.
        if rel.ends_with(".ptu") {
            let changed = |i: &str| {
                ["TTResult_NumberOfRecords", "Header_End"].contains(&i)
                    || i == scatterscope::tags::convert::PROVENANCE_TAG
                    || i == scatterscope::formats::picoquant::writer::INCOMPLETE_TAG
            };
            let kept = |tags: &[scatterscope::formats::picoquant::ptu::HeaderTag]| {
                tags.iter()
                    .filter(|t| !changed(&t.ident))
                    .map(|t| t.raw.clone())
                    .collect::<Vec<_>>()
            };
            assert_eq!(kept(&ia.tags), kept(&ib.tags), "{rel}: header tags");
            assert!(ia.tags.len() > 20, "{rel}");
            use scatterscope::formats::picoquant::ptu::TagLookup;
            assert!(
                ib.tags
                    .text(scatterscope::tags::convert::PROVENANCE_TAG)
                    .is_some_and(|p| p.contains(rel.rsplit('/').next().unwrap())),
                "{rel}"
            );
        }
    }
}

#[test]
#[ignore = "needs ptufile and numpy under target/pydeps (scripts/fetch_python_deps.sh)"]
fn ptufile_decodes_the_acquisitions_records_and_histogram() {
    for (family, board) in BOARDS {
        let dir = tempfile::tempdir().unwrap();
        let (out, o) = acquire(dir.path(), &format!("picoquant:{family}"), board, &[]);
        assert!(o.status.success(), "{}", text(&o));
        let ptu = out.join("acquisition.ptu");
        let script = r#"
import json, sys
import numpy as np
import ptufile
with ptufile.PtuFile(sys.argv[1]) as p:
    rec = p.decode_records()
    photons = rec[rec['channel'] >= 0]
    hist = np.bincount(photons['dtime'].astype(np.int64))
    print(json.dumps({"records": int(p.number_records),
                      "photons": int(len(photons)),
                      "channels": sorted(set(photons['channel'].tolist())),
                      "resolution": float(p.tcspc_resolution),
                      "hist": hist.tolist()}))
"#;
        let py = pydeps::python(script, &[&ptu]);
        let got: serde_json::Value = serde_json::from_str(&py).unwrap();
        let record = json(&out.join("acquisition.json"));
        assert_eq!(got["records"], record["ledger"]["records"], "{family}");
        assert_eq!(got["photons"], record["ledger"]["photons"], "{family}");
        // The detector is on the first input: channel 0 for ptufile in
        // every record type (a PicoHarp T3 record's routing channel 1).
        assert_eq!(got["channels"], serde_json::json!([0]), "{family}");
        let res_ps = record["resolution_ps"].as_f64().unwrap();
        assert!((got["resolution"].as_f64().unwrap() * 1e12 - res_ps).abs() < 1e-6);
        // Our stack: one bin per micro-time unit over the sync period.
        let stack = Stack::load(&out.join("stack.exr")).unwrap();
        let ours: Vec<u64> = stack.data.iter().map(|&v| v as u64).collect();
        let theirs: Vec<u64> = got["hist"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        assert!(theirs.len() <= ours.len(), "{family}");
        assert_eq!(&ours[..theirs.len()], &theirs[..], "{family}: bin for bin");
        assert!(ours[theirs.len()..].iter().all(|&v| v == 0), "{family}");
    }
}

#[test]
fn ctrl_c_ends_a_picoquant_run_with_everything_read_saved() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("acq");
    let truth_file = dir.path().join("truth.json");
    let lib = standin_library();
    let child = command::scatterscope()
        .args(["acquire", "--device", "picoquant", "--duration", "0"])
        .args(["--vendor-lib", lib.to_str().unwrap()])
        .args(["--out", out.to_str().unwrap()])
        .env(
            "SCATTERSCOPE_PQ_MOCK",
            format!("truth={}", truth_file.display()),
        )
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The PTU is started once the device is set up, right before Start.
    let ptu = out.join("acquisition.ptu");
    command::wait_for_recording(&ptu);
    std::thread::sleep(std::time::Duration::from_millis(500));
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGINT,
    )
    .unwrap();
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    let record = json(&out.join("acquisition.json"));
    assert_eq!(record["stop"], "interrupted");
    let t = truth(&truth_file);
    assert_eq!(record["ledger"]["records"], t["records"]);
    assert_eq!(record["ledger"]["recordings"][0]["records"], t["records"]);
    assert!(t["records"].as_u64().unwrap() > 100_000, "{t}");
    let (info, _) = open(&ptu).unwrap();
    assert_eq!(info.records_announced, t["records"].as_u64().unwrap());
}

/// The T3 offset in the unit the vendor's libraries take: nanoseconds
/// (MHLib's header, mhdefin.h: `MH_SetOffset` 0 to 100 000 000 ns). The
/// stand-in records what it was sent; the PTU's `MeasDesc_Offset` holds
/// the same number.
#[test]
fn the_t3_offset_reaches_the_library_in_nanoseconds() {
    use scatterscope::formats::picoquant::ptu::TagLookup;
    for family in ["multiharp", "hydraharp", "picoharp330"] {
        let dir = tempfile::tempdir().unwrap();
        let truth_file = dir.path().join("truth.json");
        let mock = format!("truth={}", truth_file.display());
        let (out, o) = acquire(
            dir.path(),
            &format!("picoquant:{family}"),
            &mock,
            &["--offset", "10ns"],
        );
        assert!(o.status.success(), "{family}: {}", text(&o));
        assert!(
            text(&o).contains("note: acquire's --offset is now --t3-offset"),
            "the old name works, with a note: {}",
            text(&o)
        );
        assert_eq!(truth(&truth_file)["offset_ns"], 10, "{family}");
        let (info, _) = open(&out.join("acquisition.ptu")).unwrap();
        assert_eq!(info.tags.int("MeasDesc_Offset"), Some(10), "{family}");
        // A bare number is picoseconds, not a whole number of ns: refused.
        let (_, o) = acquire(
            dir.path(),
            &format!("picoquant:{family}"),
            &mock,
            &["--t3-offset", "10"],
        );
        assert!(!o.status.success());
        assert!(text(&o).contains("whole nanoseconds"), "{}", text(&o));
        // Past the library's range: refused by name with the library's
        // error code and text, or for a HydraHarp, whose header bounds it
        // lower, before the library is asked.
        let (_, o) = acquire(
            dir.path(),
            &format!("picoquant:{family}"),
            &mock,
            &["--t3-offset", "200000000ns"],
        );
        assert!(!o.status.success());
        let words = match family {
            "hydraharp" => "0 to 500 000 (hhdefin.h OFFSETMAX)",
            _ => "T3 offset 200000000 ns: the",
        };
        assert!(text(&o).contains(words), "{}", text(&o));
        if family != "hydraharp" {
            assert!(
                text(&o).contains("library refused it") && text(&o).contains("error -17"),
                "{}",
                text(&o)
            );
        }
        if family == "picoharp330" {
            // Its header bounds no binning code either: the library's
            // refusal, by name.
            let (_, o) = acquire(
                dir.path(),
                &format!("picoquant:{family}"),
                &mock,
                &["--binning", "40"],
            );
            assert!(!o.status.success());
            assert!(
                text(&o).contains("binning code 40 (bins of 2^40 base steps): the")
                    && text(&o).contains("refused it"),
                "{}",
                text(&o)
            );
        }
    }
}

/// MultiHarp's `FLAG_CNTS_DROPPED` (mhdefin.h, 0x0040): the stand-in sets
/// it mid-run (fault `drop`); the ledger says so, the summary does not
/// claim the run whole, and the command fails with what was read saved.
#[test]
fn counts_dropped_in_the_device_reach_the_ledger_and_the_summary() {
    let dir = tempfile::tempdir().unwrap();
    let (out, o) = acquire(
        dir.path(),
        "picoquant:multiharp",
        "rate=max,fault=drop@200000",
        &[],
    );
    // A TimeHarp 260 says it with another bit (th260defin.h
    // `FLAG_EVTS_DROPPED` 0x0008, the others' reference-clock flag).
    let (_, th) = acquire(
        dir.path(),
        "picoquant:timeharp260",
        "rate=max,fault=drop@200000",
        &[],
    );
    let t = text(&th);
    assert!(!th.status.success(), "{t}");
    assert!(t.contains("counts dropped in the device"), "{t}");
    assert!(!t.contains("reference clock lost"), "{t}");
    let all = text(&o);
    assert!(!o.status.success(), "{all}");
    assert!(all.contains("counts dropped in the device"), "{all}");
    assert!(all.contains("not the whole measurement"), "{all}");
    assert!(
        !all.contains("balance: every record read is accounted for\n"),
        "{all}"
    );
    let record = json(&out.join("acquisition.json"));
    assert_eq!(record["ledger"]["counts_dropped"], true, "{record}");
    assert!(out.join("stack.exr").exists() && out.join("acquisition.ptu").exists());
}

/// What a T3 file's header and records say of its sync: the rate, the
/// macro unit times the rate, the last sync times the macro unit against
/// the acquisition time, and the largest micro time in sync periods.
fn sync_facts(path: &Path) -> (f64, f64, f64, f64, f64) {
    use scatterscope::formats::picoquant::ptu::TagLookup;
    let (info, _) = open(path).unwrap();
    let rate = info.sync_rate_hz.unwrap();
    let (mut last_sync, mut max_micro) = (0u64, 0u32);
    for t in ptu_tags(path) {
        if let Tag::Photon {
            macro_time,
            micro_time,
            ..
        } = t
        {
            last_sync = last_sync.max(macro_time);
            max_micro = max_micro.max(micro_time);
        }
    }
    let acquisition_s = info.tags.float("MeasDesc_AcquisitionTime").unwrap() * 1e-3;
    (
        rate,
        info.macro_unit_s * rate,
        last_sync as f64 * info.macro_unit_s / acquisition_s,
        f64::from(max_micro) * info.resolution_s * rate,
        info.tags.int("HWSync_Divider").unwrap() as f64,
    )
}

/// With a sync divider, the stand-in's PTU says of its sync what
/// PicoQuant's own `v20_t3.ptu` (HydraHarp, divider 8) says: the rate at
/// the input before the divider (in the sample, the laser's own rate from
/// its driver's tags, 80 MHz / 16), the macro unit its inverse, syncs
/// counted in undivided periods up to the acquisition time, and micro
/// times within one undivided period.
#[test]
#[ignore = "needs ../shared/data/picoquant-sample-data"]
fn with_a_sync_divider_the_ptu_says_what_picoquants_own_file_says() {
    let sample = shared_data::shared_data("picoquant-sample-data/hydraharp/v20_t3.ptu");
    let (rate, unit, span, micro, divider) = sync_facts(&sample);
    assert_eq!((rate, divider), (4_999_960.0, 8.0));
    {
        use scatterscope::formats::picoquant::ptu::TagLookup;
        let (info, _) = open(&sample).unwrap();
        let laser = info.tags.float("Sep2_SOM_100_BaseOscFreq").unwrap()
            / info.tags.float("Sep2_SOM_100_Divider").unwrap();
        assert!(
            (rate / laser - 1.0).abs() < 1e-4,
            "{rate} against the laser's {laser}"
        );
    }
    assert!((unit - 1.0).abs() < 1e-9, "{unit}");
    assert!((span - 1.0).abs() < 0.01, "{span}");
    assert!(micro <= 1.0, "{micro}");

    let dir = tempfile::tempdir().unwrap();
    let (out, o) = acquire(
        dir.path(),
        "picoquant:hydraharp",
        "sync=5e6",
        &["--sync-divider", "8"],
    );
    assert!(o.status.success(), "{}", text(&o));
    let (rate, unit, span, micro, divider) = sync_facts(&out.join("acquisition.ptu"));
    assert_eq!((rate, divider), (5e6, 8.0));
    assert!((unit - 1.0).abs() < 1e-9, "{unit}");
    assert!((span - 1.0).abs() < 0.01, "{span}");
    assert!(micro <= 1.0, "{micro}");
}

/// The count rates are read from the library during the run (about every
/// 100 ms) and kept in the acquisition's record.
#[test]
fn count_rates_are_read_during_the_run_at_5_hz_or_more() {
    let dir = tempfile::tempdir().unwrap();
    let (out, o) = acquire(dir.path(), "picoquant:multiharp", "", &["--duration", "1s"]);
    assert!(o.status.success(), "{}", text(&o));
    let record = json(&out.join("acquisition.json"));
    let samples = record["rates_during_run"].as_array().unwrap();
    assert!(samples.len() >= 5, "{} samples in 1 s", samples.len());
    let times: Vec<f64> = samples.iter().map(|s| s["t_s"].as_f64().unwrap()).collect();
    assert!(times.windows(2).all(|w| w[1] > w[0]), "{times:?}");
    for s in samples {
        let sync = record["sync_rate_hz"].as_f64().unwrap();
        assert!(
            (s["sync_hz"].as_f64().unwrap() - sync).abs() < 1e-6 * sync,
            "{s}"
        );
        assert_eq!(s["inputs"].as_array().unwrap().len(), 4, "{s}");
    }
}

/// What a PicoHarp 330 cannot take is refused by the setting's name
/// before a library is loaded or a device touched (the library named
/// here does not exist): a zero cross (this driver sets its inputs to
/// edge triggers, ph330lib.h's `PH330_SetInputTrgMode`), a trigger level
/// past ph330defin.h's 1500 mV, a sync divider past its `SYNCDIVMAX` 8
/// (which a MultiHarp takes: 16 in mhdefin.h) or not a power of two.
#[test]
fn a_picoharp_330_refuses_what_it_cannot_take_by_name_before_the_device() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-library.so");
    let cases: [(&[&str], &str); 4] = [
        (&["--sync-zero-cross", "10"], "sync_zero_cross_mv"),
        (&["--input-level", "-1600"], "-1500 to 1500 mV"),
        (&["--sync-divider", "16"], "divides the sync by 1 to 8"),
        (&["--sync-divider", "3"], "divides the sync by 1, 2, 4 or 8"),
    ];
    let out = dir.path().join("acq");
    for (extra, words) in cases {
        let mut args = vec![
            "acquire",
            "--device",
            "picoquant:picoharp330",
            "--vendor-lib",
            missing.to_str().unwrap(),
            "--duration",
            "300ms",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = scatterscope_pq(&args, "");
        let t = text(&o);
        assert!(!o.status.success(), "{t}");
        assert!(t.contains(words), "{extra:?}: {t}");
        assert!(
            !t.contains("no-such-library"),
            "refused before the library: {t}"
        );
    }
    // The same divider on a MultiHarp reaches its library.
    let (_, o) = acquire(
        dir.path(),
        "picoquant:multiharp",
        "",
        &["--sync-divider", "16"],
    );
    assert!(o.status.success(), "{}", text(&o));
    // A PicoHarp 330 whose features lack FEATURE_INPT_MODE (ph330defin.h):
    // its inputs' trigger mode is not set (the stand-in refuses the call
    // there, as such a device would), and the run goes through.
    let (_, o) = acquire(
        dir.path(),
        "picoquant:picoharp330",
        "ph330_input_modes=no",
        &[],
    );
    assert!(o.status.success(), "{}", text(&o));
}

/// Settings past the vendor's headers are refused by name before the
/// device: a TimeHarp 260's binning code past `MAXBINSTEPS` 22 less one
/// (th260defin.h), a HydraHarp's T3 offset past `OFFSETMAX` 500000
/// (hhdefin.h).
#[test]
fn settings_past_the_vendors_headers_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-library.so");
    let out = dir.path().join("acq");
    let cases: [(&str, &[&str], &str); 2] = [
        ("picoquant:timeharp260", &["--binning", "22"], "0 to 21"),
        (
            "picoquant:hydraharp",
            &["--t3-offset", "600000ns"],
            "0 to 500 000 (hhdefin.h OFFSETMAX)",
        ),
    ];
    for (device, extra, words) in cases {
        let mut args = vec![
            "acquire",
            "--device",
            device,
            "--vendor-lib",
            missing.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = scatterscope_pq(&args, "");
        let t = text(&o);
        assert!(!o.status.success(), "{extra:?}: {t}");
        assert!(t.contains(words), "{extra:?}: {t}");
        assert!(
            !t.contains("no-such-library"),
            "refused before the library: {t}"
        );
    }
}

/// A TimeHarp 260's library serves the Pico (CFDs) and the Nano (edge
/// triggers); `TH260_GetHardwareInfo` says which (th260defin.h's
/// `HWIDENT_PICO`, `HWIDENT_NANO`). The other board's setting is refused
/// by name before any setting reaches the device, the divider past its
/// `SYNCDIVMAX` 8 before the library is loaded, and each board's PTU has
/// its own record type.
#[test]
fn a_timeharp_260_is_driven_as_its_board_says() {
    use scatterscope::formats::picoquant::records::RecordType;
    let dir = tempfile::tempdir().unwrap();
    for (board, refused, words, record_type) in [
        (
            "th260=pico",
            ["--sync-edge", "rising"],
            "TimeHarp 260 Pico input has a CFD",
            RecordType::TimeHarp260PT3,
        ),
        (
            "th260=nano",
            ["--input-zero-cross=-10", "--input-level=-50"],
            "TimeHarp 260 Nano input is driven with an edge trigger",
            RecordType::TimeHarp260NT3,
        ),
    ] {
        let (_, o) = acquire(dir.path(), "picoquant:timeharp260", board, &refused);
        let t = text(&o);
        assert!(!o.status.success(), "{board}: {t}");
        assert!(t.contains(words), "{board}: {t}");
        let (out, o) = acquire(dir.path(), "picoquant:th260", board, &[]);
        assert!(o.status.success(), "{board}: {}", text(&o));
        let (info, _) = open(&out.join("acquisition.ptu")).unwrap();
        assert_eq!(info.record_type, record_type, "{board}");
        let model = if board.ends_with("nano") {
            "TimeHarp 260 N"
        } else {
            "TimeHarp 260 P"
        };
        assert_eq!(info.device, model);
    }
    let missing = dir.path().join("no-such-library.so");
    let out = dir.path().join("acq");
    let o = scatterscope_pq(
        &[
            "acquire",
            "--device",
            "picoquant:timeharp260",
            "--vendor-lib",
            missing.to_str().unwrap(),
            "--sync-divider",
            "16",
            "--out",
            out.to_str().unwrap(),
        ],
        "",
    );
    let t = text(&o);
    assert!(
        t.contains("divides the sync by 1 to 8") && !t.contains("no-such-library"),
        "{t}"
    );
}

/// A PicoHarp 300 through PHLib 3.0 as the vendor's phlib.h and phdefin.h
/// give it: PicoHarp T3 records (photons on routing channel 1, read as
/// input 0), one input beside the sync, the sync rate as count rate 0,
/// `PH_SetOffset` in picoseconds, `FLAG_FIFOFULL` 0x0003; what the family
/// cannot take (per-input offsets, an edge, CFD levels past 800 mV or zero
/// crosses past 20 mV, binning codes past `BINSTEPSMAX` 8, an offset past
/// 1e9 ps, a divider past 8) is refused by the setting's name before any
/// library is loaded.
#[test]
fn a_picoharp_300_is_driven_as_phlib_says() {
    use scatterscope::formats::picoquant::ptu::TagLookup;
    use scatterscope::formats::picoquant::records::RecordType;
    let dir = tempfile::tempdir().unwrap();
    let truth_file = dir.path().join("truth.json");
    let mock = format!("truth={}", truth_file.display());
    let (out, o) = acquire(
        dir.path(),
        "picoquant:picoharp",
        &mock,
        &[
            "--t3-offset",
            "10ns",
            "--duration",
            "600ms",
            "--binning",
            "1",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let t = truth(&truth_file);
    assert_eq!(t["offset_ps"], 10_000, "{t}");
    let (info, _) = open(&out.join("acquisition.ptu")).unwrap();
    assert_eq!(info.record_type, RecordType::PicoHarpT3);
    assert_eq!(info.device, "PicoHarp 300");
    assert_eq!(info.tags.int("MeasDesc_Offset"), Some(10));
    assert_eq!(
        info.tags.int("HW_InpChannels"),
        Some(2),
        "sync and one input"
    );
    assert!((info.resolution_s - 8e-12).abs() < 1e-18, "4 ps x 2^1");
    assert!(
        ptu_tags(&out.join("acquisition.ptu"))
            .iter()
            .all(|t| matches!(t, Tag::Photon { channel: 0, .. })),
        "every photon on input 0"
    );
    let record = json(&out.join("acquisition.json"));
    assert_eq!(record["sync_rate_hz"], 80e6, "count rate 0 is the sync's");
    for s in record["rates_during_run"].as_array().unwrap() {
        assert_eq!(s["inputs"].as_array().unwrap().len(), 1, "{s}");
    }
    assert_eq!(record["ledger"]["photons"], t["photons"]);

    // FLAG_FIFOFULL is 0x0003 in phdefin.h.
    let (out, o) = acquire(
        dir.path(),
        "picoquant:picoharp",
        "rate=max,fault=overrun@300000",
        &[],
    );
    assert!(!o.status.success(), "{}", text(&o));
    assert_eq!(json(&out.join("acquisition.json"))["stop"], "fifo_overrun");

    let missing = dir.path().join("no-such-library.so");
    let cases: [(&[&str], &str); 9] = [
        (&["--input-offsets", "0,120ps"], "a PicoHarp 300 has none"),
        (&["--sync-divider", "2"], "before or after the divider"),
        (&["--duration", "597h"], "at most 100 h (ACQTMAX"),
        (&["--sync-edge", "rising"], "PicoHarp 300 input has a CFD"),
        (&["--input-level", "900"], "levels 0 to 800 mV"),
        (&["--sync-zero-cross", "30"], "zero crosses 0 to 20 mV"),
        (&["--binning", "8"], "takes 0 to 7"),
        (&["--t3-offset", "2000000ns"], "0 to 1 000 000 ns"),
        (&["--sync-divider", "16"], "divides the sync by 1 to 8"),
    ];
    let out = dir.path().join("refused");
    for (extra, words) in cases {
        let mut args = vec![
            "acquire",
            "--device",
            "picoquant:ph300",
            "--vendor-lib",
            missing.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = scatterscope_pq(&args, "");
        let t = text(&o);
        assert!(!o.status.success(), "{extra:?}: {t}");
        assert!(t.contains(words), "{extra:?}: {t}");
        assert!(
            !t.contains("no-such-library"),
            "refused before the library: {t}"
        );
    }
}
