//! Stack file round trips and error messages.

#[path = "common/command.rs"]
mod command;
#[path = "common/npy.rs"]
mod npy;
#[path = "common/pydeps.rs"]
mod pydeps;

use std::path::Path;

use ndarray::Array3;
use scatterscope::physics::{Preset, Sampling};
use scatterscope::stack::{DroppedBin, META_VERSION, Stack, StackMeta, ValueKind};

fn sample_stack(kind: ValueKind) -> Stack {
    let data = Array3::from_shape_fn((3, 5, 7), |(k, r, c)| match kind {
        ValueKind::Counts => ((k * 31 + r * 7 + c) % 13) as f32,
        _ => (k as f32 + 1.0) * 0.1 + r as f32 * 1e-3 + c as f32 * 1.7e-7,
    });
    Stack {
        data,
        meta: StackMeta {
            version: META_VERSION,
            kind,
            bin_starts_ps: vec![40.0, 44.0, 48.0],
            bin_width_ps: 4.0,
            pixel_pitch_cm: 50.0 / 256.0,
            setup: Some(Preset::Paper.setup()),
            sampling: Some(Sampling::Integrated),
            dropped_bins: vec![DroppedBin {
                start_ps: 36.0,
                photons: 0.956,
            }],
            clamped_negative: 3,
            seed: Some(42),
            source: "test".into(),
            boundary: None,
            acquisition: Some(serde_json::json!({"device": "mock", "photons": 12})),
            unstated: Vec::new(),
            laser_frequency_hz: Some(80e6),
            laser_notes: Vec::new(),
            recorded_bins: None,
        },
        exact_counts: None,
    }
}

#[test]
fn exr_round_trip_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    for kind in [
        ValueKind::Counts,
        ValueKind::ExpectedCounts,
        ValueKind::Kernel,
    ] {
        let s = sample_stack(kind);
        let path = dir.path().join("s.exr");
        s.save(&path).unwrap();
        assert_eq!(Stack::load(&path).unwrap(), s);
    }
}

/// Every float32 bit pattern of a count (non-negative, up to 2^53) survives the stack file's
/// compression bit for bit, in an image taller than one compressed block
/// (32 lines for PIZ) and of odd sizes: subnormals, huge values, zeros.
#[test]
fn exr_round_trip_keeps_every_float_bit() {
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let data = Array3::from_shape_fn((4, 77, 53), |_| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        // Every bit pattern of a finite value up to 2^53 (past it the
        // reader refuses the value as more than any measurement counts):
        // exponents below 127 + 53.
        let bits = (state >> 32) as u32 & 0x7FFF_FFFF;
        f32::from_bits(bits % (180 << 23))
    });
    let mut s = sample_stack(ValueKind::ExpectedCounts);
    s.meta.bin_starts_ps = vec![40.0, 44.0, 48.0, 52.0];
    s.data = data;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bits.exr");
    s.save(&path).unwrap();
    let back = Stack::load(&path).unwrap();
    let bits = |a: &Array3<f32>| a.mapv(f32::to_bits);
    assert_eq!(bits(&back.data), bits(&s.data));
}

#[test]
fn exr_has_named_channels_and_plain_attributes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.exr");
    sample_stack(ValueKind::Counts).save(&path).unwrap();
    let meta = exr::meta::MetaData::read_from_file(&path, false).unwrap();
    let header = &meta.headers[0];
    let names: Vec<String> = header
        .channels
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    assert_eq!(names, ["t000", "t001", "t002"]);
    let attr = |n: &str| {
        header
            .own_attributes
            .other
            .get(&exr::prelude::Text::from(n))
            .cloned()
    };
    assert_eq!(
        attr("binWidthPs"),
        Some(exr::meta::attribute::AttributeValue::F64(4.0))
    );
    assert_eq!(
        attr("binStartPs"),
        Some(exr::meta::attribute::AttributeValue::F64(40.0))
    );
    assert_eq!(
        attr("thicknessCm"),
        Some(exr::meta::attribute::AttributeValue::F64(3.0))
    );
}

