"""Applies rules R82b and R82c (journal, forty-first session) to scored
stacks: the guard's threshold `tau` and the warning's `Z_WARN`, from
`bench-recon` outputs (rows.csv with traces/*.json, methods learned,
rl-sum and auto) and `stress_bench.py` CSVs (methods auto, learned,
rl-sum).

    python3 scripts/auto_rules.py [--bench OUT_DIR ...] [--stress ROWS.csv ...]

Per stack it takes the guard's z (auto's note "z = ..."), the network's
PSNR, `rl-sum` CV's PSNR and the z of auto's output on the whole stack;
for each candidate `tau` it counts the stacks where `auto` (the network
when its z <= tau, else `rl-sum` CV) falls below `rl-sum` CV by more than
0.5 dB, and prints the rules' choices. Used on the tuning sets to choose,
and on the held-out ones only to report.
"""

import argparse
import csv
import json
import os
import re
import sys

TAUS = (-2, -1, 0, 1, 2, 4)
Z_WARNS = (10, 20, 50, 100, 200, 500, 1000)
FLOOR_DB = 0.5
GUARD_Z = re.compile(r"z = ([+-]?[\d.]+|[+-]?inf|NaN); kept")
OUTPUT_Z = re.compile(r"^(?:learned|rl-sum): output deviance .*\(z = (-?[\d.]+|-?inf|NaN)\)")


def bench_stacks(folder):
    rows = list(csv.DictReader(open(os.path.join(folder, "rows.csv"))))
    by = {}
    for r in rows:
        by.setdefault((r["image"], r["level"]), {})[r["method"]] = r
    out = []
    for (image, level), m in sorted(by.items()):
        auto = m.get("auto (the default)")
        trace = os.path.join(folder, "traces", f"{image}_{level}_auto_(the_default).json")
        notes = json.load(open(trace))["notes"] if os.path.exists(trace) else []
        zs = [float(g.group(1)) for n in notes if (g := OUTPUT_Z.match(n))]
        out.append(stack(f"{image}@{level}", float(m["learned"]["psnr"]),
                         float(m["rl-sum (cross-validated stop)"]["psnr"]), float(auto["psnr"]),
                         auto["chose"], notes, zs[-1] if zs else float("nan")))
    return out


def stress_stacks(path):
    by = {}
    for r in csv.DictReader(open(path)):
        by.setdefault(r["stack"], {})[r["method"]] = r
    out = []
    for name, m in sorted(by.items()):
        notes = m["auto"]["notes"].split(" | ")
        zs = [float(g.group(1)) for n in notes if (g := OUTPUT_Z.match(n))]
        out.append(stack(name, float(m["learned"]["psnr"]), float(m["rl-sum"]["psnr"]),
                         float(m["auto"]["psnr"]), m["auto"]["chosen"], notes,
                         zs[-1] if zs else float("nan")))
    return out


def stack(name, learned, rl, auto, chose, notes, output_z):
    guard = [float(g.group(1)) for n in notes if (g := GUARD_Z.search(n))]
    return {"name": name, "learned": learned, "rl": rl, "auto": auto, "chose": chose,
            "guard_z": guard[0] if guard else None, "output_z": output_z}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bench", nargs="*", default=[])
    ap.add_argument("--stress", nargs="*", default=[])
    args = ap.parse_args()
    stacks = [s for f in args.bench for s in bench_stacks(f)]
    stacks += [s for f in args.stress for s in stress_stacks(f)]
    checked = [s for s in stacks if s["guard_z"] is not None]
    print(f"{len(stacks)} stacks, {len(checked)} checked by the guard "
          f"(the rest outside the trained ranges or without photons in a half)")
    print("guard z per stack (network - rl-sum CV, dB):")
    for s in sorted(checked, key=lambda s: s["guard_z"]):
        print(f"  {s['name']:32s} z {s['guard_z']:+9.2f}  net-rl {s['learned'] - s['rl']:+6.2f}")
    holding = []
    for tau in TAUS:
        kept = [s for s in checked if s["guard_z"] <= tau]
        below = [s for s in checked
                 if (s["learned"] if s["guard_z"] <= tau else s["rl"]) < s["rl"] - FLOOR_DB]
        gain = sum((s["learned"] if s["guard_z"] <= tau else s["rl"]) - s["rl"] for s in checked)
        gain /= max(len(checked), 1)
        print(f"tau {tau:+d}: network kept on {len(kept)}, below rl-sum CV by > {FLOOR_DB} dB: "
              f"{len(below)} {[s['name'] for s in below]}, mean gain over rl-sum CV {gain:+.3f} dB")
        if not below:
            holding.append(tau)
    print(f"R82b: tau = {max(holding) if holding else -2}"
          + ("" if holding else " (no candidate holds the floor: shortfall reported)"))
    oracle = sum(max(s["learned"], s["rl"]) - s["rl"] for s in checked) / max(len(checked), 1)
    print(f"ceiling (truth choosing network or rl-sum CV per stack): {oracle:+.3f} dB over rl-sum CV")
    zs = [s["output_z"] for s in stacks if s["output_z"] == s["output_z"]]
    top = max(zs) if zs else float("nan")
    above = [z for z in Z_WARNS if z > top]
    print(f"R82c: largest output z {top:.1f}; Z_WARN = {above[0] if above else 'none of the candidates'}")


if __name__ == "__main__":
    sys.exit(main())
