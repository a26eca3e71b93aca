"""The Python package against the command line on the same input, round
trips through numpy, the shared PicoQuant samples against ptufile, and
errors as exceptions with the library's message.

The command is $SCATTERSCOPE_CLI, else this repository's
target/release/scatterscope, built with cargo the first time it is missing
(a fresh clone: `pip install ./python` needs the Rust toolchain anyway).
Tests that need ../shared or ptufile skip with the reason when they are
absent (CI has both).
"""

import json
import os
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import scatterscope
from scatterscope import ScatterscopeError

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared" / "data"
SAMPLES = SHARED / "picoquant-sample-data"


def cli_path() -> Path:
    env = os.environ.get("SCATTERSCOPE_CLI")
    if env:
        return Path(env)
    p = REPO / "target" / "release" / "scatterscope"
    if not p.exists():
        built = subprocess.run(
            ["cargo", "build", "--release", "--bin", "scatterscope"], cwd=REPO, capture_output=True, text=True
        )
        assert built.returncode == 0, "building the command for the comparisons failed:\n" + built.stderr
    return p


def cli(*args: str) -> str:
    out = subprocess.run([str(cli_path()), *args], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
    return out.stdout


def need_samples() -> None:
    if not SAMPLES.exists():
        pytest.skip(f"needs {SAMPLES} (the shared PicoQuant samples)")


def mock_ptu(tmp_path: Path) -> Path:
    """A PTU of a mock acquisition: 7 x 7 pixels recorded as tags, then
    converted (pixel = input channel)."""
    tags = tmp_path / "m.sstags"
    cli("acquire", "--size", "7", "--duration", "300ms", "--tags", str(tags), "--out", str(tmp_path / "acq"))
    ptu = tmp_path / "m.ptu"
    cli("convert", str(tags), "--out", str(ptu))
    return ptu


def test_bin_file_equals_the_command_bin_for_bin(tmp_path):
    ptu = mock_ptu(tmp_path)
    cli("bin", str(ptu), "--pixels", "channel", "--bin-width", "8ps", "--out", str(tmp_path / "bin"))
    ours = scatterscope.bin_file(ptu, pixels="channel", bin_width_ps=8.0)
    theirs, meta = scatterscope.load_stack(tmp_path / "bin" / "stack.exr")
    assert len(ours["stacks"]) == 1
    np.testing.assert_array_equal(ours["stacks"][0], theirs)
    assert ours["meta"][0] == meta
    ledger = ours["ledger"]
    assert ledger["photons"] == ledger["binned"] + ledger["outside_window"] + ledger["other_channel"] + ledger[
        "outside_region"
    ]
    assert ours["stacks"][0].sum() == ledger["binned"] > 10_000


def test_becker_hickl_spc_bins_as_the_command_with_the_module_and_unit_given(tmp_path):
    """A .spc file of the SPC-600/630 256-channel layout (B&H's header:
    ADC bits 0-7, macro time 8-24, routing 25-27, INVALID bit 31): the
    photons' micro times are 255 - ADC; an invalid record is dropped."""
    records = [(1 << 31) | (3 << 27) | 500]
    photons = [(200, 5), (10, 1), (200, 5), (255, 0)]
    for i, (adc, routing) in enumerate(photons):
        records.append(adc | ((i * 100) << 8) | (routing << 25))
    records.append((1 << 31) | 77)
    spc = tmp_path / "run.spc"
    spc.write_bytes(np.array(records, dtype="<u4").tobytes())
    ours = scatterscope.bin_file(spc, pixels="channel", spc_module="spc-600-256", micro_unit_ps=20.0, dtype="uint32")
    stack = ours["stacks"][0]
    assert stack.shape == (256, 1, 6)
    assert stack[55, 0, 5] == 2 and stack[245, 0, 1] == 1 and stack[0, 0, 0] == 1
    assert ours["ledger"]["photons"] == 4 and ours["meta"][0]["bin_width_ps"] == 20.0
    cli("bin", str(spc), "--pixels", "channel", "--spc-module", "spc-600-256", "--micro-unit", "20ps",
        "--out", str(tmp_path / "bin"))
    theirs, _ = scatterscope.load_stack(tmp_path / "bin" / "stack.exr")
    np.testing.assert_array_equal(stack, theirs)
    with pytest.raises(ScatterscopeError, match="spc_module `spc-999`"):
        scatterscope.bin_file(spc, spc_module="spc-999")


def test_bin_file_gives_the_counts_in_the_dtype_asked_for(tmp_path):
    ptu = mock_ptu(tmp_path)
    floats = scatterscope.bin_file(ptu, pixels="channel")["stacks"][0]
    assert floats.dtype == np.float32
    for dtype in ["uint32", "uint16", "float32"]:
        counts = scatterscope.bin_file(ptu, pixels="channel", dtype=dtype)["stacks"][0]
        assert counts.dtype == np.dtype(dtype)
        np.testing.assert_array_equal(counts, floats)
    # Every photon in one bin of one pixel: more than uint16 holds.
    one = scatterscope.bin_file(ptu, pixels="single", bins=1, bin_width_ps=1e5, dtype="uint32")["stacks"][0]
    assert one.shape == (1, 1, 1) and one[0, 0, 0] > 65_535
    with pytest.raises(ScatterscopeError, match=f"holds {one[0, 0, 0]} photons in one bin, more than uint16"):
        scatterscope.bin_file(ptu, pixels="single", bins=1, bin_width_ps=1e5, dtype="uint16")
    with pytest.raises(ScatterscopeError, match='dtype "int8" is not one of float32, uint16, uint32'):
        scatterscope.bin_file(ptu, dtype="int8")


def test_read_tags_agrees_with_bin_file(tmp_path):
    ptu = mock_ptu(tmp_path)
    tags = scatterscope.read_tags(ptu)
    assert tags["channel"].dtype == np.uint16 and tags["macro_time"].dtype == np.uint64
    assert len(tags["channel"]) == len(tags["macro_time"]) == len(tags["micro_time"])
    assert np.all(np.diff(tags["macro_time"].astype(np.int64)) >= 0)
    binned = scatterscope.bin_file(ptu, pixels="channel")
    assert binned["ledger"]["photons"] == len(tags["channel"])
    # The stack's time profile is the histogram of the micro times.
    profile = binned["stacks"][0].sum(axis=(1, 2))
    hist = np.bincount(tags["micro_time"], minlength=len(profile))
    np.testing.assert_array_equal(profile, hist[: len(profile)])


@pytest.mark.parametrize("name", ["hydraharp/v20_t3.ptu", "hydraharp/v10_t3.ptu"])
def test_shared_t3_samples_bin_as_ptufile_histograms_them(name):
    need_samples()
    ptufile = pytest.importorskip("ptufile", reason="needs ptufile (pip install ptufile)")
    path = SAMPLES / name
    ours = scatterscope.bin_file(path, pixels="channel")["stacks"][0]
    with ptufile.PtuFile(path) as ptu:
        records = ptu.decode_records()
        theirs = ptu.decode_histogram(dtype=np.uint32)
    photons = records[records["channel"] >= 0]
    # ptufile: (channels, micro-time bins); ours: (bins, 1, channels).
    assert ours.shape[1] == 1
    for ch in range(theirs.shape[0]):
        mine = ours[:, 0, ch] if ch < ours.shape[2] else np.zeros(ours.shape[0])
        n = min(len(mine), theirs.shape[1])
        np.testing.assert_array_equal(mine[:n], theirs[ch, :n], err_msg=f"{name} channel {ch}")
        assert mine[n:].sum() == 0 and theirs[ch, n:].sum() == 0
    assert ours.sum() == len(photons)
    tags = scatterscope.read_tags(path)
    np.testing.assert_array_equal(tags["channel"], photons["channel"])
    np.testing.assert_array_equal(tags["micro_time"], photons["dtime"])
    np.testing.assert_array_equal(tags["macro_time"], photons["time"])


@pytest.mark.parametrize("ext", [".npy", ".exr"])
def test_stacks_round_trip_through_numpy_unchanged(tmp_path, ext):
    sim = scatterscope.simulate("disks", seed=4, size=32)
    path = tmp_path / f"counts{ext}"
    scatterscope.save_stack(path, sim["counts"], sim["meta"])
    data, meta = scatterscope.load_stack(path)
    np.testing.assert_array_equal(data, sim["counts"])
    assert data.dtype == np.float32
    assert meta == sim["meta"]


def test_simulate_equals_the_command(tmp_path):
    cli("simulate", "--scene", "text", "--size", "48", "--seed", "7", "--out", str(tmp_path))
    sim = scatterscope.simulate("text", seed=7, size=48)
    counts, meta = scatterscope.load_stack(tmp_path / "counts.exr")
    np.testing.assert_array_equal(sim["counts"], counts)
    assert sim["meta"] == meta
    expected, _ = scatterscope.load_stack(tmp_path / "expected.exr")
    np.testing.assert_array_equal(sim["expected"], expected)


def test_an_unknown_scene_name_lists_the_built_in_ones():
    with pytest.raises(Exception) as e:
        scatterscope.simulate("usa", size=32)
    assert "usa: no such file, and not a built-in scene (usaf, star, text, disks)" in str(e.value)


def test_simulate_an_array_matches_the_same_scene_rendered():
    scene = scatterscope.simulate("disks", seed=2, size=32)
    again = scatterscope.simulate(scene["truth"], seed=2)
    np.testing.assert_array_equal(again["expected"], scene["expected"])
    np.testing.assert_array_equal(again["counts"], scene["counts"])


def test_psf_kernels_equal_the_command(tmp_path):
    cli("psf", "--size", "32", "--out", str(tmp_path))
    k = scatterscope.psf_kernels(size=32)
    theirs, meta = scatterscope.load_stack(tmp_path / "psf.exr")
    np.testing.assert_array_equal(k["kernels"].astype(np.float32), theirs)
    kept = [b for b in k["bins"] if b["kept"]]
    assert len(kept) == k["kernels"].shape[0] == theirs.shape[0]
    assert k["setup"]["sensor"]["width_px"] == 32


@pytest.mark.parametrize("method,extra", [("rl-stack", []), ("pnp", ["--denoiser", "tv"])])
def test_reconstruct_equals_the_command_bit_for_bit(tmp_path, method, extra):
    cli("simulate", "--scene", "usaf", "--size", "48", "--seed", "1", "--out", str(tmp_path / "sim"))
    counts, meta = scatterscope.load_stack(tmp_path / "sim" / "counts.exr")
    cli("reconstruct", str(tmp_path / "sim" / "counts.exr"), "--method", method, *extra, "--out", str(tmp_path / "rec"))
    kwargs = {"denoiser": "tv"} if extra else {}
    image, trace, notes = scatterscope.reconstruct(counts, meta, method=method, **kwargs)
    theirs = scatterscope.load_image(tmp_path / "rec" / "reconstruction.exr")
    # The EXR holds float32: ours rounded the same way, bit for bit.
    np.testing.assert_array_equal(image.astype(np.float32).astype(np.float64), theirs)
    record = json.loads((tmp_path / "rec" / "trace.json").read_text())
    assert trace["method"] == record["method"]
    assert len(trace["rows"]["iteration"]) == len(record["rows"])
    np.testing.assert_array_equal(trace["rows"]["iteration"], [r["iteration"] for r in record["rows"]])
    assert notes[-len(record["notes"]) :] == record["notes"]


def test_learned_weights_from_a_file_equal_the_command(tmp_path):
    # The paper's pitch (50 cm over 256 pixels): inside the network's
    # trained blur widths, so the network runs.
    cli("simulate", "--scene", "disks", "--size", "32", "--fov", "6.25", "--seed", "4", "--out", str(tmp_path / "sim"))
    counts, meta = scatterscope.load_stack(tmp_path / "sim" / "counts.exr")
    small = REPO / "tests" / "fixtures" / "learned" / "small.safetensors"
    cli(
        "reconstruct", str(tmp_path / "sim" / "counts.exr"), "--method", "learned",
        "--learned-weights", str(small), "--out", str(tmp_path / "rec"),
    )
    image, _, notes = scatterscope.reconstruct(counts, meta, method="learned", learned_weights=small)
    theirs = scatterscope.load_image(tmp_path / "rec" / "reconstruction.exr")
    np.testing.assert_array_equal(image.astype(np.float32).astype(np.float64), theirs)
    embedded, _, _ = scatterscope.reconstruct(counts, meta, method="learned")
    assert not np.array_equal(image, embedded)
    assert any("outside what the network was trained on" in n for n in notes)
    cut = tmp_path / "cut.safetensors"
    cut.write_bytes(small.read_bytes()[:100])
    with pytest.raises(ScatterscopeError, match="cut.safetensors"):
        scatterscope.reconstruct(counts, meta, method="learned", learned_weights=cut)


def test_calibrate_slab_equals_the_command_from_files_and_from_arrays(tmp_path):
    cal = SHARED / "cdt-calibration"
    if not cal.exists():
        pytest.skip(f"needs {cal} (the shared transmittance captures)")
    out = cli(
        "calibrate-slab", "--bin-width", "8ps", "--refractive-index", "1.12", "--parts", "none",
        "--irf-from", str(cal / "capture_direct.mat"),
        "--capture", f"{cal / 'capture_3_0_inch.mat'}=3in",
        "--predict", f"{cal / 'capture_3_5_inch.mat'}=3.5in",
        "--out", str(tmp_path / "cli"),
    )
    files = scatterscope.calibrate_slab(
        cal / "capture_direct.mat", [(cal / "capture_3_0_inch.mat", 7.62)], 1.12,
        predict=[(cal / "capture_3_5_inch.mat", 8.89)], bin_width_ps=8.0,
    )
    assert files["material_toml"] == (tmp_path / "cli" / "material.toml").read_text()
    for line in files["lines"]:
        if "s)" not in line:  # wall times differ
            assert line in out, line
    assert 100 < files["mu_s_reduced_per_cm"]["value"] * 100 < 1000  # per metre, foam
    h5py = pytest.importorskip("h5py", reason="needs h5py for the arrays")

    def counts(name):
        with h5py.File(cal / name, "r") as f:
            return np.asarray(f["out"][()], dtype=np.float64).ravel()

    # The old names (mu_s' as an argument and a fit name, bin_ps) still work, and warn.
    with pytest.warns(FutureWarning) as warned:
        arrays = scatterscope.calibrate_slab(
            counts("capture_direct.mat"), [(counts("capture_3_0_inch.mat"), 7.62)], 1.12,
            predict=[(counts("capture_3_5_inch.mat"), 8.89)], bin_ps=8.0, mu_s=5.0, fit=("mu_a", "mu_s"),
        )
    said = " | ".join(str(w.message) for w in warned)
    for note in ("mu_s is now mu_s_reduced", "bin_ps is now bin_width_ps", "fit name mu_s is now mu_s_reduced"):
        assert note in said, said
    for key in ("mu_a_per_cm", "mu_s_reduced_per_cm", "chi2_per_dof"):
        assert arrays[key] == files[key], key


def test_acquire_mock_accounts_for_every_photon(tmp_path):
    done = scatterscope.acquire_mock(0.3, tmp_path / "acq", scene="star", size=32, seed=3)
    stack = done["stack"]
    assert stack.shape[1:] == (32, 32)
    acc = done["record"]["ledger"]
    assert acc["photons"] == acc["binned"] + acc["outside_window"] + acc["outside_region"] + acc["other_channel"]
    assert stack.sum() == acc["binned"] > 10_000
    assert (tmp_path / "acq" / "stack.exr").exists()
    assert any("photons" in line for line in done["summary"])


def cli_error(*args: str) -> str:
    """The command's error message (its stderr after "error: ") for args
    it refuses."""
    out = subprocess.run([str(cli_path()), *args], capture_output=True, text=True)
    assert out.returncode != 0, out.stdout
    return out.stderr.strip().removeprefix("error: ")


def standin_library() -> Path:
    """The stand-in PicoQuant library (built with the workspace; built here
    the first time it is missing)."""
    name = "libscatterscope_mock_picoquant.so"
    for d in ("debug", "release"):
        p = REPO / "target" / d / name
        if p.exists():
            return p
    built = subprocess.run(
        ["cargo", "build", "-p", "scatterscope-mock-picoquant"], cwd=REPO, capture_output=True, text=True
    )
    assert built.returncode == 0, "building the stand-in library failed:\n" + built.stderr
    return REPO / "target" / "debug" / name


def test_acquire_from_the_mock_equals_the_commands_run(tmp_path):
    # The mock unpaced to a photon count: the same request gives the same
    # photons, so the stacks and ledgers agree exactly.
    flags = {"size": 16, "unpaced": True, "max_photons": 60_000, "seed": 5}
    cli("acquire", "--device", "mock", "--size", "16", "--unpaced", "--max-photons", "60000", "--seed", "5",
        "--duration", "0", "--out", str(tmp_path / "cli"))
    done = scatterscope.acquire("mock", tmp_path / "py", 0, **flags)
    data, meta = scatterscope.load_stack(tmp_path / "cli" / "stack.exr")
    assert np.array_equal(done["stack"], data)
    record = json.loads((tmp_path / "cli" / "acquisition.json").read_text())
    for field in ("records", "photons", "binned", "outside_window", "lost_in_device"):
        assert done["record"]["ledger"][field] == record["ledger"][field], field
    assert done["meta"]["bin_starts_ps"] == meta["bin_starts_ps"]
    assert sorted(p.name for p in (tmp_path / "py").iterdir()) == sorted(p.name for p in (tmp_path / "cli").iterdir())


def test_acquire_refuses_what_the_command_refuses_with_its_words(tmp_path):
    out = str(tmp_path / "x")
    cases = [
        (["--device", "mock", "--sync-level", "-50"], dict(device="mock", sync_level_mv=-50)),
        (["--device", "mock", "--speed", "4"], dict(device="mock", speed=4.0)),
        (["--device", "picoquant", "--vendor-lib", str(standin_library()), "--t3-offset", "10500ps"],
         dict(device="picoquant", vendor_lib=str(standin_library()), t3_offset_ps=10500.0)),
    ]
    for flags, kwargs in cases:
        theirs = cli_error("acquire", *flags, "--out", out)
        device = kwargs.pop("device")
        with pytest.raises(ScatterscopeError) as raised:
            scatterscope.acquire(device, out, 0.1, **kwargs)
        assert str(raised.value) == theirs
    assert not (tmp_path / "x").exists()


def test_acquire_from_the_standin_library_with_the_commands_defaults(tmp_path):
    lib = str(standin_library())
    cli("acquire", "--device", "picoquant:hydraharp", "--vendor-lib", lib, "--duration", "200ms",
        "--out", str(tmp_path / "cli"))
    done = scatterscope.acquire("picoquant:hydraharp", tmp_path / "py", 0.2, vendor_lib=lib)
    data, meta = scatterscope.load_stack(tmp_path / "cli" / "stack.exr")
    # The same window (one sync period at the device's unit), a PTU by
    # default, every record binned or accounted for.
    assert done["stack"].shape == data.shape
    assert done["meta"]["bin_starts_ps"] == meta["bin_starts_ps"]
    for d in ("cli", "py"):
        assert (tmp_path / d / "acquisition.ptu").stat().st_size > 0
    ledger = done["record"]["ledger"]
    assert ledger["photons"] > 0 and done["stack"].sum() == ledger["binned"]
    record = json.loads((tmp_path / "cli" / "acquisition.json").read_text())
    assert done["record"]["device"] == record["device"]


def test_bad_input_raises_with_the_librarys_message(tmp_path):
    sim = scatterscope.simulate("disks", seed=0, size=16)
    bad = sim["counts"].copy()
    bad[0, 3, 4] = np.nan
    with pytest.raises(ScatterscopeError, match="NaN|not finite|finite"):
        scatterscope.reconstruct(bad, sim["meta"], method="rl-stack")
    with pytest.raises(ScatterscopeError, match="shape"):
        scatterscope.reconstruct(np.zeros((4, 4)), None)
    with pytest.raises(ScatterscopeError, match="missing.ptu"):
        scatterscope.bin_file(tmp_path / "missing.ptu")
    with pytest.raises(ScatterscopeError, match="No such file"):
        scatterscope.load_stack(tmp_path / "none.exr")
    with pytest.raises(KeyError, match="thickness_m"):
        scatterscope.psf_kernels(thickness_m=0.03)
    with pytest.raises(ScatterscopeError, match="method `magic`"):
        scatterscope.reconstruct(sim["counts"], sim["meta"], method="magic")
    with pytest.raises(ScatterscopeError, match="mu_a"):
        scatterscope.psf_kernels(mu_a=-1.0)
    wrong = np.zeros((3, 16, 16), dtype=np.float32)
    with pytest.raises(ScatterscopeError):
        scatterscope.save_stack(tmp_path / "w.exr", wrong, sim["meta"])


def test_ctrl_c_stops_a_reconstruction():
    sim = scatterscope.simulate("usaf", seed=0, size=128)
    timer = threading.Timer(1.0, lambda: os.kill(os.getpid(), signal.SIGINT))
    started = time.monotonic()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        scatterscope.reconstruct(sim["counts"], sim["meta"], method="pnp", denoiser="tv", max_iters=100000)
    assert time.monotonic() - started < 30


def test_help_reads_well():
    doc = scatterscope.__doc__
    assert "numpy in and out" in doc
    for name in scatterscope.__all__:
        obj = getattr(scatterscope, name)
        if callable(obj):
            assert obj.__doc__ and len(obj.__doc__) > 40, name


def _load_missing(path):
    return scatterscope.load_stack(path)


def test_errors_cross_a_process_boundary_with_their_message(tmp_path):
    import concurrent.futures
    import pickle

    missing = str(tmp_path / "missing.exr")
    with pytest.raises(ScatterscopeError) as local:
        scatterscope.load_stack(missing)
    assert type(local.value).__module__ == "scatterscope"
    back = pickle.loads(pickle.dumps(local.value))
    assert type(back) is ScatterscopeError and str(back) == str(local.value)
    with concurrent.futures.ProcessPoolExecutor(max_workers=1) as pool:
        with pytest.raises(ScatterscopeError) as remote:
            pool.submit(_load_missing, missing).result()
    assert "missing.exr" in str(remote.value)


@pytest.mark.parametrize("ext", ["exr", "npy"])
def test_counts_above_2_to_the_24_round_trip_exactly(tmp_path, ext):
    meta = json.loads(scatterscope._native.measured_meta(0.0, 10.0, 2, "exact"))
    counts = np.array([[[2**24 + 1, 3]], [[2**31 + 7, 0]]], dtype=np.uint32)
    path = tmp_path / f"big.{ext}"
    scatterscope.save_stack(path, counts, meta)
    back, _ = scatterscope.load_stack(path)
    assert back.dtype == np.uint32
    np.testing.assert_array_equal(back, counts)
    assert int(back.astype(np.uint64).sum()) == int(counts.astype(np.uint64).sum())


def test_decay_maps_equal_the_command_lifetime(tmp_path):
    tags = tmp_path / "run.sstags"
    cli("acquire", "--device", "mock", "--size", "16", "--fov", "3cm", "--tags", str(tags), "--out", str(tmp_path / "acq"))
    cli("lifetime", str(tags), "--min-photons", "5", "--no-figures", "--out", str(tmp_path / "lt"))
    binned = scatterscope.bin_file(tags, dtype="uint32")
    maps = scatterscope.decay_maps(binned["stacks"][0], binned["meta"][0], min_photons=5)
    side = json.loads((tmp_path / "lt" / "maps.json").read_text())
    ours = np.load(tmp_path / "lt" / "maps.npy")
    by_name = dict(zip(side["channels"], ours))
    assert maps["frequency_hz"] == side["laser_frequency_hz"]
    assert maps["onset_ps"] == side["onset_ps"]
    np.testing.assert_array_equal(by_name["photons"], maps["photons"].astype(np.float32))
    np.testing.assert_array_equal(by_name["g harmonic 1"], maps["g1"].astype(np.float32))
    np.testing.assert_array_equal(by_name["fast lifetime (ps)"], maps["fast_lifetime_ps"].astype(np.float32))


def test_decay_maps_mask_and_refuse_with_the_librarys_words():
    counts = np.zeros((4, 2, 2), np.uint16)
    counts[1, 0, 0], counts[2, 0, 0] = 50, 30
    meta = {"bin_starts_ps": [0.0, 10.0, 20.0, 30.0], "bin_width_ps": 10.0, "laser_frequency_hz": 80e6}
    maps = scatterscope.decay_maps(counts, meta)
    assert maps["mask"].sum() == 3 and np.isnan(maps["mean_time_ps"][maps["mask"]]).all()
    assert any("3 of 4 pixels masked" in n for n in maps["notes"])
    with pytest.raises(ScatterscopeError, match="states no laser frequency"):
        scatterscope.decay_maps(counts, {"bin_starts_ps": meta["bin_starts_ps"], "bin_width_ps": 10.0})
    bad = counts.astype(np.float32)
    bad[0, 1, 1] = np.nan
    with pytest.raises(ScatterscopeError, match="bin 0, row 1, column 1 holds NaN"):
        scatterscope.decay_maps(bad, meta)


def test_fit_lifetimes_equal_the_command_fit(tmp_path):
    tags = tmp_path / "run.sstags"
    cli("acquire", "--device", "mock", "--size", "16", "--fov", "3cm", "--tags", str(tags), "--out", str(tmp_path / "acq"))
    cli("fit", str(tags), "--bin-width", "100ps", "--bins", "125", "--irf", "gaussian", "--min-photons", "20",
        "--no-figures", "--out", str(tmp_path / "fit"))
    binned = scatterscope.bin_file(tags, bin_width_ps=100.0, bins=125, dtype="uint32")
    maps = scatterscope.fit_lifetimes(binned["stacks"][0], binned["meta"][0], irf="gaussian", min_photons=20)
    side = json.loads((tmp_path / "fit" / "fit.json").read_text())
    ours = np.load(tmp_path / "fit" / "fit.npy")
    # The IRF the fit used, as numpy reads it: unit sum on the stack's bins.
    irf = np.load(tmp_path / "fit" / "fit_irf.npy")
    assert irf.shape == (125,) and irf.dtype == np.float64 and abs(irf.sum() - 1.0) < 1e-9
    assert side["summed_values"][0].startswith("tau1 = ")
    by_name = dict(zip(side["channels"], ours))
    np.testing.assert_array_equal(by_name["tau1 (ps)"], maps["tau1_ps"].astype(np.float32))
    np.testing.assert_array_equal(by_name["mask"] > 0.5, maps["mask"])
    assert not np.isnan(maps["tau1_ps"][~maps["mask"]]).any()
    assert np.isnan(maps["tau1_ps"][maps["mask"]]).all()
    with pytest.raises(ScatterscopeError, match="components 4"):
        scatterscope.fit_lifetimes(binned["stacks"][0], binned["meta"][0], components=4)
    with pytest.raises(ScatterscopeError, match="holds no photon"):
        scatterscope.fit_lifetimes(binned["stacks"][0], binned["meta"][0], irf=np.zeros(125))
    # Issue 89: arguments of the wrong kind are refused by name.
    stack, meta = binned["stacks"][0], binned["meta"][0]
    for kwargs, words in [
        (dict(counts=stack.tolist(), meta=meta), "must be a numpy array"),
        (dict(counts=stack, meta=None), "meta must be the stack's metadata"),
        (dict(counts=stack, meta=meta, components=2.7), "components 2.7"),
        (dict(counts=stack, meta=meta, window="0:100"), "window '0:100'"),
        (dict(counts=stack.astype(np.float32) + 0.5, meta=meta), "give whole photon counts"),
    ]:
        with pytest.raises(ScatterscopeError, match=words):
            scatterscope.fit_lifetimes(**kwargs)
    # A float32 stack of whole counts (bin_file's other dtype) fits as its
    # uint32 copy.
    as_float = scatterscope.fit_lifetimes(stack.astype(np.float32), meta, irf="gaussian", min_photons=20)
    np.testing.assert_array_equal(as_float["tau1_ps"], maps["tau1_ps"])


def test_reconstruct_embedded_equals_the_command_and_names_its_noise_model(tmp_path):
    """A stand-in cube as a lab publishes it (MATLAB level 5, rows x
    columns x bins, a background subtracted), read with load_array: the
    array function and the command on the same cube give the same
    transmission and notes."""
    geometry = ["--front-thickness", "2.5cm", "--back-thickness", "2.5cm", "--mu-s-reduced", "71",
                "--mu-a", "0.14", "--index", "1", "--beam", "6cm"]
    cli("simulate-embedded", "--target", "letter:L", "--pixels", "16", "--pitch", "2.8mm", "--bins", "100",
        "--bad-pixels", "4,1,1", "--seed", "4", *geometry, "--out", str(tmp_path / "sim"))
    cube = scatterscope.load_array(tmp_path / "sim" / "cube.mat")
    assert cube.shape == (16, 16, 100)
    cube = np.transpose(cube, (2, 0, 1))
    trans, beam, used, report = scatterscope.reconstruct_embedded(
        cube, (0.28, 0.28), 50.0, front_thickness_cm=2.5, back_thickness_cm=2.5, mu_s_reduced=71.0,
        mu_a=0.14, refractive_index=1.0, beam="6cm")
    out = cli(
        "embedded", str(tmp_path / "sim" / "cube.mat"), "--pitch", "2.8mm", "--bin-width", "50ps",
        *geometry, "--out", str(tmp_path / "cli"),
    )
    assert report["noise"]["kind"] == "poisson_less_background"
    assert "noise model: Poisson less a subtracted background" in out
    np.testing.assert_allclose(trans, np.load(tmp_path / "cli" / "transmission.npy"), rtol=1e-5, atol=1e-6)
    assert used.shape == (16, 16) and (~used).sum() == 6
    for note in report["notes"]:
        assert note in out, note
    with pytest.raises(scatterscope.ScatterscopeError, match="NaN at bin 3, row 2, column 1"):
        bad = cube.copy()
        bad[3, 2, 1] = np.nan
        scatterscope.reconstruct_embedded(bad, (0.28, 0.28), 50.0, front_thickness_cm=2.5,
                                          back_thickness_cm=2.5, mu_s_reduced=71.0, mu_a=0.14,
                                          refractive_index=1.0)


def test_arrays_past_the_memory_budget_are_refused_before_they_are_copied(monkeypatch):
    """Under SCATTERSCOPE_MEMORY_LIMIT, reconstruct and reconstruct_embedded
    refuse an array by its shape before copying it (the copy of a large
    array alone ended the interpreter)."""
    monkeypatch.setenv("SCATTERSCOPE_MEMORY_LIMIT", "2mb")
    big = np.zeros((32, 64, 64), np.float32)
    with pytest.raises(scatterscope.ScatterscopeError, match=r"reconstructing an array of shape \[32, 64, 64\]"):
        scatterscope.reconstruct(big, scatterscope.measured_meta(0.0, 4.0, 32))
    with pytest.raises(scatterscope.ScatterscopeError, match=r"reconstructing a cube of shape \[32, 64, 64\]"):
        scatterscope.reconstruct_embedded(big, (0.14, 0.14), 50.0, front_thickness_cm=2.5,
                                          back_thickness_cm=2.5, mu_s_reduced=71.0, mu_a=0.14,
                                          refractive_index=1.0)
