//! Becker & Hickl files through `info`, `bin`, `convert` and Python's
//! reader, judged by independent readers: tttrlib decodes the `.spc`
//! files photon for photon as we do, sdtfile reads the `.sdt` files block
//! for block as we bin them. The files are made from B&H's documented
//! layouts (tests/common/bh_files.rs): every module family, every flag, a
//! cut tail, a zipped block and blocks that are not decay curves.

#[path = "common/bh_files.rs"]
mod bh_files;
#[path = "common/command.rs"]
mod command;
#[path = "common/ptu_tags.rs"]
mod ptu_tags;
#[path = "common/pydeps.rs"]
mod pydeps;

use std::path::Path;

use bh_files::{Layout, SdtBlock, SdtMeasurement, random_spc, sdt_file};
use command::{run, text};
use ptu_tags::ptu_tags;
use scatterscope::events::Tag;
use scatterscope::formats::becker_hickl::spc::{self, SpcModule, SpcOptions};
use scatterscope::stack::{Stack, Unstated};
use scatterscope::tags::bin_file::{BinSpec, Pixels, bin_file_counts};

const LAYOUTS: [(Layout, SpcModule); 3] = [
    (Layout::Spc130, SpcModule::Spc130),
    (Layout::Spc600_256, SpcModule::Spc600Channels256),
    (Layout::Spc600_4096, SpcModule::Spc600Channels4096),
];

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The setup file SPCM saves beside a `.spc`: TAC range 50 ns, gain 4.
fn write_set(spc: &Path) {
    std::fs::write(
        spc.with_extension("set"),
        b"*IDENTIFICATION\r\n  ID : SPC Setup Script File\r\n*END\r\n*SETUP\r\nSYS_PARA_BEGIN:\r\n#SP [SP_TAC_R,F,5.0e-08]\r\n#SP [SP_TAC_G,I,4]\r\n#SP [SP_ADC_RE,I,4096]\r\nSYS_PARA_END:\r\n*END\r\n",
    )
    .unwrap();
}

/// Photons as (channel, macro time, micro time), markers as (bits, macro
/// time), and the flags counted.
type Decoded = (Vec<(u16, u64, u32)>, Vec<(u8, u64)>, spc::CardFlags);

/// Every photon and marker our reader decodes, with the flags it counted.
fn ours(path: &Path, module: SpcModule) -> Decoded {
    let options = SpcOptions {
        module: Some(module),
        micro_unit_ps: Some(10.0),
    };
    let info = spc::open(path, &options).unwrap();
    let (mut photons, mut markers) = (Vec::new(), Vec::new());
    let reader = info.records_part(0, 1).unwrap();
    let flags = spc::decode_each(&info, reader, |tag| {
        match tag {
            Some(Tag::Photon {
                channel,
                macro_time,
                micro_time,
            }) => photons.push((channel, macro_time, micro_time)),
            Some(Tag::Marker { bits, macro_time }) => markers.push((bits, macro_time)),
            _ => {}
        }
        Ok::<(), spc::SpcFileError>(())
    })
    .unwrap();
    (photons, markers, flags)
}

#[test]
fn spc_files_bin_with_an_honest_ledger() {
    let dir = tempfile::tempdir().unwrap();
    for (layout, module) in LAYOUTS {
        let path = dir.path().join(format!("{}.spc", layout.ours()));
        std::fs::write(&path, random_spc(layout, 20_000, 2, 7)).unwrap();
        write_set(&path);
        let (photons, markers, flags) = ours(&path, module);
        let spec = BinSpec {
            pixels: Pixels::Channel,
            spc: SpcOptions {
                module: Some(module),
                micro_unit_ps: None,
            },
            ..BinSpec::default()
        };
        let binned = bin_file_counts(&path, &spec).unwrap();
        let acc = binned.counts;
        assert!(acc.balances(), "{acc:?}");
        assert_eq!(acc.records, 20_000, "{layout:?}");
        assert_eq!(acc.photons, photons.len() as u64);
        assert_eq!(
            acc.binned,
            photons.len() as u64,
            "every micro time is in the ADC's range"
        );
        assert_eq!(acc.markers, markers.len() as u64);
        // The stack is the histogram of (micro time, channel).
        let stack = &binned.stacks[0].counts;
        let channels = module.adc_channels() as usize;
        assert_eq!(
            stack.dim().0,
            channels,
            "{layout:?}: one bin per ADC channel"
        );
        let mut expected = ndarray::Array3::<u32>::zeros(stack.dim());
        for &(c, _, m) in &photons {
            expected[[m as usize, 0, c as usize]] += 1;
        }
        assert_eq!(stack, &expected, "{layout:?}");
        // The micro-time unit from the .set: 50 ns / 4 / channels.
        let unit_ps = 50_000.0 / 4.0 / channels as f64;
        assert!(
            (binned.resolution_ps - unit_ps).abs() < 1e-9,
            "{}",
            binned.resolution_ps
        );
        let summary = binned.summary().join("\n");
        assert!(
            summary.contains(&format!("{} INVALID records dropped", flags.invalid)),
            "{summary}"
        );
        assert!(flags.invalid > 0 && flags.overflows > 0, "{flags:?}");
        if layout != Layout::Spc600_4096 {
            assert!(flags.overflow_entries > 0, "{flags:?}");
        }
        if flags.gaps > 0 {
            assert!(
                binned
                    .warnings()
                    .iter()
                    .any(|w| w.contains("GAP flag") && w.contains("lost in the card")),
                "{:?}",
                binned.warnings()
            );
        }
    }
}

