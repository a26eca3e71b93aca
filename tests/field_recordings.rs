//! Files real instruments wrote (`../shared/data/flim-samples`: a
//! Becker & Hickl SPC-130 and SPC-630 FIFO file, an SPC-150 `.sdt` FLIM
//! image, a PicoHarp PTU FLIM image; their licences beside them), binned
//! by the command as a lab would and judged by the independent readers:
//! tttrlib photon for photon, sdtfile and ptufile value for value,
//! tifffile and ome-types for the OME-TIFF's sizes.

#[path = "common/command.rs"]
mod command;
#[path = "common/pydeps.rs"]
mod pydeps;
#[path = "common/shared_data.rs"]
mod shared_data;

use std::path::Path;

use command::{run, text};
use shared_data::shared_data;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Whether our `.npy` stack (bins, rows, columns) holds, per routing
/// channel, the micro-time histogram of tttrlib's photons: prints
/// `equal photons`.
const TTTRLIB_HISTOGRAMS: &str = r#"
import sys, numpy, tttrlib
t = tttrlib.TTTR(sys.argv[1], sys.argv[2])
photons = numpy.asarray(t.event_types) == 0
ch = numpy.asarray(t.routing_channels).astype(numpy.int64)[photons]
micro = numpy.asarray(t.micro_times).astype(numpy.int64)[photons]
ours = numpy.load(sys.argv[3])
bins, rows, cols = ours.shape
theirs = numpy.zeros((bins, cols), numpy.int64)
numpy.add.at(theirs, (micro, ch), 1)
print("equal" if rows == 1 and (ours[:, 0, :] == theirs).all() else "differ", int(photons.sum()))
"#;

/// Bins `file` by routing channel into `.npy` with `flags`, returns the
/// command's output and the stack's path.
fn bin_by_channel(file: &Path, out: &Path, flags: &[&str]) -> (String, std::path::PathBuf) {
    let args = [
        &[
            "bin",
            s(file),
            "--pixels",
            "channel",
            "--npy",
            "--no-preview",
        ],
        flags,
        &["--out", s(out)],
    ];
    let r = run(&args.concat());
    let t = text(&r);
    assert!(matches!(r.status.code(), Some(0 | 4)), "{t}");
    (t, out.join("stack.npy"))
}

#[test]
#[ignore = "needs ../shared/data and target/pydeps (scripts/fetch_python_deps.sh)"]
fn an_spc630_fifo_file_bins_photon_for_photon_as_tttrlib_reads_it() {
    let file = shared_data("flim-samples/becker-hickl/bh_spc630_256.spc");
    let dir = tempfile::tempdir().unwrap();
    // Read as the default SPC-130 layout, its header's bit 26 (a raw-data
    // file there, reserved in the 256-channel layout) is refused, naming
    // the layout that reads it.
    let r = run(&["bin", s(&file), "--out", s(&dir.path().join("x"))]);
    let t = text(&r);
    assert_eq!(r.status.code(), Some(1), "{t}");
    assert!(t.contains("--spc-module spc-600-256"), "{t}");
    let (t, npy) = bin_by_channel(
        &file,
        &dir.path().join("b"),
        &["--spc-module", "spc-600-256"],
    );
    assert!(t.contains("294884 photons, 294884 binned"), "{t}");
    let got = pydeps::python(TTTRLIB_HISTOGRAMS, &[s(&file), "SPC-600_256", s(&npy)]);
    assert_eq!(got.trim(), "equal 294884");
}

#[test]
#[ignore = "needs ../shared/data and target/pydeps (scripts/fetch_python_deps.sh)"]
fn an_spc_file_without_its_setup_bins_by_adc_channel_as_tttrlib_reads_it() {
    let file = shared_data("flim-samples/becker-hickl/bh_spc132.spc");
    let dir = tempfile::tempdir().unwrap();
    let (t, npy) = bin_by_channel(&file, &dir.path().join("b"), &[]);
    assert!(
        t.contains("warning: the micro-time unit is unknown") && t.contains("bh_spc132.set"),
        "{t}"
    );
    let got = pydeps::python(TTTRLIB_HISTOGRAMS, &[s(&file), "SPC-130", s(&npy)]);
    assert_eq!(got.trim(), "equal 183657");
    // The sidecar marks the bins as channels, not picoseconds.
    let meta = std::fs::read_to_string(npy.with_extension("json")).unwrap();
    assert!(meta.contains("\"time_unit\""), "{meta}");
    // With the unit given, the same photons bin by time.
    let (t, _) = bin_by_channel(&file, &dir.path().join("c"), &["--micro-unit", "3.0518ps"]);
    assert!(
        t.contains("3.0518 ps bins") && !t.contains("unknown"),
        "{t}"
    );
}

