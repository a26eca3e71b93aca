//! `scatterscope embedded`: a SPAD camera's cube of an object inside the
//! medium, lit through it, as a lab publishes it (a MATLAB level 5 cube of
//! rows x columns x bins with a background subtracted, and a file of pixel
//! centres), reconstructed with no hand conversion; the noise model named;
//! the bad pixels found; bad input refused by file and field with nothing
//! written. The stand-ins are `simulate-embedded`'s, written by the
//! project's own MAT writer; that writer and the reader are held to SciPy's
//! (`scipy.io`, an independent implementation) in the ignored tests.

#[path = "common/command.rs"]
mod command;
#[path = "common/pydeps.rs"]
mod pydeps;

use std::path::Path;

use command::{json, run, text};
use ndarray::Array2;
use ndarray_npy::ReadNpyExt;

/// The published data's geometry: 2.5 + 2.5 cm of mu_s' 71 /cm, mu_a
/// 0.14 /cm, n 1, a 6 cm beam.
const GEOMETRY: [&str; 12] = [
    "--front-thickness",
    "2.5cm",
    "--back-thickness",
    "2.5cm",
    "--mu-s-reduced",
    "71",
    "--mu-a",
    "0.14",
    "--index",
    "1",
    "--beam",
    "6cm",
];

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Simulates `target` with `extra` flags into `dir`.
fn simulate(dir: &Path, target: &str, extra: &[&str]) {
    let mut args = vec!["simulate-embedded", "--target", target, "--out", s(dir)];
    args.extend(GEOMETRY);
    args.extend(extra);
    let o = run(&args);
    assert!(o.status.success(), "{}", text(&o));
}

/// `embedded` on `dir`'s cube and positions with `extra` flags, into
/// `out`.
fn reconstruct(dir: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    reconstruct_in(dir, out, &GEOMETRY, extra)
}

/// [`reconstruct`] told `geometry`.
fn reconstruct_in(
    dir: &Path,
    out: &Path,
    geometry: &[&str],
    extra: &[&str],
) -> std::process::Output {
    let cube = dir.join("cube.mat");
    let positions = dir.join("positions.mat");
    let mut args = vec![
        "embedded",
        s(&cube),
        "--positions",
        s(&positions),
        "--positions-unit",
        "1mm",
        "--bin-width",
        "50ps",
        "--out",
        s(out),
    ];
    args.extend(geometry);
    args.extend(extra);
    run(&args)
}

fn read2(path: &Path) -> Array2<f64> {
    Array2::<f32>::read_npy(std::fs::File::open(path).unwrap())
        .unwrap()
        .mapv(f64::from)
}

fn correlation(a: &Array2<f64>, b: &Array2<f64>) -> f64 {
    let (ma, mb) = (a.mean().unwrap(), b.mean().unwrap());
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        ab += (x - ma) * (y - mb);
        aa += (x - ma).powi(2);
        bb += (y - mb).powi(2);
    }
    ab / (aa * bb).sqrt()
}

#[test]
fn a_published_layout_cube_is_reconstructed_with_its_noise_model_and_bad_pixels_named() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    simulate(dir.path(), "letter:T", &["--seed", "7", "--photons", "3e5"]);
    let o = reconstruct(dir.path(), &out, &[]);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(
        said.contains("noise model: Poisson less a subtracted background"),
        "{said}"
    );
    // 20 filtered, 2 hot, 2 dead: the stand-in's defaults, all found.
    assert!(
        said.contains("24 of 1024 (0 by the given mask, 20 filtered"),
        "{said}"
    );
    assert!(said.contains("2 dead") && said.contains("2 hot"), "{said}");
    let report = json(&out.join("report.json"));
    // Time zero fitted (the stand-in's is 1000 ps) within 5 standard
    // errors and 25 ps.
    let t0 = report["calibration"]["time_zero_ps"][0].as_f64().unwrap();
    let se = report["calibration"]["time_zero_ps"][1].as_f64().unwrap();
    assert!((t0 - 1000.0).abs() < (5.0 * se).max(25.0), "{t0} +- {se}");
    // The letter is there: the transmission correlates with the truth.
    let truth = read2(&dir.path().join("truth.npy"));
    let got = read2(&out.join("transmission.npy"));
    let r = correlation(&truth, &got);
    assert!(r > 0.6, "correlation {r}");
    // The misfit is within the noise for the model that made the cube.
    let z = said
        .split("(z = ")
        .nth(1)
        .and_then(|t| t.split(')').next())
        .and_then(|t| t.parse::<f64>().ok())
        .expect("a misfit z");
    assert!(z.abs() < 10.0, "{said}");
    let used = read2(&out.join("used_pixels.npy"));
    assert_eq!(used.iter().filter(|&&u| u == 0.0).count(), 24);
}

