//! OME-TIFF out, judged by independent readers: tifffile reads the stacks
//! `bin`, `acquire` and `reconstruct` write with the shape, axes, counts
//! and physical sizes of the EXR beside them, sees the lifetime modulo of
//! T, and ome-types parses the OME-XML against its schema's model.

#[path = "common/command.rs"]
mod command;
#[path = "common/pydeps.rs"]
mod pydeps;

use command::{SMALL_SENSOR, run, text};
use std::path::Path;

use ndarray::Array3;
use scatterscope::stack::{Stack, StackMeta, Unstated, ValueKind};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// What tifffile and ome-types make of an OME-TIFF, as JSON: the series'
/// axes, shape and dtype, every value (flat, C order), the OME pixel type,
/// physical size and unit, and the modulo annotation's attributes.
const READ: &str = r#"
import json, sys, tifffile, ome_types
with tifffile.TiffFile(sys.argv[1]) as t:
    series = t.series[0]
    values = series.asarray()
    ome = ome_types.from_xml(t.ome_metadata)
    modulo = None
    if "ModuloAlongT" in t.ome_metadata:
        import xml.etree.ElementTree as ET
        for e in ET.fromstring(t.ome_metadata).iter():
            if e.tag.endswith("ModuloAlongT"):
                modulo = dict(e.attrib)
                modulo["labels"] = [float(l.text) for l in e if l.tag.endswith("Label")]
    p = ome.images[0].pixels
    print(json.dumps({
        "is_ome": t.is_ome,
        "axes": series.axes,
        "shape": list(values.shape),
        "dtype": str(values.dtype),
        "values": values.astype("float64").ravel().tolist(),
        "type": p.type.value,
        "size_x_um": p.physical_size_x,
        "unit": p.physical_size_x_unit.value if p.physical_size_x_unit else None,
        "size_t": p.size_t,
        "modulo": modulo,
    }))
"#;

fn read(path: &Path) -> serde_json::Value {
    serde_json::from_str(&pydeps::python(READ, &[s(path)])).unwrap()
}

/// The values of an EXR stack, flat in (bin, row, column) order.
fn values(stack: &Stack) -> Vec<f64> {
    stack.data.iter().map(|&v| f64::from(v)).collect()
}

#[test]
#[ignore = "needs tifffile and ome-types under target/pydeps (scripts/fetch_python_deps.sh)"]
fn a_binned_stack_opens_in_tifffile_as_its_exr() {
    let dir = tempfile::tempdir().unwrap();
    let ptu = dir.path().join("scan.ptu");
    scatterscope::formats::picoquant::writer::write_synthetic_t3(&ptu, 200_000).unwrap();
    let out = dir.path().join("bin");
    let r = run(&[
        "bin",
        s(&ptu),
        "--bin-width",
        "64ps",
        "--bins",
        "40",
        "--ome-tiff",
        "--out",
        s(&out),
    ]);
    assert!(r.status.success(), "{}", text(&r));
    let exr = Stack::load(&out.join("stack.exr")).unwrap();
    let tif = read(&out.join("stack.ome.tif"));
    assert_eq!(tif["is_ome"], true, "{tif}");
    let (k, h, w) = exr.data.dim();
    assert_eq!(
        tif["axes"], "HYX",
        "tifffile's axis for a lifetime modulo: {tif}"
    );
    assert_eq!(tif["shape"], serde_json::json!([k, h, w]));
    assert_eq!(tif["dtype"], "uint16");
    assert_eq!(tif["type"], "uint16");
    let got: Vec<f64> = serde_json::from_value(tif["values"].clone()).unwrap();
    assert_eq!(got, values(&exr));
    assert!(got.iter().sum::<f64>() > 0.0);
    // Physical sizes: this file states no pixel size, so the OME-TIFF
    // carries none (not the stack's placeholder); the bins along T.
    assert!(exr.meta.is_unstated(Unstated::PixelPitch));
    assert!(tif["size_x_um"].is_null(), "{tif}");
    assert_eq!(tif["size_t"], k);
    let m = &tif["modulo"];
    assert_eq!(m["Type"], "lifetime", "{tif}");
    assert_eq!(m["Unit"], "ps");
    assert_eq!(m["Step"].as_str().unwrap().parse::<f64>().unwrap(), 64.0);
    let start: f64 = m["Start"].as_str().unwrap().parse().unwrap();
    let end: f64 = m["End"].as_str().unwrap().parse().unwrap();
    assert_eq!(start, exr.meta.bin_starts_ps[0]);
    assert_eq!(end, exr.meta.bin_starts_ps[k - 1]);
}