#[test]
#[ignore = "needs ../shared/data and target/pydeps (scripts/fetch_python_deps.sh)"]
fn an_sdt_flim_image_bins_value_for_value_as_sdtfile_reads_it() {
    let file = shared_data("flim-samples/becker-hickl/SDT_c01.sdt");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("b");
    for npy in [true, false] {
        let mut args = vec![
            "bin",
            s(&file),
            "--no-preview",
            "--ome-tiff",
            "--out",
            s(&out),
        ];
        if npy {
            args.push("--npy");
        }
        let r = run(&args);
        assert!(r.status.success(), "{}", text(&r));
    }
    // Every block, in .npy (16-bit, as stored), EXR and OME-TIFF, against
    // sdtfile's arrays (rows, columns, points).
    let script = r#"
import sys, numpy, sdtfile, tifffile, OpenEXR
f = sdtfile.SdtFile(sys.argv[1])
out = sys.argv[2]
for i, d in enumerate(f.data):
    want = numpy.moveaxis(d, -1, 0)
    npy = numpy.load(f"{out}/stack_f{i:03}.npy")
    assert npy.dtype == numpy.uint16, npy.dtype
    tif = tifffile.imread(f"{out}/stack_f{i:03}.ome.tif")
    with OpenEXR.File(f"{out}/stack_f{i:03}.exr") as e:
        ch = e.channels()
        exr = numpy.stack([ch[name].pixels for name in sorted(ch)])
    for name, got in (("npy", npy), ("ome.tif", tif), ("exr", exr)):
        assert got.shape == want.shape and (got == want).all(), (i, name, got.shape)
    print(i, int(want.sum()), f.times[i][1] * 1e12)
"#;
    let got = pydeps::python(script, &[s(&file), s(&out)]);
    let lines: Vec<&str> = got.lines().collect();
    assert_eq!(lines.len(), 2, "{got}");
    assert!(
        lines[0].starts_with("0 5359 46.83907") && lines[1].starts_with("1 227683 46.83907"),
        "{got}"
    );
}

#[test]
#[ignore = "needs ../shared/data and target/pydeps (scripts/fetch_python_deps.sh)"]
fn a_ptu_flim_image_bins_as_ptufile_decodes_it_and_keeps_its_pixel_size() {
    let file = shared_data("flim-samples/picoquant/hazelnut_flim_z1.ptu");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("b");
    let r = run(&[
        "bin",
        s(&file),
        "--npy",
        "--ome-tiff",
        "--no-preview",
        "--out",
        s(&out),
    ]);
    assert!(r.status.success(), "{}", text(&r));
    let script = r#"
import sys, numpy, ptufile, tifffile
from ome_types import from_xml
with ptufile.PtuFile(sys.argv[1]) as f:
    d = f.decode_image(dtype="uint32")
    um = f.tags["ImgHdr_PixResol"]
want = numpy.moveaxis(d.sum(axis=0)[:, :, 0, :], -1, 0)
ours = numpy.load(sys.argv[2] + "/stack.npy")
assert ours.shape == want.shape and (ours == want).all(), (ours.shape, want.shape)
with tifffile.TiffFile(sys.argv[2] + "/stack.ome.tif") as t:
    p = from_xml(t.ome_metadata).images[0].pixels
print(int(want.sum()), p.physical_size_x == um and p.physical_size_y == um, p.physical_size_x_unit.value)
"#;
    let got = pydeps::python(script, &[s(&file), s(&out)]);
    assert_eq!(got.trim(), "150363 True µm");
}