#[test]
fn a_camera_gain_is_measured_and_named_and_the_object_still_found() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    simulate(
        dir.path(),
        "letter:T",
        &["--seed", "8", "--photons", "3e5", "--gain", "3.8"],
    );
    let o = reconstruct(dir.path(), &out, &[]);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(said.contains("noise model: scaled Poisson"), "{said}");
    let report = json(&out.join("report.json"));
    let gain = report["noise"]["gain"].as_f64().unwrap();
    assert!((gain / 3.8 - 1.0).abs() < 0.15, "gain {gain}");
    let r = correlation(
        &read2(&dir.path().join("truth.npy")),
        &read2(&out.join("transmission.npy")),
    );
    assert!(r > 0.5, "correlation {r}");
}

#[test]
fn a_wrong_medium_is_warned_of_by_its_misfit() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    simulate(dir.path(), "letter:T", &["--seed", "9", "--photons", "5e5"]);
    // Told a quarter of the scattering, time zero fixed at the truth: no
    // transmission explains the counts.
    let o = reconstruct(
        dir.path(),
        &out,
        &[
            "--time-zero",
            "1000ps",
            "--back-mu-s-reduced",
            "18",
            "--max-iters",
            "300",
        ],
    );
    let said = text(&o);
    assert_eq!(o.status.code(), Some(4), "{said}");
    assert!(
        said.contains("warning: no transmission explains the counts"),
        "{said}"
    );
    assert!(
        said.contains("counts over prediction by time group"),
        "{said}"
    );
}

#[test]
fn fitting_the_scattering_or_the_absorption_recovers_it_from_the_cube_alone() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    simulate(
        dir.path(),
        "letter:T",
        &["--seed", "10", "--photons", "5e5"],
    );
    // Told half the scattering; fitted back from the summed time profile.
    let mut told = GEOMETRY;
    told[5] = "35.5";
    let o = reconstruct_in(dir.path(), &out, &told, &["--fit-scattering"]);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    let report = json(&out.join("report.json"));
    let mus = report["calibration"]["mu_s_reduced_per_cm"][0]
        .as_f64()
        .unwrap();
    assert!((mus / 71.0 - 1.0).abs() < 0.15, "{mus} /cm for 71: {said}");
    // The absorption alike, told half of it.
    let mut told = GEOMETRY;
    told[7] = "0.07";
    let o = reconstruct_in(dir.path(), &out, &told, &["--fit-absorption"]);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    let mua = json(&out.join("report.json"))["calibration"]["mu_a_per_cm"][0]
        .as_f64()
        .unwrap();
    assert!(
        (mua / 0.14 - 1.0).abs() < 0.15,
        "{mua} /cm for 0.14: {said}"
    );
    // Both together trade off with the time zero: refused by name.
    let o = reconstruct_in(
        dir.path(),
        &dir.path().join("both"),
        &told,
        &["--fit-absorption", "--fit-scattering"],
    );
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("the scattering and the absorption together"),
        "{}",
        text(&o)
    );
}

fn refused(dir: &Path, extra: &[&str], words: &[&str]) {
    let out = dir.join("refused");
    let o = reconstruct(dir, &out, extra);
    let said = text(&o);
    assert_eq!(o.status.code(), Some(1), "{said}");
    for w in words {
        assert!(said.contains(w), "`{w}` not in: {said}");
    }
    for name in scatterscope::embedded::OUTPUTS {
        assert!(!out.join(name).exists(), "{name} written: {said}");
    }
}

/// Writes `cube` (bins, rows, columns) as the stand-in's layout in `dir`.
fn write_cube(dir: &Path, cube: &ndarray::Array3<f64>) {
    scatterscope::embedded::simulate::write_as_lab(cube, (0.14, 0.14), dir).unwrap();
}

