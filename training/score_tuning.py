"""Scores learned-reconstruction weight files on the benchmark's tuning
images, image by image, in the benchmark's terms: the margin over
Richardson-Lucy's best iteration chosen with the truth and the distance
to `rl-sum` with its cross-validated stop, both read from a
`bench-recon` run's rows.csv on the same images and levels.

    python score_tuning.py IMAGES_DIR ROWS_CSV WEIGHTS.safetensors [...]

Each case is simulated by `scatterscope.learned_case` as the benchmark
simulates it (256-pixel sensor at the centre of a 384 grid, paper preset,
seed 0; the built-in scenes rendered onto the sensor's field, the rest of
the grid dark, as `bench-recon` places them) and run through the network
in PyTorch (the engine's layers, `learned_model.py`). Only the tuning
split is read. Used to measure the ceiling of a larger network
(BENCHMARKS.md, "The learned reconstruction").
"""

import csv
import os
import sys

import numpy as np
import torch
from PIL import Image
from safetensors import safe_open
from safetensors.torch import load_file

import learned_model as lm
import scatterscope
from train_learned import PAPER_PHOTONS, psnr

LEVELS = (0.1, 1.0, 10.0)
GRID, SENSOR = 384, 256


def load(path):
    with safe_open(path, "pt") as f:
        channels = tuple(int(c) for c in f.metadata()["channels"].split(","))
    model = lm.LearnedNet(channels)
    model.load_state_dict(load_file(path))
    return model.eval()


def objects(folder):
    for r in csv.DictReader(open(os.path.join(folder, "manifest.csv"))):
        if r["split"] != "tuning":
            continue
        if r["file"]:
            img = np.asarray(Image.open(os.path.join(folder, r["file"])).convert("L"), dtype=np.float64) / 255.0
        else:
            truth = scatterscope.simulate(r["name"])["truth"]
            img = np.zeros((GRID, GRID))
            m = (GRID - SENSOR) // 2
            img[m:m + SENSOR, m:m + SENSOR] = truth
        yield r["name"], img


def main():
    folder, rows_csv, weights = sys.argv[1], sys.argv[2], sys.argv[3:]
    rows = {}
    for r in csv.DictReader(open(rows_csv)):
        rows[(r["image"], float(r["level"]), r["method"])] = float(r["psnr"])
    models = [(os.path.basename(w), load(w)) for w in weights]
    torch.set_num_threads(2)
    scores = {name: {lv: [] for lv in LEVELS} for name, _ in models}
    for image, obj in objects(folder):
        for level in LEVELS:
            c = scatterscope.learned_case(obj, SENSOR, seed=0, preset="paper", photons=PAPER_PHOTONS * level)
            best = rows[(image, level, "rl-sum (best iteration by truth)")]
            cv = rows[(image, level, "rl-sum (cross-validated stop)")]
            for name, model in models:
                with torch.no_grad():
                    out = model(torch.from_numpy(c["inputs"][None]))[0, 0].numpy().astype(np.float64)
                p = psnr(np.maximum(out * c["scale"], 0), c["truth"])
                scores[name][level].append((image, p - best, p - cv, max(p, cv) - best))
    for name, by_level in scores.items():
        for level, s in by_level.items():
            margins = [m for _, m, _, _ in s]
            vs_cv = [v for _, _, v, _ in s]
            oracle = [o for _, _, _, o in s]
            worst = min(s, key=lambda t: t[2])
            print(
                f"{name} {level}x ({len(s)} images): margin over RL best {np.mean(margins):+.2f} dB "
                f"(worst {min(margins):+.2f}), worst vs rl-sum CV {worst[2]:+.2f} ({worst[0]}), "
                f"truth choosing it or rl-sum CV {np.mean(oracle):+.2f}"
            )


if __name__ == "__main__":
    main()
