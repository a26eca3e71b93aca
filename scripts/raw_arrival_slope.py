#!/usr/bin/env python3
"""How far the raw photon arrival times of the letter-U series move per
labelled centimetre, before any reconstruction.

Reads letter_u_NN.mat (NN cm) from a folder of the confocal diffuse
tomography scans (default ../shared/data/cdt-scenes), takes four timings
from the raw counts and regresses each on the labelled distance. The
slab's delay is the same in every scan, so it cancels in the slope; a
slope below the round trip at the speed of light (2 cm / c0 per cm) says
the recording and its labels disagree, whatever the reconstruction.

Usage: PYTHONPATH=target/pydeps python3 scripts/raw_arrival_slope.py [DIR] [BIN_PS]
"""

import glob
import re
import sys

import h5py
import numpy as np

LIGHT_SPEED = 299_792_458.0


def time_axis_first(counts):
    """The counts with the longest (time) axis first."""
    return np.moveaxis(counts, int(np.argmax(counts.shape)), 0)


def timings(counts):
    """Peak, half-maximum rising edge and centroid of the summed
    histogram, and the median over the brightest points of each point's
    smoothed peak, all in bins."""
    total = counts.reshape(counts.shape[0], -1).sum(axis=1)
    peak = int(np.argmax(total))
    half = total[peak] / 2
    j = peak
    while j > 0 and total[j - 1] >= half:
        j -= 1
    edge = (j - 1) + (half - total[j - 1]) / (total[j] - total[j - 1])
    lo, hi = max(peak - 40, 0), peak + 40
    k = np.arange(len(total))
    centroid = (total[lo:hi] * k[lo:hi]).sum() / total[lo:hi].sum()
    taps = np.exp(-0.5 * (np.arange(-12, 13) / 4.0) ** 2)
    taps /= taps.sum()
    smooth = np.apply_along_axis(lambda v: np.convolve(v, taps, "same"), 0, counts)
    brightest = smooth.max(axis=0)
    chosen = brightest >= 0.5 * brightest.max()
    per_point = float(np.median(smooth.argmax(axis=0)[chosen]))
    return peak, edge, centroid, per_point


def main():
    folder = sys.argv[1] if len(sys.argv) > 1 else "../shared/data/cdt-scenes"
    bin_ps = float(sys.argv[2]) if len(sys.argv) > 2 else 16.0
    rows = []
    for path in sorted(glob.glob(f"{folder}/letter_u_*.mat")):
        cm = int(re.findall(r"letter_u_(\d+)\.mat", path)[0])
        with h5py.File(path, "r") as f:
            counts = time_axis_first(np.array(f["meas"], dtype=np.float64))
        rows.append((cm, *timings(counts)))
        print(cm, " ".join(f"{t:.2f}" for t in rows[-1][1:]))
    if len(rows) < 2:
        sys.exit(f"{folder}: fewer than two letter_u_NN.mat scans")
    cm = np.array([r[0] for r in rows], float)
    round_trip = 2e-2 / LIGHT_SPEED / (bin_ps * 1e-12)
    print(f"round trip at c0: {round_trip:.3f} bins of {bin_ps} ps per cm")
    names = ["summed peak", "summed rising edge", "summed centroid", "per-point peak"]
    for i, name in enumerate(names, start=1):
        slope = np.polyfit(cm, [r[i] for r in rows], 1)[0]
        print(f"{name}: {slope:.3f} bins per cm, {slope / round_trip:.3f} of the round trip")


if __name__ == "__main__":
    main()