#[test]
fn the_same_stack_always_gives_the_same_exr_bytes() {
    // The exr crate keeps custom attributes in a hash map whose order
    // changes between maps; the writer puts them in name order.
    let dir = tempfile::tempdir().unwrap();
    let stack = sample_stack(ValueKind::Counts);
    let first = dir.path().join("a.exr");
    stack.save(&first).unwrap();
    let bytes = std::fs::read(&first).unwrap();
    for i in 0..8 {
        let path = dir.path().join(format!("b{i}.exr"));
        stack.save(&path).unwrap();
        assert!(std::fs::read(&path).unwrap() == bytes, "write {i} differs");
    }
    // Still a valid file with every attribute and the same data.
    let back = Stack::load(&first).unwrap();
    assert_eq!(back.data, stack.data);
    assert_eq!(back.meta, stack.meta);
    let meta = exr::meta::MetaData::read_from_file(&first, false).unwrap();
    let names: Vec<String> = meta.headers[0]
        .own_attributes
        .other
        .keys()
        .map(|k| k.to_string())
        .collect();
    for want in ["binStartPs", "binWidthPs", "pixelPitchCm", "scatterscope"] {
        assert!(names.iter().any(|n| n == want), "{want} missing: {names:?}");
    }
}

#[test]
fn npy_round_trip_is_exact_for_floats_and_counts() {
    let dir = tempfile::tempdir().unwrap();
    for kind in [ValueKind::Counts, ValueKind::ExpectedCounts] {
        let s = sample_stack(kind);
        let path = dir.path().join("s.npy");
        s.save(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let header = String::from_utf8_lossy(&bytes[..128]).to_string();
        let want = if kind == ValueKind::Counts {
            "'<u4'"
        } else {
            "'<f4'"
        };
        assert!(header.contains(want), "{header}");
        assert!(header.contains("(3, 5, 7)"), "{header}");
        assert_eq!(Stack::load(&path).unwrap(), s);
    }
}

/// A .npy file built byte by byte from the format description, independent
/// of the writer under test.
fn handmade_npy(path: &Path, descr: &str, shape: (usize, usize, usize), payload: &[u8]) {
    std::fs::write(path, npy::npy_bytes(descr, shape, payload)).unwrap();
}

#[test]
fn npy_reads_float64_and_uint16_from_other_writers() {
    let dir = tempfile::tempdir().unwrap();
    let meta = sample_stack(ValueKind::Counts).meta;
    let path = dir.path().join("f8.npy");
    let values: Vec<f64> = (0..105).map(|i| i as f64 * 0.5).collect();
    let payload: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    handmade_npy(&path, "<f8", (3, 5, 7), &payload);
    std::fs::write(
        dir.path().join("f8.json"),
        serde_json::to_string(&meta).unwrap(),
    )
    .unwrap();
    let s = Stack::load(&path).unwrap();
    assert_eq!(s.data[[2, 4, 6]], 52.0);
    assert_eq!(s.data[[0, 0, 1]], 0.5);

    let path = dir.path().join("u2.npy");
    let payload: Vec<u8> = (0..105u16).flat_map(|v| v.to_le_bytes()).collect();
    handmade_npy(&path, "<u2", (3, 5, 7), &payload);
    std::fs::write(
        dir.path().join("u2.json"),
        serde_json::to_string(&meta).unwrap(),
    )
    .unwrap();
    assert_eq!(Stack::load(&path).unwrap().data[[1, 0, 0]], 35.0);

    let path = dir.path().join("i2.npy");
    handmade_npy(&path, "<i2", (3, 5, 7), &payload);
    std::fs::write(
        dir.path().join("i2.json"),
        serde_json::to_string(&meta).unwrap(),
    )
    .unwrap();
    let e = Stack::load(&path).unwrap_err().to_string();
    assert!(e.contains("i2.npy") && e.contains("dtype `<i2`"), "{e}");
}

#[test]
fn bad_files_give_errors_naming_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    // Missing sidecar.
    let path = dir.path().join("lonely.npy");
    sample_stack(ValueKind::Counts).save(&path).unwrap();
    std::fs::remove_file(dir.path().join("lonely.json")).unwrap();
    let e = Stack::load(&path).unwrap_err().to_string();
    assert!(e.contains("lonely.json"), "{e}");
    // Not a .npy at all.
    let path = dir.path().join("junk.npy");
    std::fs::write(&path, b"hello world, not numpy").unwrap();
    std::fs::write(
        dir.path().join("junk.json"),
        serde_json::to_string(&sample_stack(ValueKind::Counts).meta).unwrap(),
    )
    .unwrap();
    let e = Stack::load(&path).unwrap_err().to_string();
    assert!(e.contains("junk.npy") && e.contains("NUMPY"), "{e}");
    // NaN in the data.
    let mut s = sample_stack(ValueKind::ExpectedCounts);
    s.data[[1, 2, 3]] = f32::NAN;
    let path = dir.path().join("nan.exr");
    s.save(&path).unwrap();
    let e = Stack::load(&path).unwrap_err().to_string();
    assert!(
        e.contains("nan.exr") && e.contains("bin 1, row 2, column 3 holds NaN"),
        "{e}"
    );
    // Metadata that disagrees with the data.
    let mut s = sample_stack(ValueKind::Counts);
    s.meta.bin_starts_ps.pop();
    let path = dir.path().join("short.exr");
    s.save(&path).unwrap();
    let e = Stack::load(&path).unwrap_err().to_string();
    assert!(
        e.contains("bin_starts_ps has 2 entries but the stack has 3 bins"),
        "{e}"
    );
    // Truncated EXR.
    let path = dir.path().join("cut.exr");
    sample_stack(ValueKind::Counts).save(&path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    let e = Stack::load(&path).unwrap_err().to_string();
    assert!(e.contains("cut.exr"), "{e}");
    // Unknown extension.
    let e = sample_stack(ValueKind::Counts)
        .save(&dir.path().join("s.png"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("s.png") && e.contains(".exr, .npy or .ome.tif"),
        "{e}"
    );
    // OME-TIFF is written, not read: a reader of stacks says so.
    let tif = dir.path().join("s.ome.tif");
    sample_stack(ValueKind::Counts).save(&tif).unwrap();
    let e = Stack::load(&tif).unwrap_err().to_string();
    assert!(
        e.contains("s.ome.tif") && e.contains("not read back"),
        "{e}"
    );
}

#[test]
fn stacks_written_by_openexr_read_without_metadata() {
    // Written by the OpenEXR project's own library
    // (scripts/make_openexr_fixtures.py): float32 with ZIP, half with PIZ;
    // bin k, row r, column c holds (k + 1) * 100 + 10 r + c.
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/openexr");
    for name in ["float_zip.exr", "half_piz.exr"] {
        let path = dir.join(name);
        let (data, meta) = Stack::read(&path).unwrap();
        assert!(meta.is_none(), "{name}");
        assert_eq!(data.dim(), (3, 8, 8), "{name}");
        for ((k, r, c), &v) in data.indexed_iter() {
            assert_eq!(
                v,
                ((k + 1) * 100 + r * 10 + c) as f32,
                "{name} at {k},{r},{c}"
            );
        }
        let e = Stack::load(&path).unwrap_err().to_string();
        assert!(
            e.contains(name) && e.contains("no `scatterscope` attribute"),
            "{e}"
        );
    }
}

#[test]
fn plain_npy_reads_without_sidecar_and_takes_given_metadata() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plain.npy");
    let payload: Vec<u8> = (0..105u32).flat_map(|v| v.to_le_bytes()).collect();
    handmade_npy(&path, "<u4", (3, 5, 7), &payload);
    let (data, meta) = Stack::read(&path).unwrap();
    assert!(meta.is_none());
    assert_eq!(data[[2, 4, 6]], 104.0);
    let e = Stack::load(&path).unwrap_err().to_string();
    assert!(e.contains("plain.npy") && e.contains("no sidecar"), "{e}");
    // The physics' window becomes the file's three bins from t_start.
    let mut setup = Preset::Paper.setup();
    setup.bins.start_ps = 40.0;
    setup.sensor.height_px = 5;
    setup.sensor.width_px = 7;
    let meta = StackMeta::consecutive(&setup, 3, ValueKind::Counts, "plain".into()).unwrap();
    assert_eq!(meta.bin_starts_ps, vec![40.0, 44.0, 48.0]);
    assert_eq!(meta.setup.as_ref().unwrap().bins.count, 3);
    assert_eq!(meta.pixel_pitch_cm, setup.sensor.pixel_pitch_cm());
    let stack = Stack::from_parts(data, meta, &path).unwrap();
    assert_eq!(stack.total(), (0..105).sum::<u32>() as f64);
    // A window the physics cannot have is refused with its field.
    let e = StackMeta::consecutive(&setup, 0, ValueKind::Counts, "plain".into())
        .unwrap_err()
        .to_string();
    assert!(e.contains("bins"), "{e}");
}

/// Found by the `exr_stack` fuzz target: 759 bytes whose header declares
/// 117440513 x 8 pixels made the reader allocate gigabytes. Declared sizes
/// beyond what the file could hold are refused before any pixel is read.
#[test]
fn an_exr_declaring_more_pixels_than_it_could_hold_is_refused() {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz/exr_huge_declared_size.exr");
    let e = Stack::read(&path).unwrap_err().to_string();
    assert!(
        e.contains("exr_huge_declared_size.exr")
            && e.contains("declares 117440513 x 8 pixels")
            && e.contains("file of 759 bytes"),
        "{e}"
    );
}

#[test]
fn a_measured_irf_of_the_largest_size_round_trips_through_exr_and_npy() {
    use scatterscope::physics::{IrfTable, irf::MAX_TABLE_BINS};
    let dir = tempfile::tempdir().unwrap();
    let weights: Vec<f64> = (0..MAX_TABLE_BINS)
        .map(|j| (-(j as f64) / 900.0).exp() * (1.0 + 0.3 * (j as f64 * 0.37).sin()))
        .collect();
    let mut s = sample_stack(ValueKind::Counts);
    let mut setup = Preset::Paper.setup();
    setup.irf = Some(IrfTable::new(0.25, -37.5, weights).unwrap().into());
    s.meta.setup = Some(setup);
    for name in ["s.exr", "s.npy"] {
        let path = dir.path().join(name);
        s.save(&path).unwrap();
        assert_eq!(Stack::load(&path).unwrap(), s, "{name}");
    }
}

/// Counts at and just above 2^24, where float32 stops holding every whole
/// number, in a stack that round-trips through both formats bit for bit.
/// Counts turned into values in their own memory give the stack the
/// borrowing conversion gives: whole arrays, arrays cut along their first
/// axis (an offset into their memory), transposed ones, counts past 2^24.
#[test]
fn owned_counts_become_the_same_stack_as_borrowed_ones() {
    use ndarray::{Array3, s};
    let meta = sample_stack(ValueKind::Counts).meta;
    let counts = Array3::from_shape_fn((5, 4, 3), |(k, r, c)| (k * 100 + r * 10 + c) as u32);
    let mut big = counts.clone();
    big[[1, 2, 0]] = (1 << 24) + 1;
    let cases = [
        counts.clone(),
        counts.clone().slice_move(s![2.., .., ..]),
        counts.clone().permuted_axes([0, 2, 1]),
        big,
    ];
    for (i, c) in cases.into_iter().enumerate() {
        let borrowed = Stack::from_counts(c.view(), meta.clone());
        let owned = Stack::from_owned_counts(c, meta.clone());
        assert_eq!(owned, borrowed, "case {i}");
        assert_eq!(owned.exact_counts.is_some(), i == 3, "case {i}");
    }
}

#[test]
fn counts_above_2_to_the_24_round_trip_exactly_through_exr_and_npy() {
    let dir = tempfile::tempdir().unwrap();
    let mut counts = ndarray::Array3::<u32>::zeros((3, 2, 2));
    counts[[0, 0, 0]] = 1 << 24;
    counts[[0, 0, 1]] = (1 << 24) + 1; // float32 rounds this to 2^24
    counts[[1, 1, 0]] = u32::MAX;
    counts[[2, 1, 1]] = 7;
    let meta = sample_stack(ValueKind::Counts).meta;
    let stack = Stack::from_counts(counts.view(), meta.clone());
    assert_eq!(stack.exact_counts.as_ref(), Some(&counts));
    for ext in ["exr", "npy"] {
        let path = dir.path().join(format!("big.{ext}"));
        stack.save(&path).unwrap();
        let back = Stack::load(&path).unwrap();
        assert_eq!(back.exact_counts.as_ref(), Some(&counts), "{ext}");
        assert_eq!(back.data, stack.data, "{ext}");
    }
    // Up to 2^24 float32 is exact and nothing more is kept.
    counts[[0, 0, 1]] = 1 << 24;
    counts[[1, 1, 0]] = 0;
    assert!(
        Stack::from_counts(counts.view(), meta)
            .exact_counts
            .is_none()
    );
}

/// 2^24 + 3 photons in one bin: `bin`'s stack and its file sum to the ledger.
#[test]
fn a_bin_of_more_than_2_to_the_24_photons_sums_to_the_ledger() {
    use scatterscope::formats::picoquant::records::RecordType;
    use scatterscope::formats::picoquant::writer::{PtuWriter, WriterHeader};
    use scatterscope::tags::bin_file::{BinOutputs, BinSpec, bin_file, bin_file_to};
    let dir = tempfile::tempdir().unwrap();
    let ptu = dir.path().join("one-bin.ptu");
    let h = WriterHeader {
        resolution_s: 10e-12,
        sync_rate_hz: 40e6,
        device: "test".into(),
        imaging: None,
        extra: Vec::new(),
    };
    let n = (1u32 << 24) + 3;
    // Generic T3 photons on channel 0, micro time 100, each at sync 5.
    let record = (100u32 << 10) | 5;
    let mut w = PtuWriter::create(&ptu, RecordType::GenericT3, &h).unwrap();
    w.write_records(&vec![record; n as usize]).unwrap();
    w.finish().unwrap();
    let binned = bin_file(&ptu, &BinSpec::default()).unwrap();
    assert_eq!(binned.counts.binned, u64::from(n));
    let stack = &binned.stacks[0];
    let exact = stack
        .exact_counts
        .as_ref()
        .expect("counts above 2^24 are kept");
    assert_eq!(
        exact.iter().map(|&c| u64::from(c)).sum::<u64>(),
        u64::from(n)
    );
    // The command's writer keeps them exactly too, in EXR and in .npy.
    for npy in [false, true] {
        let out = dir.path().join(format!("out{npy}"));
        let outputs = BinOutputs {
            npy,
            ..BinOutputs::new(&out)
        };
        let written = bin_file_to(&ptu, &BinSpec::default(), &outputs).unwrap();
        let back = Stack::load(&written.stacks[0][0]).unwrap();
        assert_eq!(back.exact_counts.as_ref(), Some(exact), "npy {npy}");
        assert_eq!(back.meta, stack.meta, "npy {npy}");
    }
}

/// The OpenEXR project's own library reads the stack files we write,
/// float32 bins and 32-bit count channels alike, sample for sample.
#[test]
#[ignore = "needs OpenEXR under target/pydeps (scripts/fetch_python_deps.sh)"]
fn openexr_reads_our_stacks_sample_for_sample() {
    use ndarray_npy::ReadNpyExt;
    let dir = tempfile::tempdir().unwrap();
    let mut floats = sample_stack(ValueKind::ExpectedCounts);
    floats.data = Array3::from_shape_fn((3, 70, 41), |(k, r, c)| {
        (k as f32 + 0.5) * 1e-3 + r as f32 * 7.25 + c as f32 * 1e5
    });
    let counts = Array3::from_shape_fn((3, 70, 41), |(k, r, c)| {
        (1u32 << 24) + (k * 1_000_003 + r * 977 + c) as u32
    });
    let mut exact = Stack::from_counts(counts.view(), floats.meta.clone());
    exact.meta.kind = ValueKind::Counts;
    assert!(exact.exact_counts.is_some());
    let script = r#"
import sys, numpy, OpenEXR
with OpenEXR.File(sys.argv[1]) as f:
    ch = f.channels()
    names = sorted(n for n in ch if n.startswith("t"))
    numpy.save(sys.argv[2], numpy.stack([ch[n].pixels for n in names]))
"#;
    let read_back = |stack: &Stack, name: &str| {
        let exr = dir.path().join(format!("{name}.exr"));
        let npy = dir.path().join(format!("{name}.npy"));
        stack.save(&exr).unwrap();
        pydeps::python(script, &[&exr, &npy]);
        std::fs::File::open(&npy).unwrap()
    };
    let theirs = Array3::<f32>::read_npy(read_back(&floats, "floats")).unwrap();
    assert_eq!(theirs.mapv(f32::to_bits), floats.data.mapv(f32::to_bits));
    let theirs = Array3::<u32>::read_npy(read_back(&exact, "counts")).unwrap();
    assert_eq!(theirs, counts);
}

/// OpenEXR's own library opens a stack of 32767 bins and not one of 32768:
/// the writer refuses the latter by name (pointing to .npy), and `bin`
/// refuses such a window before reading the file.
#[test]
#[ignore = "needs OpenEXR under target/pydeps (scripts/fetch_python_deps.sh)"]
fn stacks_of_more_bins_than_openexr_opens_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let stack = |k: usize| {
        Stack::new(
            Array3::ones((k, 1, 1)),
            StackMeta::measured(0.0, 1.0, k, "test".into(), None),
        )
    };
    let ok = dir.path().join("most.exr");
    stack(32_767).save(&ok).unwrap();
    let opened = pydeps::python(
        "import sys, OpenEXR\nwith OpenEXR.File(sys.argv[1]) as f: print(len(f.channels()))",
        &[ok.to_str().unwrap()],
    );
    assert_eq!(opened.trim(), "32767");
    let e = stack(32_768)
        .save(&dir.path().join("too_many.exr"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("32768 slices") && e.contains(".npy"), "{e}");
    assert!(!dir.path().join("too_many.exr").exists());
    let ptu = dir.path().join("t3.ptu");
    scatterscope::formats::picoquant::writer::write_synthetic_t3(&ptu, 1_000).unwrap();
    let r = command::run(&[
        "bin",
        ptu.to_str().unwrap(),
        "--bins",
        "40000",
        "--out",
        dir.path().join("b").to_str().unwrap(),
    ]);
    let t = command::text(&r);
    assert_eq!(r.status.code(), Some(1), "{t}");
    assert!(t.contains("40000 bins") && t.contains("--npy"), "{t}");
}
