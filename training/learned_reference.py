"""PyTorch's output of the learned reconstruction's unrolled network,
committed as small fixtures so that the Rust engine
(src/reconstruct/learned/) is checked against it: a network of the same
architecture with small random weights (channels 4, 6, 8; 2 stages of 2 EM
steps; seed 7) and the embedded weights, each on one small case the
library simulates (a 32-pixel sensor at the paper's pitch on a 160-pixel
object of seeded glows, seed 5), in float64: the stages' data steps are
the same operator in both, so the outputs agree to the CNN's float32
rounding.

    python learned_reference.py --embedded ../weights/learned-unrolled.safetensors \\
        --out ../tests/fixtures/learned
"""

import argparse
import os

import numpy as np
import torch
from safetensors.torch import load_file

import unrolled_model as um

SENSOR = 32
OBJECT = 160
SEED = 5


def glows():
    rng = np.random.default_rng(11)
    yy, xx = np.mgrid[:OBJECT, :OBJECT].astype(np.float64)
    img = np.zeros((OBJECT, OBJECT))
    for _ in range(6):
        cy, cx = rng.uniform(0.35, 0.65, 2) * OBJECT
        r = rng.uniform(1.5, 6.0)
        img += rng.uniform(0.2, 1.0) * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * r * r))
    return img / img.max()


def output(model, c):
    op = um.Operator(
        torch.from_numpy(c["kernel"][None]),
        tuple(c["sensor_offset"]),
        SENSOR,
        torch.tensor([c["background"]], dtype=torch.float64),
        torch.from_numpy(c["counts"][None]),
    )
    with torch.no_grad():
        out = model(
            torch.from_numpy(c["base_grid"][None]),
            torch.from_numpy(c["inputs"][None].astype(np.float64)),
            op,
            torch.tensor([c["scale"]], dtype=torch.float64),
        )
    return out[0].numpy() * c["scale"]


def main():
    import scatterscope

    ap = argparse.ArgumentParser()
    ap.add_argument("--embedded", required=True)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    obj = glows()
    np.save(os.path.join(args.out, "object.npy"), obj)
    c = scatterscope.learned_case(obj, SENSOR, seed=SEED, preset="paper", fov_cm=50.0 * SENSOR / 256)
    torch.manual_seed(7)
    small = um.UnrolledNet((4, 6, 8), stages=2, em_steps=2).eval()
    with torch.no_grad():
        for p in small.parameters():
            p.uniform_(-0.3, 0.3)
    um.export(
        small,
        os.path.join(args.out, "small.safetensors"),
        {"photons_per_pixel": [1.0, 10.0], "kernel_width_px": [1.0, 10.0], "background_share_max": 0.0},
        {"trained": "random weights for the engine's fixture (seed 7)"},
    )
    np.save(os.path.join(args.out, "small_output.npy"), output(small.double(), c))
    tensors = load_file(args.embedded)
    from safetensors import safe_open
    with safe_open(args.embedded, "pt") as f:
        meta = f.metadata()
    channels = tuple(int(v) for v in meta["channels"].split(","))
    embedded = um.UnrolledNet(channels, int(meta["stages"]), int(meta["em_steps"])).eval()
    embedded.load_state_dict({("stage_weights" if k == "stage_weights" else "cnn." + k): v for k, v in tensors.items()})
    np.save(os.path.join(args.out, "embedded_output.npy"), output(embedded.double(), c))


if __name__ == "__main__":
    main()