#[test]
fn the_command_bins_converts_and_refuses_spc_files_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.spc");
    std::fs::write(&path, random_spc(Layout::Spc130, 5_000, 1, 3)).unwrap();
    // No setup file and no unit: binned by ADC channel with a warning
    // (exit 4) naming both ways to give the unit, the stack marked so.
    let out = run(&["bin", s(&path), "--out", s(&dir.path().join("a"))]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(4), "{t}");
    assert!(
        t.contains("warning: the micro-time unit is unknown")
            && t.contains("run.set")
            && t.contains("--micro-unit")
            && t.contains("4096 x 1 x 1 (1-channel bins from channel 0; time unit unknown)"),
        "{t}"
    );
    let unitless = Stack::load(&dir.path().join("a/stack.exr")).unwrap();
    assert!(unitless.meta.is_unstated(Unstated::TimeUnit));
    assert_eq!(unitless.meta.bin_width_ps, 1.0);
    // A time window needs the unit; the reconstruction refuses the stack.
    let out = run(&[
        "bin",
        s(&path),
        "--bin-width",
        "8ps",
        "--out",
        s(&dir.path().join("a2")),
    ]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(t.contains("--bin-width and --t-start are times"), "{t}");
    let out = run(&[
        "reconstruct",
        s(&dir.path().join("a/stack.exr")),
        "--out",
        s(&dir.path().join("a3")),
    ]);
    let t = text(&out);
    assert_ne!(out.status.code(), Some(0), "{t}");
    assert!(t.contains("unknown time unit"), "{t}");
    // With the unit: binned; the layout assumed is said; GAP flags make
    // a warning (exit 4).
    let bin_at_12_5ps = |file: &Path, out: &str, more: &[&str]| {
        let out = dir.path().join(out);
        let args = [
            &["bin", s(file), "--micro-unit", "12.5ps", "--out", s(&out)],
            more,
        ];
        run(&args.concat())
    };
    let out = bin_at_12_5ps(&path, "b", &[]);
    let t = text(&out);
    assert!(matches!(out.status.code(), Some(0 | 4)), "{t}");
    assert!(
        t.contains("SPC-130/140/150/160/180/830") && t.contains("--spc-module"),
        "{t}"
    );
    assert!(dir.path().join("b/stack.exr").is_file(), "{t}");
    // The wrong layout: the 48-bit header is not there.
    let out = run(&[
        "info",
        s(&path),
        "--spc-module",
        "spc-600-4096",
        "--micro-unit",
        "3ps",
    ]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(
        t.contains("run.spc") && t.contains("--spc-module spc-130"),
        "{t}"
    );
    // A cut tail: refused, then binned when allowed, and said.
    let mut bytes = std::fs::read(&path).unwrap();
    bytes.extend([0x12, 0x34]);
    let cut = dir.path().join("cut.spc");
    std::fs::write(&cut, &bytes).unwrap();
    let out = bin_at_12_5ps(&cut, "c", &[]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(
        t.contains("cut.spc") && t.contains("file is cut") && t.contains("2 bytes"),
        "{t}"
    );
    let out = bin_at_12_5ps(&cut, "d", &["--allow-truncated"]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(4), "{t}");
    assert!(t.contains("warning: file is cut"), "{t}");
    // .spc options on a file of another kind: refused by name.
    let ptu = dir.path().join("x.ptu");
    let out = run(&[
        "convert",
        s(&path),
        "--micro-unit",
        "12.5ps",
        "--out",
        s(&ptu),
    ]);
    let t = text(&out);
    assert!(matches!(out.status.code(), Some(0 | 4)), "{t}");
    // Every reader that takes them refuses them alike, naming the file.
    let other = dir.path().join("y.ptu");
    for (command, out) in [("bin", s(&dir.path().join("e"))), ("convert", s(&other))] {
        let out = run(&[command, s(&ptu), "--spc-module", "spc-130", "--out", out]);
        let t = text(&out);
        assert_eq!(out.status.code(), Some(1), "{command}: {t}");
        assert!(
            t.contains(
                "x.ptu: the .spc module and micro-time unit apply to Becker & Hickl FIFO files"
            ),
            "{command}: {t}"
        );
    }
    assert!(!other.exists());
    let out = run(&["info", s(&ptu), "--micro-unit", "12.5ps"]);
    assert!(
        text(&out).contains("x.ptu: the .spc module"),
        "{}",
        text(&out)
    );
    // The PTU holds the same photons, routing channel as input channel.
    let (photons, markers, _) = ours(&path, SpcModule::Spc130);
    let (info, _) = scatterscope::formats::picoquant::open(&ptu).unwrap();
    assert!((info.resolution_s - 12.5e-12).abs() < 1e-18);
    assert!(
        (info.macro_unit_s - 50e-9).abs() < 1e-15,
        "{}",
        info.macro_unit_s
    );
    let (mut p, mut m) = (Vec::new(), Vec::new());
    for tag in ptu_tags(&ptu) {
        match tag {
            Tag::Photon {
                channel,
                macro_time,
                micro_time,
            } => p.push((channel, macro_time, micro_time)),
            Tag::Marker { bits, macro_time } => m.push((bits, macro_time)),
            Tag::Sync { .. } => {}
        }
    }
    assert_eq!(p, photons);
    assert_eq!(m, markers);
}

/// Three measurement blocks: 4 x 3 scans of 64 points (two), one single
/// curve of 32 points.
fn sdt_fixture() -> (Vec<u8>, Vec<Vec<f64>>) {
    let mut rng = bh_files::Rng(99);
    let mut curves = |n: usize| (0..n).map(|_| rng.below(3000) as f64).collect::<Vec<_>>();
    let (a, b, c, fcs) = (curves(12 * 64), curves(12 * 64), curves(32), curves(40));
    let measurements = [
        SdtMeasurement::spc150(12.5e-9, 1, 64, (4, 3)),
        SdtMeasurement::spc150(50e-9, 2, 32, (1, 1)),
    ];
    let blocks = [
        SdtBlock {
            values: a.clone(),
            item: 2,
            zipped: false,
            contents: 0x60,
            measurement: 0,
        },
        SdtBlock {
            values: fcs,
            item: 8,
            zipped: false,
            contents: 0x20,
            measurement: 1,
        },
        SdtBlock {
            values: b.clone(),
            item: 4,
            zipped: true,
            contents: 0x60,
            measurement: 0,
        },
        SdtBlock {
            values: c.clone(),
            item: 8,
            zipped: false,
            contents: 0x00,
            measurement: 1,
        },
    ];
    (sdt_file(&measurements, &blocks), vec![a, b, c])
}

#[test]
fn sdt_blocks_bin_as_stacks_and_what_is_left_out_is_said() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scan.sdt");
    let (bytes, blocks) = sdt_fixture();
    std::fs::write(&path, &bytes).unwrap();
    let binned = bin_file_counts(&path, &BinSpec::default()).unwrap();
    assert_eq!(
        binned.stacks.len(),
        3,
        "the two image blocks and the curve of another size and time unit"
    );
    for (stack, values) in binned.stacks.iter().zip(&blocks).take(2) {
        assert_eq!(stack.counts.dim(), (64, 3, 4));
        for ((k, y, x), &v) in stack.counts.indexed_iter() {
            assert_eq!(f64::from(v), values[(y * 4 + x) * 64 + k]);
        }
    }
    // The decay curve of another TAC setting is a stack of its own, in its
    // own time unit (50 ns / gain 2 / 32 points).
    let curve = &binned.stacks[2];
    assert_eq!(curve.counts.dim(), (32, 1, 1));
    assert_eq!(
        curve
            .counts
            .iter()
            .map(|&c| f64::from(c))
            .collect::<Vec<_>>(),
        blocks[2]
    );
    assert!((curve.meta.bin_width_ps - 50e3 / 2.0 / 32.0).abs() < 1e-6);
    assert!((binned.resolution_ps - 12.5e3 / 64.0).abs() < 1e-6);
    let acc = binned.counts;
    assert!(acc.balances());
    assert_eq!(acc.photons as f64, blocks.iter().flatten().sum::<f64>());
    let notes = binned.notes.join("\n");
    assert!(notes.contains("data block 1 (FCS block"), "{notes}");
    assert!(
        notes.contains("differ in size or time unit") && notes.contains("32 x 1 x 1 of 781.25 ps"),
        "{notes}"
    );
    // Two points a bin from point 8: the sums of pairs.
    let spec = BinSpec {
        bin_width_ps: Some(2.0 * 12.5e3 / 64.0),
        t_start_ps: 8.0 * 12.5e3 / 64.0,
        ..BinSpec::default()
    };
    let wide = bin_file_counts(&path, &spec).unwrap();
    // The curve of another unit has no whole number of points in such a
    // bin: left out, by name.
    assert_eq!(wide.stacks.len(), 2);
    assert!(
        wide.warnings()
            .iter()
            .any(|w| w.contains("data block 3") && w.contains("not a whole number")),
        "{:?}",
        wide.warnings()
    );
    let s0 = &wide.stacks[0].counts;
    assert_eq!(s0.dim(), (28, 3, 4));
    assert_eq!(
        f64::from(s0[[1, 2, 3]]),
        blocks[0][(2 * 4 + 3) * 64 + 10] + blocks[0][(2 * 4 + 3) * 64 + 11]
    );
    assert_eq!(wide.counts.outside_window as f64, {
        let first8 = |v: &Vec<f64>| {
            (0..12)
                .map(|c| v[c * 64..c * 64 + 8].iter().sum::<f64>())
                .sum::<f64>()
        };
        first8(&blocks[0]) + first8(&blocks[1])
    });
    // A width of a point and a half: refused by name.
    let spec = BinSpec {
        bin_width_ps: Some(1.5 * 12.5e3 / 64.0),
        ..BinSpec::default()
    };
    let e = bin_file_counts(&path, &spec).unwrap_err().to_string();
    assert!(e.contains("scan.sdt") && e.contains("whole number"), "{e}");
    // A cut file names the block that reaches past its end.
    let cut = dir.path().join("cut.sdt");
    std::fs::write(&cut, &bytes[..bytes.len() - 100]).unwrap();
    let e = bin_file_counts(&cut, &BinSpec::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cut.sdt") && e.contains("data block 3") && e.contains("cut"),
        "{e}"
    );
    // info lists every block and what is left out.
    let out = run(&["info", s(&path)]);
    let t = text(&out);
    assert!(out.status.success(), "{t}");
    assert!(
        t.contains("block 2 (number 3): IMG curves of 64 points as 3 x 4 pixels, u32 zipped"),
        "{t}"
    );
    assert!(t.contains("left out: data block 1 (FCS block"), "{t}");
}

/// An `.sdt` FLIM image as Bruker's Prairie View writes them for an
/// SPC-150 (the module name followed by bytes outside ASCII in its 16-byte
/// field, the date as MM:DD:YYYY), in a folder whose name is not ASCII:
/// binned and written, its metadata readable text, the names kept.
#[test]
fn a_prairie_view_sdt_in_a_folder_of_any_name_bins_and_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("Messungen-\u{fc}ber-\u{5149}");
    std::fs::create_dir(&folder).unwrap();
    let path = folder.join("TSeries-001_Cycle00001.sdt");
    let mut m = SdtMeasurement::spc150(12.5e-9, 1, 16, (3, 2));
    m.module = b"SPC-150\0\xC3\xA9\x8F\xFF\x01bh";
    m.date = b"11:05:2019";
    let values: Vec<f64> = (0..6 * 16).map(|i| (i % 7) as f64).collect();
    let block = SdtBlock {
        values: values.clone(),
        item: 2,
        zipped: true,
        contents: 0x60,
        measurement: 0,
    };
    std::fs::write(&path, sdt_file(&[m], &[block])).unwrap();
    let out = folder.join("b");
    let r = run(&["bin", s(&path), "--ome-tiff", "--out", s(&out)]);
    let t = text(&r);
    assert_eq!(r.status.code(), Some(0), "{t}");
    let back = Stack::load(&out.join("stack.exr")).unwrap();
    assert!(
        back.meta.source.contains("\u{5149}"),
        "{}",
        back.meta.source
    );
    assert!(
        back.meta.source.contains("module SPC-150)"),
        "{}",
        back.meta.source
    );
    assert_eq!(back.total(), values.iter().sum::<f64>());
    let r = run(&["info", s(&path)]);
    let t = text(&r);
    assert!(r.status.success(), "{t}");
    assert!(
        t.contains("module SPC-150;") && !t.contains('\u{fffd}'),
        "{t}"
    );
}