#[test]
fn bad_cubes_positions_and_masks_are_refused_by_file_and_field_with_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    simulate(dir.path(), "letter:T", &["--seed", "11", "--bins", "120"]);
    let cube_path = dir.path().join("cube.mat");
    let good = scatterscope::formats::mat5::read(&cube_path).unwrap();
    let dims = good.arrays[0].dims.clone();
    let with = |f: &dyn Fn(&mut Vec<f64>)| {
        let mut v = good.arrays[0].values.clone();
        f(&mut v);
        scatterscope::formats::mat5::write(&cube_path, &[("cube", &dims, &v)]).unwrap();
    };
    // NaN in the cube.
    with(&|v| v[777] = f64::NAN);
    refused(dir.path(), &[], &["cube.mat", "`cube` holds NaN at bin"]);
    // All negative.
    with(&|v| v.iter_mut().for_each(|x| *x = -x.abs() - 1.0));
    refused(dir.path(), &[], &["cube.mat", "no positive value"]);
    with(&|_| {});
    // Positions that do not match: a 16 x 16 grid for the 32 x 32 cube.
    let small = dir.path().join("small");
    std::fs::create_dir_all(&small).unwrap();
    write_cube(
        &small,
        &ndarray::Array3::from_shape_fn((4, 16, 16), |(k, i, j)| {
            ((k * 7 + i * 3 + j * 5) % 11) as f64 + 1.0
        }),
    );
    let positions = dir.path().join("positions.mat");
    let kept = std::fs::read(&positions).unwrap();
    std::fs::copy(small.join("positions.mat"), &positions).unwrap();
    refused(dir.path(), &[], &["positions.mat", "32 x 32 pixels"]);
    std::fs::write(&positions, kept).unwrap();
    // Too few bins to measure the variance (the small cube: 4 bins).
    refused(&small, &[], &["cube.mat", "4 time bins", "at least 5"]);
    // Past the memory budget: refused before the work, by what it needed.
    refused(
        dir.path(),
        &["--memory-limit", "1mb"],
        &["reconstructing a cube of 120 bins x 32 x 32 pixels"],
    );
    // A mask of every pixel.
    let mask = dir.path().join("mask.npy");
    ndarray_npy::write_npy(&mask, &Array2::<f64>::ones((32, 32))).unwrap();
    refused(
        dir.path(),
        &["--mask", s(&mask)],
        &["mask.npy", "leaves out every pixel"],
    );
    // A mask of the wrong shape.
    ndarray_npy::write_npy(&mask, &Array2::<f64>::zeros((31, 32))).unwrap();
    refused(dir.path(), &["--mask", s(&mask)], &["mask.npy", "[31, 32]"]);
}

#[test]
#[ignore = "needs scipy under target/pydeps (scripts/fetch_python_deps.sh)"]
fn matlab_level_5_files_agree_with_scipy_both_ways() {
    let dir = tempfile::tempdir().unwrap();
    let theirs = dir.path().join("theirs");
    std::fs::create_dir_all(&theirs).unwrap();
    // SciPy writes: compressed and plain, signed 16-bit, single and
    // double, a logical mask, a cell and a string (skipped by name); each
    // array also as .npy (numpy's writer) for the comparison.
    pydeps::python(
        r#"
import sys, numpy as np, scipy.io as sio
d = sys.argv[1]
rng = np.random.default_rng(5)
cube = rng.integers(-40, 300, size=(6, 7, 9)).astype(np.int16)
arrays = {"cube": cube, "single": rng.random((3, 4)).astype(np.float32),
          "double": rng.standard_normal((5, 2)), "mask": rng.random((6, 7)) > 0.5}
for compress in (True, False):
    name = "compressed.mat" if compress else "plain.mat"
    sio.savemat(f"{d}/{name}", {**arrays, "notes": "a string", "cells": np.array([[1, "a"]], dtype=object)},
                do_compression=compress)
for k, v in arrays.items():
    np.save(f"{d}/{k}.npy", v.astype(np.float64))
"#,
        &[s(&theirs)],
    );
    for file in ["compressed.mat", "plain.mat"] {
        let (arrays, skipped) =
            scatterscope::formats::lab_array::read_all(&theirs.join(file)).unwrap();
        assert!(
            skipped.iter().any(|n| n.starts_with("cells")),
            "{skipped:?}"
        );
        assert!(
            skipped.iter().any(|n| n.starts_with("notes")),
            "{skipped:?}"
        );
        for name in ["cube", "single", "double", "mask"] {
            let ours = arrays.iter().find(|a| a.name == name).unwrap();
            let want =
                scatterscope::formats::npy::read_numbers(&theirs.join(format!("{name}.npy")))
                    .unwrap();
            assert_eq!(ours.values.shape(), want.shape(), "{file} {name}");
            assert_eq!(ours.values, want, "{file} {name}");
        }
    }
    // Ours, read by SciPy: the stand-in's cube against the same values
    // written by ndarray-npy.
    simulate(dir.path(), "letter:T", &["--seed", "12", "--bins", "40"]);
    let cube = scatterscope::formats::lab_array::read_all(&dir.path().join("cube.mat"))
        .unwrap()
        .0
        .remove(0)
        .values;
    ndarray_npy::write_npy(dir.path().join("cube.npy"), &cube).unwrap();
    let said = pydeps::python(
        r#"
import sys, numpy as np, scipy.io as sio
m = sio.loadmat(sys.argv[1] + "/cube.mat")
p = sio.loadmat(sys.argv[1] + "/positions.mat")
want = np.load(sys.argv[1] + "/cube.npy")
assert m["cube"].shape == want.shape == (32, 32, 40), (m["cube"].shape, want.shape)
assert np.array_equal(m["cube"], want)
assert p["x"].shape == (32, 32) and np.allclose(np.diff(p["x"], axis=1), 1.4)
assert np.allclose(np.diff(p["y"], axis=0), 1.4)
print("agreed")
"#,
        &[s(dir.path())],
    );
    assert!(said.contains("agreed"));
}

