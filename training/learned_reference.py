"""PyTorch's output of the learned reconstruction's network, committed as
small fixtures so that the Rust engine (src/reconstruct/learned/net.rs)
is checked against it: a network of the same architecture with small
random weights (channels 4, 6, 8; seed 7) and random inputs of an odd
size (6 x 21 x 14: the padding to multiples of 4 and the crop), and the
embedded weights on the same inputs.

    python learned_reference.py --embedded ../weights/learned-unet2.safetensors \\
        --out ../tests/fixtures/learned
"""

import argparse
import os

import numpy as np
import torch
from safetensors.torch import load_file

import learned_model as lm


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--embedded", required=True)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    torch.manual_seed(7)
    small = lm.LearnedNet((4, 6, 8)).eval()
    with torch.no_grad():
        for p in small.parameters():
            p.uniform_(-0.3, 0.3)
    lm.export(
        small,
        os.path.join(args.out, "small.safetensors"),
        {"photons_per_pixel": [1.0, 10.0], "kernel_width_px": [1.0, 10.0], "background_share_max": 0.0},
        {"trained": "random weights for the engine's fixture (seed 7)"},
    )
    x = torch.rand((1, lm.INPUTS, 21, 14), generator=torch.Generator().manual_seed(8)) * 2.0
    np.save(os.path.join(args.out, "input.npy"), x[0].numpy().astype(np.float32))
    with torch.no_grad():
        np.save(os.path.join(args.out, "small_output.npy"), small(x)[0, 0].numpy().astype(np.float32))
        tensors = load_file(args.embedded)
        c = (tensors["enc0.0.weight"].shape[0], tensors["enc1.0.weight"].shape[0], tensors["mid.0.weight"].shape[0])
        embedded = lm.LearnedNet(c).eval()
        embedded.load_state_dict(tensors)
        np.save(os.path.join(args.out, "embedded_output.npy"), embedded(x)[0, 0].numpy().astype(np.float32))


if __name__ == "__main__":
    main()