/// tttrlib's decoding of a `.spc` file as JSON: per event, its type (0
/// photon, 1 marker), routing channel (marker bits for markers), macro
/// and micro time.
const TTTRLIB: &str = r#"
import json, sys, tttrlib
t = tttrlib.TTTR(sys.argv[1], sys.argv[2])
print(json.dumps({
    "type": [int(v) for v in t.event_types],
    "channel": [int(v) & 0xFF for v in t.routing_channels],
    "macro": [int(v) for v in t.macro_times],
    "micro": [int(v) for v in t.micro_times],
}))
"#;

#[test]
#[ignore = "needs target/pydeps (scripts/fetch_python_deps.sh)"]
fn spc_files_decode_photon_for_photon_as_tttrlib_does() {
    let dir = tempfile::tempdir().unwrap();
    for (layout, module) in LAYOUTS {
        let path = dir.path().join(format!("{}.spc", layout.ours()));
        std::fs::write(&path, random_spc(layout, 30_000, 3, 11)).unwrap();
        let (photons, markers, _) = ours(&path, module);
        let t: serde_json::Value =
            serde_json::from_str(&pydeps::python(TTTRLIB, &[s(&path), layout.tttrlib()])).unwrap();
        let col = |k: &str| -> Vec<u64> {
            t[k].as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_u64().unwrap())
                .collect()
        };
        let (kind, channel, mt, micro) = (col("type"), col("channel"), col("macro"), col("micro"));
        let theirs: Vec<usize> = (0..kind.len()).filter(|&i| kind[i] == 0).collect();
        assert_eq!(theirs.len(), photons.len(), "{layout:?}: photons");
        for (&i, &(c, m, u)) in theirs.iter().zip(&photons) {
            assert_eq!(micro[i], u64::from(u), "{layout:?} photon {i}: micro time");
            match layout {
                // tttrlib 0.26.2 gives the 48-bit layout's routing byte
                // inverted (255 - R); B&H's header and libtcspc take it as
                // stored, as we do.
                Layout::Spc600_4096 => assert_eq!(channel[i], 255 - u64::from(c), "photon {i}"),
                _ => assert_eq!(channel[i], u64::from(c), "{layout:?} photon {i}: channel"),
            }
            // tttrlib 0.26.2's SPC-600/630 macro times differ from B&H's
            // header (an overflow period of 2^16, not 2^17; the 48-bit
            // layout's bytes 4-5 unread), where libtcspc agrees with us:
            // compared for the SPC-130 family only. Binning uses the
            // micro time and channel alone.
            if layout == Layout::Spc130 {
                assert_eq!(mt[i], m, "photon {i}: macro time");
            }
        }
        let their_markers: Vec<(u8, u64)> = (0..kind.len())
            .filter(|&i| kind[i] == 1)
            .map(|i| (channel[i] as u8, mt[i]))
            .collect();
        assert_eq!(their_markers, markers, "{layout:?}: markers");
    }
}

