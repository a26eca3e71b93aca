"""Python package benchmarks, on this machine (run by hand; results go in
BENCHMARKS.md):

1. Binning T3 files from Python (`scatterscope.bin_file`, one pixel per
   channel, the file's micro-time unit) against ptufile's
   `PtuFile.decode_histogram` on the same file: the shared HydraHarp T3
   samples and a synthetic 20 M-record Generic T3 file; each result checked
   bin for bin, the median of RUNS runs timed.
2. A 256 x 256 FLIM image file (synthetic, 3 MB, two frames) from Python
   (`scatterscope.bin_file(..., dtype="uint16")`, frames summed) against
   ptufile's `decode_image(frame=-1)` returning the same counts: the best
   of RUNS in-process calls each, the images checked pixel for pixel.
3. The paper preset's reconstruction (default method) from Python against
   `scatterscope reconstruct` on the same counts: median wall time of RUNS
   runs each, and the images compared bit for bit.

    python python/bench/bench_python.py [--runs 5] [--recon-runs 3]
"""

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import ptufile

import scatterscope

REPO = Path(__file__).resolve().parents[2]
CLI = REPO / "target" / "release" / "scatterscope"


def timed(fn, runs):
    """The seconds of each of `runs` calls of `fn`, and its last result."""
    times = []
    out = None
    for _ in range(runs):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return times, out


def median_time(fn, runs):
    times, out = timed(fn, runs)
    return statistics.median(times), out


def best_time(fn, runs):
    times, out = timed(fn, runs)
    return min(times), out


def ptufile_histogram(path):
    with ptufile.PtuFile(path) as p:
        return p.decode_histogram(dtype=np.uint32)


def check_equal(ours, theirs, name):
    # ours: (bins, 1, channels); theirs: (channels, bins).
    for ch in range(theirs.shape[0]):
        mine = ours[:, 0, ch] if ch < ours.shape[2] else np.zeros(ours.shape[0])
        n = min(len(mine), theirs.shape[1])
        if not (np.array_equal(mine[:n], theirs[ch, :n]) and mine[n:].sum() == 0 and theirs[ch, n:].sum() == 0):
            raise SystemExit(f"{name}: channel {ch} differs from ptufile")


def ptufile_image(path):
    with ptufile.PtuFile(path) as p:
        return p.decode_image(frame=-1)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--recon-runs", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        synthetic = tmp / "synthetic.ptu"
        subprocess.run(["cargo", "run", "--release", "--quiet", "--example", "synthetic_ptu", "--",
                        str(synthetic), "20000000"], cwd=REPO, check=True, capture_output=True)
        files = [REPO.parent / "shared/data/picoquant-sample-data/hydraharp" / n for n in ("v20_t3.ptu", "v10_t3.ptu")]
        files = [f for f in files if f.exists()] + [synthetic]
        print("| file | records | scatterscope.bin_file (ms) | ptufile decode_histogram (ms) | ratio |")
        print("| --- | --- | --- | --- | --- |")
        for f in files:
            f.read_bytes()  # into the page cache
            t_ours, ours = median_time(lambda: scatterscope.bin_file(f, pixels="channel"), args.runs)
            t_theirs, theirs = median_time(lambda: ptufile_histogram(f), args.runs)
            check_equal(ours["stacks"][0], theirs, f.name)
            print(f"| {f.name} | {ours['ledger']['records']} | {t_ours * 1e3:.3f} | {t_theirs * 1e3:.3f} | {t_theirs / t_ours:.2f}x |")

        flim = tmp / "flim.ptu"
        subprocess.run(["cargo", "run", "--release", "--quiet", "--example", "synthetic_ptu", "--", "--flim",
                        str(flim)], cwd=REPO, check=True, capture_output=True)
        flim.read_bytes()
        t_ours, ours = best_time(lambda: scatterscope.bin_file(flim, dtype="uint16"), args.runs)
        t_theirs, theirs = best_time(lambda: ptufile_image(flim), args.runs)
        # ours: (bins, rows, cols); theirs: (frames, rows, cols, channels, bins).
        mine = ours["stacks"][0]
        if not np.array_equal(mine, theirs[0, :, :, 0, :].transpose(2, 0, 1)):
            raise SystemExit("FLIM image: differs from ptufile's")
        print()
        print(f"FLIM 256 x 256 ({flim.stat().st_size / 1e6:.1f} MB, {ours['ledger']['records']} records), best of "
              f"{args.runs}: scatterscope.bin_file(dtype='uint16') {t_ours * 1e3:.1f} ms, ptufile decode_image "
              f"{t_theirs * 1e3:.1f} ms ({t_theirs / t_ours:.2f}x); {mine.dtype} {mine.shape}, equal pixel for pixel")

        sim = tmp / "sim"
        subprocess.run([str(CLI), "simulate", "--preset", "paper", "--scene", "usaf", "--seed", "1", "--out", str(sim)],
                       check=True, capture_output=True)
        counts, meta = scatterscope.load_stack(sim / "counts.exr")
        t_cli, _ = median_time(lambda: subprocess.run(
            [str(CLI), "reconstruct", str(sim / "counts.exr"), "--out", str(tmp / "rec")], check=True,
            capture_output=True), args.recon_runs)
        t_py, (image, trace, _) = median_time(lambda: scatterscope.reconstruct(counts, meta), args.recon_runs)
        theirs = scatterscope.load_image(tmp / "rec" / "reconstruction.exr")
        same = np.array_equal(image.astype(np.float32).astype(np.float64), theirs)
        print()
        print(f"paper preset, default method ({trace['method']}): CLI {t_cli:.2f} s, Python {t_py:.2f} s "
              f"(Python / CLI = {t_py / t_cli:.3f}); images bit for bit equal: {same}")
        if not same:
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
