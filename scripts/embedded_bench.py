#!/usr/bin/env python3
"""How well `scatterscope embedded` recovers objects inside the medium, and
how fast: letters (correlation with the truth) and double slits (the
smallest separation resolved) in the published data's geometry, at its
light and noise, from the project's simulator and from an independent one
(scripts/embedded_independent.py), for three treatments of the time axis.

    PYTHONPATH=target/pydeps python3 scripts/embedded_bench.py tuning OUT
    PYTHONPATH=target/pydeps python3 scripts/embedded_bench.py held-out OUT
    PYTHONPATH=target/pydeps python3 scripts/embedded_bench.py held-out OUT --tables-only

The sets were named before any score (docs/journal, forty-third session):
nothing is chosen on `held-out`. Writes OUT/results.json, prints the tables
(markdown), and for the held-out set draws OUT/resolution.png (the slits'
dip against their separation, the blur's width marked) and
OUT/letters.png. Uses target/release/scatterscope (cargo build --release).

A double slit counts as resolved where the profile across both slits
(central rows) dips between their peaks below 0.81 of the lower peak and
neither slit dips along its length (central 1.4 cm) below 0.81 of the
lower of the maxima on either side of the dip.
"""

import json
import os
import subprocess
import sys
import time

import numpy as np

EXE = os.environ.get("SCATTERSCOPE", "target/release/scatterscope")
GEOMETRY = (
    "--front-thickness 2.5cm --back-thickness 2.5cm --mu-s-reduced 71 "
    "--mu-a 0.14 --index 1 --beam 6cm"
).split()
PITCH = 0.14
METHODS = {"groups-8": [], "summed": ["--time-groups", "1"], "groups-32": ["--time-groups", "32"]}
SETS = {
    "tuning": dict(
        letters=["A", "K"], slits=[0.4, 0.8, 1.5], seeds=[1, 2], gains=[1.0, 0.35, 3.8], photons=[2.5e5, 5.5e5]
    ),
    "held-out": dict(
        letters=["X", "T", "S", "H", "E"],
        slits=[0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0, 1.2, 1.5, 2.0],
        seeds=[101, 102, 103],
        gains=[1.0, 0.35, 3.8],
        photons=[2.5e5, 5.5e5],
    ),
}
INDEPENDENT = {"tuning": [], "held-out": ["X", "T", "H", "L", "V"]}


def simulate(out, target, seed, gain, photons, independent=False):
    if independent:
        cmd = [sys.executable, "scripts/embedded_independent.py", out, "--target", target,
               "--seed", str(seed), "--gain", str(gain), "--photons", str(photons)]
    else:
        cmd = [EXE, "simulate-embedded", "--target", target, "--seed", str(seed), "--gain", str(gain),
               "--photons", str(photons), "--bins", "160", "--out", out, *GEOMETRY]
    subprocess.run(cmd, check=True, capture_output=True)


def reconstruct(case, extra):
    out = os.path.join(case, "rec")
    cmd = [EXE, "embedded", os.path.join(case, "cube.mat"), "--positions", os.path.join(case, "positions.mat"),
           "--positions-unit", "1mm", "--bin-width", "50ps", "--out", out, *GEOMETRY, *extra]
    t = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - t
    if done.returncode not in (0, 4):
        raise RuntimeError(done.stdout + done.stderr)
    report = json.load(open(os.path.join(out, "report.json")))
    return np.load(os.path.join(out, "transmission.npy")).astype(float), report, seconds


def correlation(a, b):
    return float(np.corrcoef(a.ravel(), b.ravel())[0, 1])


def slit_verdict(img, sep):
    size = img.shape[0]
    x = (np.arange(size) - (size - 1) / 2) * PITCH
    rows = np.abs(x) <= 0.6
    across = img[rows].mean(axis=0)
    left = np.where((x < 0) & (x > -1.5))[0]
    right = np.where((x > 0) & (x < 1.5))[0]
    li = left[np.argmax(across[left])]
    ri = right[np.argmax(across[right])]
    between = across[li : ri + 1]
    low = min(across[li], across[ri])
    dip = float(between.min() / low) if low > 0 else 1.0

    def dips_along(col):
        along = img[np.abs(x) <= 0.7, col]
        for i in range(1, len(along) - 1):
            if along[i] < 0.81 * min(along[:i].max(), along[i + 1 :].max()):
                return True
        return False

    resolved = dip < 0.81 and not dips_along(li) and not dips_along(ri)
    return dict(dip=dip, resolved=bool(resolved))