/// sdtfile's arrays of an `.sdt` file as JSON: per block, shape and
/// values (C order), and the time axis.
const SDTFILE: &str = r#"
import json, sys, sdtfile
f = sdtfile.SdtFile(sys.argv[1])
print(json.dumps([
    {"shape": list(d.shape), "values": d.astype("float64").ravel().tolist(), "dt": float(t[1] - t[0]) if len(t) > 1 else 0.0}
    for d, t in zip(f.data, f.times)
]))
"#;

#[test]
#[ignore = "needs target/pydeps (scripts/fetch_python_deps.sh)"]
fn sdt_files_bin_block_for_block_as_sdtfile_reads_them() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scan.sdt");
    std::fs::write(&path, sdt_fixture().0).unwrap();
    let theirs: serde_json::Value =
        serde_json::from_str(&pydeps::python(SDTFILE, &[s(&path)])).unwrap();
    let binned = bin_file_counts(&path, &BinSpec::default()).unwrap();
    // Blocks 0 and 2 are our stacks; sdtfile shapes them (rows, cols, points).
    for (stack, block) in binned.stacks.iter().zip([0, 2]) {
        let b = &theirs[block];
        assert_eq!(b["shape"], serde_json::json!([3, 4, 64]), "block {block}");
        let values: Vec<f64> = b["values"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        for ((k, y, x), &v) in stack.counts.indexed_iter() {
            assert_eq!(
                f64::from(v),
                values[(y * 4 + x) * 64 + k],
                "block {block} ({k}, {y}, {x})"
            );
        }
        let dt_ps = b["dt"].as_f64().unwrap() * 1e12;
        assert!(
            (dt_ps - stack.meta.bin_width_ps).abs() < 1e-3 * dt_ps,
            "{dt_ps} vs {}",
            stack.meta.bin_width_ps
        );
    }
    // The single decay curve we leave out (another size) is sdtfile's
    // block 3 too, 32 points.
    assert_eq!(theirs[3]["shape"], serde_json::json!([1, 1, 32]));
}

