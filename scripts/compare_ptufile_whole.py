#!/usr/bin/env python3
"""`scatterscope bin` against ptufile, whole process against whole process.

For each T3 PTU file given (default: the shared PicoQuant samples that are
T3 PTU files, and a synthetic 3 MB FLIM image file of 256 x 256 pixels
written by `cargo run --release --example synthetic_ptu -- --flim`), runs,
alternating, `scatterscope bin FILE` (with and without its preview) and a
Python process that imports ptufile and numpy, decodes the same histogram
(`decode_histogram`, every channel, one sync period; for an image file
`decode_image`, frames summed) and saves it with `numpy.save`. Each is
timed from process start to exit; prints the median of RUNS runs of each
and the ratio. Bin-for-bin equality is checked by the tests (python/tests
for the shared T3 samples against ptufile's histograms,
tests/picoquant.rs for a synthetic FLIM file against its images); this
script times only.

Usage: PYTHONPATH=target/pydeps python3 scripts/compare_ptufile_whole.py [--runs N] [FILE ...]
"""

import argparse
import glob
import os
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
SAMPLES = os.path.join(ROOT, "..", "shared", "data", "picoquant-sample-data")

PTUFILE_SAVE = """
import sys, numpy, ptufile
with ptufile.PtuFile(sys.argv[1]) as ptu:
    if ptu.is_image:
        h = ptu.decode_image(frame=-1)
    else:
        h = ptu.decode_histogram(dtype="uint32")
numpy.save(sys.argv[2], h)
"""


def synthetic_flim():
    """The synthetic FLIM image file under target/, written if missing."""
    path = os.path.join(ROOT, "target", "ptufile-compare", "flim.ptu")
    if not os.path.exists(path):
        os.makedirs(os.path.dirname(path), exist_ok=True)
        subprocess.run(
            ["cargo", "run", "--release", "--quiet", "--example", "synthetic_ptu", "--", "--flim", path],
            cwd=ROOT,
            check=True,
            stdout=subprocess.DEVNULL,
        )
    return path


def wall(cmd, env=None):
    """Seconds from the process's start to its exit; fails loudly."""
    start = time.perf_counter()
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"{' '.join(cmd)}: exit {done.returncode}: {done.stderr.decode()}")
    return seconds


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--cli", default=os.path.join(ROOT, "target", "release", "scatterscope"))
    parser.add_argument("files", nargs="*")
    args = parser.parse_args()
    files = args.files or sorted(glob.glob(os.path.join(SAMPLES, "*", "*_t3.ptu"))) + [synthetic_flim()]
    env = dict(os.environ)
    print("| file | size | bin (s) | bin --no-preview (s) | ptufile + numpy.save (s) | ptufile / bin | ptufile / bin --no-preview |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as tmp:
        for path in files:
            times = {"bin": [], "bare": [], "ptufile": []}
            for _ in range(args.runs):
                times["bin"].append(wall([args.cli, "bin", path, "--out", os.path.join(tmp, "a")]))
                times["bare"].append(
                    wall([args.cli, "bin", path, "--no-preview", "--out", os.path.join(tmp, "b")])
                )
                times["ptufile"].append(
                    wall([sys.executable, "-c", PTUFILE_SAVE, path, os.path.join(tmp, "h.npy")], env)
                )
            med = {k: statistics.median(v) for k, v in times.items()}
            size = os.path.getsize(path)
            print(
                f"| {os.path.basename(path)} | {size / 1e3:.0f} kB | {med['bin']:.3f} | {med['bare']:.3f} "
                f"| {med['ptufile']:.3f} | {med['ptufile'] / med['bin']:.1f}x | {med['ptufile'] / med['bare']:.1f}x |"
            )


if __name__ == "__main__":
    main()