def main():
    which, out = sys.argv[1], sys.argv[2]
    if len(sys.argv) > 3 and sys.argv[3] == "--tables-only":
        tables(json.load(open(os.path.join(out, "results.json"))), out, which)
        return
    spec = SETS[which]
    os.makedirs(out, exist_ok=True)
    rows = []
    cases = []
    for letter in spec["letters"]:
        for seed in spec["seeds"]:
            for gain in spec["gains"]:
                for photons in spec["photons"]:
                    cases.append(("letter", f"letter:{letter}", seed, gain, photons, False))
    for sep in spec["slits"]:
        for seed in spec["seeds"]:
            cases.append(("slits", f"slits:{sep}", seed, 1.0, 4e5, False))
    for letter in INDEPENDENT[which]:
        for seed in spec["seeds"]:
            cases.append(("independent", f"letter:{letter}", seed, 1.0, 4e5, True))
    for kind, target, seed, gain, photons, independent in cases:
        case = os.path.join(out, f"{kind}-{target.replace(':', '-')}-{seed}-{gain}-{photons:g}")
        simulate(case, target, seed, gain, photons, independent)
        truth = np.load(os.path.join(case, "truth.npy")).astype(float)
        for method, extra in METHODS.items():
            img, report, seconds = reconstruct(case, extra)
            row = dict(kind=kind, target=target, seed=seed, gain=gain, photons=photons, method=method,
                       seconds=seconds, iterations=report["fit"]["iterations"],
                       noise=report["noise"]["kind"], blur_fwhm_cm=report["blur_fwhm_cm"],
                       misfit_z=(report["fit"]["deviance"] - report["fit"]["expected_deviance"][0])
                       / report["fit"]["expected_deviance"][1],
                       correlation=correlation(img, truth))
            if kind == "slits":
                row.update(slit_verdict(img, float(target.split(":")[1])))
            rows.append(row)
            print(json.dumps(row), flush=True)
    json.dump(rows, open(os.path.join(out, "results.json"), "w"), indent=1)
    tables(rows, out, which)


def tables(rows, out, which):
    print(f"\n### {which}: letters, correlation with the truth (mean, worst) and seconds (median)\n")
    print("| method | gain 1 | gain 0.35 | gain 3.8 | independent model | seconds |")
    print("| --- | --- | --- | --- | --- | --- |")
    for m in METHODS:
        cells = []
        for g in (1.0, 0.35, 3.8):
            c = [r["correlation"] for r in rows if r["kind"] == "letter" and r["method"] == m and r["gain"] == g]
            cells.append(f"{np.mean(c):.3f} ({min(c):.3f})" if c else "-")
        c = [r["correlation"] for r in rows if r["kind"] == "independent" and r["method"] == m]
        cells.append(f"{np.mean(c):.3f} ({min(c):.3f})" if c else "-")
        s = [r["seconds"] for r in rows if r["method"] == m]
        print(f"| `{m}` | " + " | ".join(cells) + f" | {np.median(s):.2f} |")
    seps = sorted({float(r["target"].split(":")[1]) for r in rows if r["kind"] == "slits"})
    if not seps:
        return
    blur = np.median([r["blur_fwhm_cm"] for r in rows])
    print(f"\n### {which}: double slits resolved (of {len({r['seed'] for r in rows if r['kind'] == 'slits'})} seeds); blur FWHM {blur:.2f} cm\n")
    print("| method | " + " | ".join(f"{s:g} cm" for s in seps) + " | smallest resolved by every seed |")
    print("| --- | " + " | ".join("---" for _ in seps) + " | --- |")
    curves = {}
    for m in METHODS:
        counts, dips = [], []
        for s in seps:
            rs = [r for r in rows if r["kind"] == "slits" and r["method"] == m and float(r["target"].split(":")[1]) == s]
            counts.append((sum(r["resolved"] for r in rs), len(rs)))
            dips.append(np.median([r["dip"] for r in rs]))
        curves[m] = dips
        smallest = "none"
        for i, s in enumerate(seps):
            if all(c == n for c, n in counts[i:]):
                smallest = f"{s:g} cm"
                break
        print(f"| `{m}` | " + " | ".join(f"{c}/{n}" for c, n in counts) + f" | {smallest} |")
    if which == "held-out":
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 4))
        for m, d in curves.items():
            ax.plot(seps, d, "o-", label=m)
        ax.axhline(0.81, color="k", ls=":", label="0.81 (resolved below)")
        ax.axvline(blur, color="gray", ls="--", label=f"blur FWHM {blur:.2f} cm")
        ax.set_xlabel("slit separation, centre to centre (cm)")
        ax.set_ylabel("dip between the slits / lower peak (median)")
        ax.set_title("Double slits inside 2.5 + 2.5 cm of mu_s' 71 /cm (held-out seeds)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(os.path.join(out, "resolution.png"), dpi=110)
        letters_figure(rows, out, plt)


def letters_figure(rows, out, plt):
    """Truth and default reconstruction of each held-out letter, seed 101,
    gain 1, the lower light level; and the independent model's."""
    picks = [r for r in rows if r["method"] == "groups-8" and r["seed"] == 101 and r["gain"] == 1.0
             and (r["kind"] == "independent" or (r["kind"] == "letter" and r["photons"] == 2.5e5))]
    fig, axes = plt.subplots(2, len(picks), figsize=(1.3 * len(picks), 2.9))
    for col, r in enumerate(picks):
        case = os.path.join(out, f"{r['kind']}-{r['target'].replace(':', '-')}-{r['seed']}-{r['gain']}-{r['photons']:g}")
        img, _, _ = reconstruct(case, METHODS["groups-8"])
        axes[0, col].imshow(np.load(os.path.join(case, "truth.npy")), cmap="gray", vmin=0, vmax=1)
        axes[1, col].imshow(img, cmap="gray", vmin=0, vmax=1)
        axes[0, col].set_title(("indep. " if r["kind"] == "independent" else "") + r["target"][-1], fontsize=8)
        axes[1, col].set_xlabel(f"r = {r['correlation']:.2f}", fontsize=8)
        for a in axes[:, col]:
            a.set_xticks([])
            a.set_yticks([])
    axes[0, 0].set_ylabel("truth", fontsize=8)
    axes[1, 0].set_ylabel("embedded", fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "letters.png"), dpi=110)


if __name__ == "__main__":
    main()