#[test]
fn a_batch_bins_becker_hickl_files_as_the_command_does() {
    let dir = tempfile::tempdir().unwrap();
    let spc = dir.path().join("run.spc");
    // Without GAP flags (byte 1 bit 6), whose warning would fail the job.
    let mut bytes = random_spc(Layout::Spc600_4096, 3_000, 4, 5);
    bytes.chunks_exact_mut(6).for_each(|r| r[1] &= !0x40);
    std::fs::write(&spc, bytes).unwrap();
    write_set(&spc);
    std::fs::write(dir.path().join("scan.sdt"), sdt_fixture().0).unwrap();
    let manifest = dir.path().join("jobs.toml");
    std::fs::write(
        &manifest,
        "[[job]]\nname = \"fifo\"\ncommand = \"bin\"\ninput = \"run.spc\"\nargs = [\"--spc-module\", \"spc-600-4096\", \"--no-preview\"]\n\n[[job]]\nname = \"histograms\"\ncommand = \"bin\"\ninput = \"scan.sdt\"\nargs = [\"--no-preview\"]\n\n[[job]]\nname = \"ptu\"\ncommand = \"convert\"\ninput = \"run.spc\"\nargs = [\"--spc-module\", \"spc-600-4096\"]\n",
    )
    .unwrap();
    let out = dir.path().join("out");
    let o = run(&["batch", s(&manifest), "--out", s(&out)]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let fifo = scatterscope::stack::Stack::load(&out.join("fifo/stack.exr")).unwrap();
    let direct = bin_file_counts(
        &spc,
        &BinSpec {
            spc: SpcOptions {
                module: Some(SpcModule::Spc600Channels4096),
                micro_unit_ps: None,
            },
            ..BinSpec::default()
        },
    )
    .unwrap();
    let counts = direct.stacks[0].counts.mapv(|c| c as f32);
    assert_eq!(fifo.data, counts);
    for f in ["stack_f000.exr", "stack_f001.exr", "stack_f002.exr"] {
        assert!(out.join("histograms").join(f).is_file(), "{f}: {t}");
    }
    // A conversion writes one file: the batch names it in the job's folder.
    let ptu = out.join("ptu/converted.ptu");
    let (info, _) = scatterscope::formats::picoquant::open(&ptu).unwrap();
    assert_eq!(info.records_present, info.records_announced, "{t}");
}

/// Found by fuzzing (fuzz/fuzz_targets/becker_hickl.rs): scan and image
/// sizes whose product overflows are sizes that match no block, not a
/// panic; the block's curves then form a row.
#[test]
fn sdt_sizes_whose_product_overflows_place_the_curves_in_a_row() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("huge.sdt");
    let measurements = [SdtMeasurement {
        repeats: (i32::MAX, i32::MAX),
        ..SdtMeasurement::spc150(12.5e-9, 1, 16, (i32::MAX, i32::MAX))
    }];
    let blocks = [SdtBlock {
        values: (0..48).map(f64::from).collect(),
        item: 2,
        zipped: false,
        contents: 0x00,
        measurement: 0,
    }];
    std::fs::write(&path, sdt_file(&measurements, &blocks)).unwrap();
    let binned = bin_file_counts(&path, &BinSpec::default()).unwrap();
    assert_eq!(binned.stacks[0].counts.dim(), (16, 1, 3));
    assert_eq!(binned.counts.photons, (0..48).sum::<u64>());
}

