"""Times a 256 x 256 FLIM image fitted pixel by pixel with two components
and the IRF, whole process: `scatterscope fit` (read, bin, fit, write the
OME-TIFF, npy and JSON) against ptufile's decoding, numpy's binning,
flimlib's Marquardt engine over the same pixels (Poisson maximum
likelihood, started alike) and np.save of its parameters.

    PYTHONPATH=target/pydeps python3 scripts/bench_fit.py FILE.ptu [ROUNDS]

The IRF: the Gaussian `fit --irf gaussian` fits on the summed decay,
integrated over the bins, given to both as an array (its shift held); binning 4 (9 x 9);
pixels of at least 100 photons. Prints each round and the medians.
"""

import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CLI = os.path.join(ROOT, "target", "release", "scatterscope")
BINNING = 4
MIN_PHOTONS = 100


def binned(stack, b):
    h, w, _ = stack.shape
    c = np.pad(stack, ((1, 0), (1, 0), (0, 0))).cumsum(0).cumsum(1)
    r0 = np.clip(np.arange(h) - b, 0, h)
    r1 = np.clip(np.arange(h) + b + 1, 0, h)
    q0 = np.clip(np.arange(w) - b, 0, w)
    q1 = np.clip(np.arange(w) + b + 1, 0, w)
    return (c[r1][:, q1] - c[r0][:, q1] - c[r1][:, q0] + c[r0][:, q0])


def flimlib_round(path, irf, out, background_start):
    """One timed round of ptufile + numpy + flimlib + np.save; flimlib's
    background starts at 0 (`background_start` "zero") or at the mean of
    each decay's bins before its rise ("pre-rise"). Returns wall and CPU
    seconds, the pixels and how many flimlib returned unchanged."""
    import flimlib
    import ptufile

    started, cpu = time.perf_counter(), time.process_time()
    with ptufile.PtuFile(path) as f:
        d = f.decode_image(dtype="uint32")
        width = f.tags["MeasDesc_Resolution"] * 1e12
    stack = d.sum(axis=0)[:, :, 0, :].astype(np.float64)
    decays = binned(stack, BINNING)
    pick = decays.sum(axis=-1) >= MIN_PHOTONS
    y = decays[pick]
    param = np.zeros((len(y), 5))
    if background_start == "pre-rise":
        rise = int(np.argmax(y.sum(axis=0)))
        param[:, 0] = y[:, : max(rise - 3, 1)].mean(axis=1)
    param[:, 1] = param[:, 3] = y.max(axis=1) / 2
    param[:, 2], param[:, 4] = 0.5, 2.0
    res = flimlib.GCI_marquardt_fitting_engine(
        width * 1e-3, y, param, instr=irf / irf.sum(), noise_type="NOISE_MLE",
        compute_fitted=False, compute_residuals=False, compute_covar=False,
        compute_alpha=False, compute_erraxes=False)
    np.save(out, res.param)
    unchanged = int(np.all(res.param == param, axis=1).sum())
    return time.perf_counter() - started, time.process_time() - cpu, int(pick.sum()), unchanged


def main():
    path = sys.argv[1]
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    import ptufile

    with ptufile.PtuFile(path) as f:
        d = f.decode_image(dtype="uint32")
        width = f.tags["MeasDesc_Resolution"] * 1e12
    n = d.shape[-1]
    # The IRF: the Gaussian `fit --irf gaussian` finds on the summed decay
    # (centre and width in bins), integrated over the bins.
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [CLI, "fit", path, "--components", "2", "--irf", "gaussian", "--binning",
               str(BINNING), "--min-photons", str(MIN_PHOTONS), "--no-figures", "--out", tmp]
        subprocess.run(cmd, check=True, capture_output=True)
        params = json.load(open(os.path.join(tmp, "fit.json")))["summed_params"]
    centre, sd = params[5], params[6]
    cdf = np.vectorize(lambda z: 0.5 * math.erfc(-z / math.sqrt(2.0)))
    i = np.arange(n)
    irf = cdf((i + 0.5 - centre) / sd) - cdf((i - 0.5 - centre) / sd)
    print(f"IRF: centre {centre * width:.1f} ps, FWHM {sd * width * 2.354820045:.1f} ps")
    import resource

    def children_cpu():
        r = resource.getrusage(resource.RUSAGE_CHILDREN)
        return r.ru_utime + r.ru_stime

    ours, ours_cpu = [], []
    theirs = {"zero": [], "pre-rise": []}
    theirs_cpu = {"zero": [], "pre-rise": []}
    with tempfile.TemporaryDirectory() as tmp:
        np.save(os.path.join(tmp, "irf.npy"), irf)
        for r in range(rounds):
            cmd = [CLI, "fit", path, "--components", "2", "--irf", os.path.join(tmp, "irf.npy"),
                   "--binning", str(BINNING), "--min-photons", str(MIN_PHOTONS),
                   "--no-figures", "--out", os.path.join(tmp, f"fit{r}")]
            started, cpu = time.perf_counter(), children_cpu()
            p = subprocess.run(cmd, capture_output=True, text=True)
            took = time.perf_counter() - started
            ours_cpu.append(children_cpu() - cpu)
            if p.returncode != 0:
                sys.exit(f"{' '.join(cmd)}: {p.stderr}")
            fitted = [l for l in p.stdout.splitlines() if "pixels fitted" in l][0].split(" of ")[0]
            ours.append(took)
            line = f"round {r + 1}: scatterscope fit {took:.2f} s ({ours_cpu[-1]:.2f} CPU s, {fitted} pixels fitted)"
            for start in theirs:
                t, c, pixels, unchanged = flimlib_round(path, irf, os.path.join(tmp, f"flimlib{r}.npy"), start)
                theirs[start].append(t)
                theirs_cpu[start].append(c)
                line += f"; flimlib from a {start} background {t:.2f} s ({c:.2f} CPU s, {pixels} pixels, {unchanged} returned unchanged)"
            print(line)
    print(f"median: scatterscope fit {np.median(ours):.2f} s, {np.median(ours_cpu):.2f} CPU s")
    for start in theirs:
        print(f"median: ptufile + flimlib from a {start} background {np.median(theirs[start]):.2f} s, "
              f"{np.median(theirs_cpu[start]):.2f} CPU s: {np.median(theirs[start]) / np.median(ours):.1f}x wall, "
              f"{np.median(theirs_cpu[start]) / np.median(ours_cpu):.1f}x per CPU second")


if __name__ == "__main__":
    main()