#[test]
fn an_instrument_response_from_a_csv_is_taken_as_given_and_moves_the_time_zero_by_its_delay() {
    let dir = tempfile::tempdir().unwrap();
    simulate(
        dir.path(),
        "letter:T",
        &["--seed", "13", "--photons", "5e5"],
    );
    let plain = dir.path().join("plain");
    let o = reconstruct(dir.path(), &plain, &["--iterations", "20"]);
    assert!(o.status.success(), "{}", text(&o));
    // A response that delays every photon by 200-210 ps (a header line,
    // then one number per line; 20 bins of 10 ps at 0, then one at 1).
    let irf = dir.path().join("irf.csv");
    let mut csv = String::from("delay_bin,weight\n");
    for k in 0..20 {
        csv.push_str(&format!("{k},0\n"));
    }
    csv.push_str("20,1\n");
    std::fs::write(&irf, csv).unwrap();
    let delayed = dir.path().join("delayed");
    let o = reconstruct(
        dir.path(),
        &delayed,
        &[
            "--iterations",
            "20",
            "--irf",
            s(&irf),
            "--irf-bin-width",
            "10ps",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let t0 = |d: &Path| {
        json(&d.join("report.json"))["calibration"]["time_zero_ps"][0]
            .as_f64()
            .unwrap()
    };
    let shift = t0(&plain) - t0(&delayed);
    assert!(
        (shift - 205.0).abs() < 10.0,
        "time zero moved by {shift} ps"
    );
}

#[test]
fn a_cube_without_dark_bins_needs_its_subtracted_background_stated_as_a_level_or_a_map() {
    let dir = tempfile::tempdir().unwrap();
    // The camera's window opens 1 ns after the pulse: the light arrives
    // within a few bins.
    simulate(
        dir.path(),
        "letter:T",
        &[
            "--seed",
            "14",
            "--time-zero=-1500ps",
            "--bins",
            "120",
            "--residual",
            "0,0",
        ],
    );
    refused(dir.path(), &[], &["cube.mat", "--subtracted-background"]);
    let out = dir.path().join("level");
    let o = reconstruct(dir.path(), &out, &["--subtracted-background", "20"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("from the stated subtracted background"),
        "{}",
        text(&o)
    );
    let map = dir.path().join("background.npy");
    ndarray_npy::write_npy(&map, &Array2::<f64>::from_elem((32, 32), 20.0)).unwrap();
    let out = dir.path().join("map");
    let o = reconstruct(dir.path(), &out, &["--subtracted-background", s(&map)]);
    assert!(o.status.success(), "{}", text(&o));
    let r = correlation(
        &read2(&dir.path().join("truth.npy")),
        &read2(&out.join("transmission.npy")),
    );
    assert!(r > 0.5, "correlation {r}");
}

#[test]
fn rectangular_pixels_are_read_from_one_positions_array_and_said() {
    let dir = tempfile::tempdir().unwrap();
    simulate(dir.path(), "letter:T", &["--seed", "15", "--bins", "120"]);
    // One (rows, cols, 2) array in cm: x along the columns 0.14 cm apart,
    // y along the rows 0.145 cm apart (3.6 % taller).
    let positions = ndarray::Array3::from_shape_fn((32, 32, 2), |(i, j, c)| {
        if c == 0 {
            0.14 * j as f64
        } else {
            0.145 * i as f64
        }
    });
    let file = dir.path().join("centres.npy");
    ndarray_npy::write_npy(&file, &positions).unwrap();
    let out = dir.path().join("out");
    let cube = dir.path().join("cube.mat");
    let mut args = vec![
        "embedded",
        s(&cube),
        "--positions",
        s(&file),
        "--positions-unit",
        "1cm",
        "--bin-width",
        "50ps",
        "--out",
        s(&out),
    ];
    args.extend(GEOMETRY);
    let o = run(&args);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(
        said.contains("pixels of 0.1400 x 0.1450 cm (+3.6 % in y)"),
        "{said}"
    );
    let pitch = &json(&out.join("report.json"))["pitch_cm"];
    assert!((pitch[0].as_f64().unwrap() - 0.14).abs() < 1e-12);
    assert!((pitch[1].as_f64().unwrap() - 0.145).abs() < 1e-12);
    // Without a unit the positions are refused by name.
    let o = run(&args
        .iter()
        .filter(|a| **a != "--positions-unit" && **a != "1cm")
        .copied()
        .collect::<Vec<_>>());
    assert!(text(&o).contains("--positions-unit"), "{}", text(&o));
}