/// The error `bin` gives for a file `name` of one zipped block of 16
/// points, its bytes changed by `damage` (given them and the offset of
/// the block's header).
fn error_of_a_damaged_zipped_block(name: &str, damage: impl FnOnce(&mut [u8], usize)) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    let measurements = [SdtMeasurement::spc150(12.5e-9, 1, 16, (1, 1))];
    let blocks = [SdtBlock {
        values: vec![1.0; 16],
        item: 2,
        zipped: true,
        contents: 0x00,
        measurement: 0,
    }];
    let mut bytes = sdt_file(&measurements, &blocks);
    let header = u32::from_le_bytes(bytes[14..18].try_into().unwrap()) as usize;
    damage(&mut bytes, header);
    std::fs::write(&path, &bytes).unwrap();
    bin_file_counts(&path, &BinSpec::default())
        .unwrap_err()
        .to_string()
}

/// Found by fuzzing: a zipped block whose data lie past the file's end
/// (and no next block) is an error naming the block, not an overflow.
#[test]
fn a_zipped_block_past_the_files_end_is_refused_by_name() {
    let e = error_of_a_damaged_zipped_block("past.sdt", |bytes, header| {
        let past = (bytes.len() + 100) as u32;
        bytes[header + 2..header + 6].copy_from_slice(&past.to_le_bytes());
        bytes[header + 6..header + 10].copy_from_slice(&0u32.to_le_bytes());
    });
    assert!(
        e.contains("past.sdt") && e.contains("data block 0") && e.contains("past the file's end"),
        "{e}"
    );
}

