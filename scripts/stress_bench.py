"""Scores `scatterscope reconstruct`'s methods on the stacks of
`stress_scenes.py` (an independent forward model), in the benchmark's
terms: each method's PSNR against the truth, its margin over
Richardson-Lucy's best iteration chosen with the truth (`rl-sum`, fixed,
up to 1000 iterations) and its distance to `rl-sum` with its
cross-validated stop.

    python3 scripts/stress_bench.py STACKS_DIR OUT.csv [--methods auto,learned,rl-sum] [--cli target/release/scatterscope]

Writes one row per stack and method (stack, kind, level, method, psnr,
margin, vs_rl_sum_cv, wall_s, chosen, notes) and prints the means per
level, the worst margins and the stacks below `rl-sum` CV by more than
0.5 dB.
"""

import argparse
import csv
import json
import os
import re
import subprocess
import sys
import tempfile

PSNR = re.compile(r"output PSNR (-?[\d.]+) dB.*best iteration by truth: (\d+) \((-?[\d.]+) dB\)")


def run(cli, folder, args):
    with tempfile.TemporaryDirectory() as out:
        cmd = [cli, "reconstruct", os.path.join(folder, "counts.npy"), "--truth",
               os.path.join(folder, "truth.npy"), "--out", out] + args
        p = subprocess.run(cmd, capture_output=True, text=True)
        if p.returncode not in (0, 4):
            raise SystemExit(f"{' '.join(cmd)} failed ({p.returncode}):\n{p.stderr}")
        text = p.stdout + p.stderr
        m = PSNR.search(text)
        trace = json.load(open(os.path.join(out, "trace.json")))
        notes = [line.strip() for line in text.splitlines() if line.strip().startswith(("auto:", "learned:", "rl-sum:", "warning:"))]
        chosen = next((n.removeprefix("auto: chose ") for n in notes if n.startswith("auto: chose ")), "")
        return float(m.group(1)), float(m.group(3)), float(trace.get("wall_s", float("nan"))), chosen, notes


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("stacks")
    ap.add_argument("out")
    ap.add_argument("--methods", default="auto,learned,rl-sum")
    ap.add_argument("--cli", default="target/release/scatterscope")
    args = ap.parse_args()
    methods = args.methods.split(",")
    rows = []
    for name in sorted(os.listdir(args.stacks)):
        folder = os.path.join(args.stacks, name)
        if not os.path.exists(os.path.join(folder, "counts.npy")):
            continue
        kind, level = name.rsplit("_", 1)
        _, best, _, _, _ = run(args.cli, folder, ["--method", "rl-sum", "--rl-stop", "fixed", "--rl-iters", "1000"])
        results = {}
        for method in methods:
            results[method] = run(args.cli, folder, ["--method", method])
        cv = results["rl-sum"][0] if "rl-sum" in results else float("nan")
        for method, (psnr, _, wall, chosen, notes) in results.items():
            row = {
                "stack": name, "kind": kind, "level": level.removesuffix("x"), "method": method,
                "psnr": round(psnr, 3), "margin": round(psnr - best, 3), "vs_rl_sum_cv": round(psnr - cv, 3),
                "wall_s": round(wall, 3), "chosen": chosen, "notes": " | ".join(notes),
            }
            rows.append(row)
            print(f"{name:18s} {method:8s} {psnr:7.2f} dB  margin {psnr - best:+6.2f}  vs rl-sum CV {psnr - cv:+6.2f}  {wall:6.2f} s  {chosen}", flush=True)
    tmp = args.out + ".tmp"
    with open(tmp, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, args.out)
    for method in methods:
        for level in sorted({r["level"] for r in rows}, key=float):
            sel = [r for r in rows if r["method"] == method and r["level"] == level]
            mean = sum(r["margin"] for r in sel) / len(sel)
            worst = min(sel, key=lambda r: r["vs_rl_sum_cv"])
            below = [r["stack"] for r in sel if r["vs_rl_sum_cv"] < -0.5]
            print(f"{method:8s} {level:>4s}x mean margin {mean:+.2f} dB, worst vs rl-sum CV {worst['vs_rl_sum_cv']:+.2f} ({worst['stack']}), below by > 0.5 dB: {len(below)} {below}")


if __name__ == "__main__":
    sys.exit(main())