#[test]
#[ignore = "needs tifffile and ome-types under target/pydeps (scripts/fetch_python_deps.sh)"]
fn large_counts_and_gaps_in_time_are_kept_exactly() {
    let dir = tempfile::tempdir().unwrap();
    // Counts past 2^16 and past 2^24 (where float32 stops holding whole
    // numbers): 32-bit integers, every count exact.
    let counts = Array3::from_shape_fn((3, 2, 5), |(k, y, x)| {
        (1u32 << 24) + 3 + (k * 100 + y * 10 + x) as u32
    });
    let meta = StackMeta::measured(100.0, 8.0, 3, "test".into(), None);
    let mut stack = Stack::from_counts(counts.view(), meta);
    // Bins that do not follow one another: one label per bin.
    stack.meta.bin_starts_ps = vec![100.0, 108.0, 140.0];
    let path = dir.path().join("big.ome.tif");
    stack.save(&path).unwrap();
    let tif = read(&path);
    assert_eq!(tif["dtype"], "uint32", "{tif}");
    let got: Vec<f64> = serde_json::from_value(tif["values"].clone()).unwrap();
    let want: Vec<f64> = counts.iter().map(|&c| f64::from(c)).collect();
    assert_eq!(got, want);
    assert_eq!(
        tif["modulo"]["labels"],
        serde_json::json!([100.0, 108.0, 140.0]),
        "{tif}"
    );
    // Expected counts are floats, as they are.
    let mut expected = Stack::new(
        Array3::from_elem((2, 2, 2), 0.25),
        StackMeta::measured(0.0, 8.0, 2, "test".into(), None),
    );
    expected.meta.kind = ValueKind::ExpectedCounts;
    let path = dir.path().join("expected.ome.tif");
    expected.save(&path).unwrap();
    let tif = read(&path);
    assert_eq!(tif["dtype"], "float32", "{tif}");
    assert_eq!(tif["values"], serde_json::json!(vec![0.25; 8]));
}

#[test]
#[ignore = "needs tifffile and ome-types under target/pydeps (scripts/fetch_python_deps.sh)"]
fn acquire_and_reconstruct_write_ome_tiff_beside_their_exr() {
    let dir = tempfile::tempdir().unwrap();
    let acq = dir.path().join("acq");
    let flags = ["--duration", "300ms", "--ome-tiff", "--out", s(&acq)];
    let r = run(&[&["acquire"][..], &SMALL_SENSOR, &flags].concat());
    assert!(r.status.success(), "{}", text(&r));
    let exr = Stack::load(&acq.join("stack.exr")).unwrap();
    let tif = read(&acq.join("stack.ome.tif"));
    let got: Vec<f64> = serde_json::from_value(tif["values"].clone()).unwrap();
    assert_eq!(got, values(&exr));
    let rec = dir.path().join("rec");
    let r = run(&[
        "reconstruct",
        s(&acq.join("stack.exr")),
        "--method",
        "rl-sum",
        "--ome-tiff",
        "--out",
        s(&rec),
    ]);
    assert!(r.status.success(), "{}", text(&r));
    let image = scatterscope::formats::image::read_image(&rec.join("reconstruction.exr")).unwrap();
    let tif = read(&rec.join("reconstruction.ome.tif"));
    assert_eq!(tif["axes"], "YX", "{tif}");
    assert_eq!(tif["dtype"], "float32");
    let got: Vec<f64> = serde_json::from_value(tif["values"].clone()).unwrap();
    let want: Vec<f64> = image.iter().map(|&v| f64::from(v as f32)).collect();
    assert_eq!(got, want);
    assert_eq!(tif["size_x_um"].as_f64().unwrap(), 3.0 / 16.0 * 1e4);
}