/// Found by fuzzing: a zipped block whose next block lies a terabyte on
/// (the offset's high byte of a revision-15 header) is an error naming
/// the block, checked before any buffer of that length is made (such a
/// buffer aborted the process).
#[test]
fn a_zipped_block_reaching_a_terabyte_past_the_end_is_refused_before_reading() {
    // next_block_offs's extension byte: 0xFF << 32, a terabyte on.
    let e = error_of_a_damaged_zipped_block("far.sdt", |bytes, header| bytes[header + 1] = 0xFF);
    assert!(
        e.contains("far.sdt") && e.contains("data block 0") && e.contains("past the file's end"),
        "{e}"
    );
}

/// A `.spc` of `entries` overflow-count records (each the most a record
/// counts, 2^28 - 1 overflows of 4096 clocks) and then one photon.
fn overflow_spc(entries: usize) -> Vec<u8> {
    let mut bytes = bh_files::header(Layout::Spc130, 500, 0, false);
    for _ in 0..entries {
        bytes.extend(bh_files::overflows(0x0FFF_FFFF));
    }
    bytes.extend(bh_files::photon(
        Layout::Spc130,
        0,
        100,
        7,
        false,
        false,
        false,
    ));
    bytes
}

/// Files in `dir` other than `keep` (a leftover temporary output).
fn others(dir: &Path, keep: &[&Path]) -> Vec<std::path::PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| !keep.contains(&p.as_path()))
        .collect()
}

#[test]
fn a_conversion_that_would_outgrow_the_disk_is_refused_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let spc = dir.path().join("gaps.spc");
    // A million entries of 2^40 clocks: a PTU of petabytes.
    std::fs::write(&spc, overflow_spc(1_000_000)).unwrap();
    let ptu = dir.path().join("gaps.ptu");
    let started = std::time::Instant::now();
    let r = run(&["convert", s(&spc), "--micro-unit", "10ps", "--out", s(&ptu)]);
    let t = text(&r);
    assert_eq!(r.status.code(), Some(1), "{t}");
    assert!(
        t.contains("gaps.spc") && t.contains("refused before writing") && t.contains("overflows"),
        "{t}"
    );
    assert!(started.elapsed().as_secs() < 20, "{:?}", started.elapsed());
    assert_eq!(
        others(dir.path(), &[&spc]),
        Vec::<std::path::PathBuf>::new()
    );
    // `bin` of the same file: its one photon, at once.
    let r = run(&[
        "bin",
        s(&spc),
        "--micro-unit",
        "10ps",
        "--out",
        s(&dir.path().join("b")),
    ]);
    assert!(text(&r).contains("1 photons, 1 binned"), "{}", text(&r));
}

