"""MCML 1.2.2 (Wang and Jacques) side by side with our Monte Carlo transport,
in one run on one machine: speed on van de Hulst's slab, and total
reflection and transmission of slabs with mismatched faces.

MCML's source is not part of this repository and is not fetched by it:
give the folder holding MCML 1.2.2's mcmlmain.c, mcmlgo.c, mcmlio.c,
mcmlnr.c and mcml.h (the authors' Unix release). It is built here with
gcc -O3 into target/mcml-build.

Usage: python3 scripts/mcml_side_by_side.py MCML_SOURCE_DIR
           [--photons N] [--repeats K]

Speed: photons per CPU second of each program on van de Hulst's slab,
three rounds each, alternating,
(mu_a 10 /cm, mu_s 90 /cm, g 0.75, n 1, 0.02 cm): MCML is one process on
one core; ours runs on every core and is divided by its CPU time.

Agreement: MCML seeds itself from the clock's second, so its K runs are
started at least a second apart and give K independent estimates; their
spread gives MCML's standard error. Ours is one run of K * N packets with
its own standard error. Each difference is printed in combined standard
errors (z).
"""

import argparse
import math
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# (mu_a, mu_s, g, n, thickness_cm): the three slabs of
# physics/tests/transport.rs::mismatched_faces_agree_with_adding_doubling.
CASES = [
    (10.0, 90.0, 0.75, 1.4, 0.02),
    (1.0, 99.0, 0.9, 1.33, 0.1),
    (5.0, 5.0, 0.0, 1.5, 0.1),
]
VAN_DE_HULST = (10.0, 90.0, 0.75, 1.0, 0.02)


def build_mcml(src: Path) -> Path:
    out = ROOT / "target" / "mcml-build"
    out.mkdir(parents=True, exist_ok=True)
    exe = out / "mcml"
    sources = [src / f for f in ("mcmlmain.c", "mcmlgo.c", "mcmlio.c", "mcmlnr.c")]
    missing = [str(f) for f in sources + [src / "mcml.h"] if not f.is_file()]
    if missing:
        sys.exit(f"MCML source not found: {', '.join(missing)}")
    subprocess.run(
        ["gcc", "-O3", "-w", "-o", str(exe), *map(str, sources), "-lm"], check=True
    )
    return exe


def run_mcml(exe: Path, case, photons: int, work: Path):
    """One MCML run: (specular + diffuse reflectance, transmittance, CPU s)."""
    mu_a, mu_s, g, n, d = case
    mci = work / "case.mci"
    mco = work / "case.mco"
    mci.write_text(
        "1.0\n1\ncase.mco A\n"
        f"{photons}\n0.01 0.01\n10 10 10\n1\n1.0\n"
        f"{n} {mu_a} {mu_s} {g} {d}\n1.0\n"
    )
    before = os.times()
    subprocess.run([str(exe), "case.mci"], cwd=work, check=True, stdout=subprocess.DEVNULL)
    after = os.times()
    cpu = (after.children_user - before.children_user) + (
        after.children_system - before.children_system
    )
    text = mco.read_text()

    def value(label):
        m = re.search(r"^\s*([-+0-9.eE]+)\s+#" + re.escape(label), text, re.M)
        if m is None:
            sys.exit(f"{mco}: no '{label}' line")
        return float(m.group(1))

    r = value("Specular reflectance") + value("Diffuse reflectance")
    return r, value("Transmittance"), cpu


def run_ours(case, packets: int):
    """One run of ours: (R with specular, its error, T, its error, per CPU s)."""
    out = subprocess.run(
        [
            "cargo", "run", "-q", "--release", "-p", "scatterscope-physics",
            "--example", "transport_speed", "--", str(packets), "1",
            *map(str, case),
        ],
        cwd=ROOT, check=True, capture_output=True, text=True,
    ).stdout
    m = re.search(
        r"([0-9.e+]+) per CPU s; specular ([0-9.]+), R ([0-9.]+) \+- ([0-9.]+), "
        r"T ([0-9.]+) \+- ([0-9.]+)",
        out,
    )
    if m is None:
        sys.exit(f"unexpected output of transport_speed: {out}")
    rate, spec, r, re_, t, te = map(float, m.groups())
    return spec + r, re_, t, te, rate


def mean_se(values):
    k = len(values)
    mean = sum(values) / k
    return mean, math.sqrt(sum((v - mean) ** 2 for v in values) / (k - 1) / k)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("mcml_source", type=Path)
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=8)
    args = ap.parse_args()
    if args.repeats < 2:
        sys.exit("--repeats must be at least 2")
    exe = build_mcml(args.mcml_source)
    work = ROOT / "target" / "mcml-build" / "runs"
    work.mkdir(exist_ok=True)
    subprocess.run(
        ["cargo", "build", "-q", "--release", "-p", "scatterscope-physics",
         "--example", "transport_speed"],
        cwd=ROOT, check=True,
    )

    print("## Speed on van de Hulst's slab")
    big = 10 * args.photons
    # Three rounds each, alternating, so a busy moment hits both alike.
    mcml_rates, our_rates = [], []
    for _ in range(3):
        mcml_rates.append(big / run_mcml(exe, VAN_DE_HULST, big, work)[2])
        our_rates.append(run_ours(VAN_DE_HULST, big)[4])
    for name, rates in (("MCML 1.2.2 (gcc -O3, one core)", mcml_rates), ("ours (both cores)", our_rates)):
        shown = ", ".join(f"{r:.3g}" for r in rates)
        print(f"{name}: {big} photons per round, per CPU s {shown}; median {sorted(rates)[1]:.3g}")

    print("\n## Total reflection (with specular) and transmission")
    print("case | MCML R | ours R | z | MCML T | ours T | z")
    for case in CASES:
        runs = []
        for _ in range(args.repeats):
            start = time.time()
            runs.append(run_mcml(exe, case, args.photons, work))
            # MCML seeds from the clock's second: the next run must start
            # in a later second.
            time.sleep(max(0.0, 1.05 - (time.time() - start)))
        (mr, mre), (mt, mte) = mean_se([x[0] for x in runs]), mean_se([x[1] for x in runs])
        r, re_, t, te, _ = run_ours(case, args.repeats * args.photons)
        zr = (r - mr) / math.hypot(re_, mre)
        zt = (t - mt) / math.hypot(te, mte)
        label = "mu_a {} mu_s {} g {} n {} d {}".format(*case)
        print(
            f"{label} | {mr:.5f} +- {mre:.5f} | {r:.5f} +- {re_:.5f} | {zr:+.2f}"
            f" | {mt:.5f} +- {mte:.5f} | {t:.5f} +- {te:.5f} | {zt:+.2f}"
        )


if __name__ == "__main__":
    main()