#[test]
fn convert_stops_on_ctrl_c_and_sigterm_and_leaves_nothing() {
    for signal in [
        nix::sys::signal::Signal::SIGINT,
        nix::sys::signal::Signal::SIGTERM,
    ] {
        let dir = tempfile::tempdir().unwrap();
        let spc = dir.path().join("long.spc");
        // 2,000 entries: about a million overflow records each, 8 GB of
        // PTU in all, more than the signal leaves time to write.
        std::fs::write(&spc, overflow_spc(2_000)).unwrap();
        let ptu = dir.path().join("long.ptu");
        let child = command::scatterscope()
            .args(["convert", s(&spc), "--micro-unit", "10ps", "--out", s(&ptu)])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(700));
        let signalled = std::time::Instant::now();
        nix::sys::signal::kill(nix::unistd::Pid::from_raw(child.id() as i32), signal).unwrap();
        let o = child.wait_with_output().unwrap();
        let t = format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        assert_eq!(o.status.code(), Some(3), "{signal}: {t}");
        assert!(
            t.contains("interrupted") && t.contains("nothing was written"),
            "{t}"
        );
        assert!(
            signalled.elapsed().as_secs() < 5,
            "{:?}",
            signalled.elapsed()
        );
        assert_eq!(
            others(dir.path(), &[&spc]),
            Vec::<std::path::PathBuf>::new()
        );
    }
}

#[test]
fn no_command_writes_over_the_setup_file_it_reads_and_a_huge_one_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let spc = dir.path().join("run.spc");
    std::fs::write(&spc, random_spc(Layout::Spc130, 2_000, 1, 5)).unwrap();
    write_set(&spc);
    let set = spc.with_extension("set");
    let before = std::fs::read(&set).unwrap();
    let r = run(&["convert", s(&spc), "--out", s(&set)]);
    let t = text(&r);
    assert_eq!(r.status.code(), Some(1), "{t}");
    assert!(t.contains("run.set"), "{t}");
    assert_eq!(
        std::fs::read(&set).unwrap(),
        before,
        "the setup file is intact"
    );
    // A 20 GiB "setup file" (sparse): refused by its size, not read.
    let big = dir.path().join("big.spc");
    std::fs::copy(&spc, &big).unwrap();
    let f = std::fs::File::create(big.with_extension("set")).unwrap();
    f.set_len(20 << 30).unwrap();
    let started = std::time::Instant::now();
    let r = run(&["bin", s(&big), "--out", s(&dir.path().join("b"))]);
    let t = text(&r);
    assert_eq!(r.status.code(), Some(1), "{t}");
    assert!(
        t.contains("big.set") && t.contains("setup file of 21474836480 bytes"),
        "{t}"
    );
    assert!(started.elapsed().as_secs() < 5, "{:?}", started.elapsed());
}

/// Overflow counts that add up past 2^64 macro-time ticks: `info` says the
/// duration is unknown (a warning), not a wrapped or saturated number.
#[test]
fn info_says_when_overflows_pass_two_to_the_64_ticks() {
    let dir = tempfile::tempdir().unwrap();
    let spc = dir.path().join("far.spc");
    // The 256-channel layout's overflows are 2^17 ticks: 2^28 - 1 of them
    // per count entry, so 2^19 entries pass 2^64 (a 2 MB file).
    let mut bytes = bh_files::header(Layout::Spc600_256, 500, 0, false);
    for _ in 0..(1 << 19) + 16 {
        bytes.extend(bh_files::overflows(0x0FFF_FFFF));
    }
    bytes.extend(bh_files::photon(
        Layout::Spc600_256,
        0,
        100,
        7,
        false,
        false,
        false,
    ));
    std::fs::write(&spc, bytes).unwrap();
    let r = run(&[
        "info",
        s(&spc),
        "--spc-module",
        "spc-600-256",
        "--micro-unit",
        "10ps",
    ]);
    let t = text(&r);
    assert_eq!(r.status.code(), Some(4), "{t}");
    assert!(
        t.contains("measured duration unknown") && !t.contains("measured duration: "),
        "{t}"
    );
}
