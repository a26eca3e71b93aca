"""The learned reconstruction's network in PyTorch, as the Rust engine runs
it (src/reconstruct/learned/net.rs), and its safetensors export.

A two-scale U-Net: two 3x3 convolutions with ReLU per block at three
resolutions (channels c0, c1, c2), 2x2 average pooling down, nearest
upsampling and concatenation (upsampled first, then the encoder's map)
up, a last 3x3 convolution whose output is added to the input's base
channel (the last Richardson-Lucy iterate). Inputs whose sides are not
multiples of 4 are padded at the bottom and right by repeating the last
row and column, and the output cropped, as the engine does.
"""

import json

import torch
import torch.nn as nn
import torch.nn.functional as F

FORMAT = "scatterscope-learned"
FORMAT_VERSION = "1"
ARCHITECTURE = "unet2"
# What src/reconstruct/learned/inputs.rs computes: the Richardson-Lucy
# iterates, then the scaled counts, the light level and the blur width.
CHECKPOINTS = (10, 40, 150)
INPUTS = len(CHECKPOINTS) + 3
BASE = len(CHECKPOINTS) - 1


def block(cin, cout):
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, padding=1),
        nn.ReLU(),
        nn.Conv2d(cout, cout, 3, padding=1),
        nn.ReLU(),
    )


class LearnedNet(nn.Module):
    def __init__(self, channels=(16, 32, 48)):
        super().__init__()
        c0, c1, c2 = channels
        self.channels = tuple(channels)
        self.enc0 = block(INPUTS, c0)
        self.enc1 = block(c0, c1)
        self.mid = block(c1, c2)
        self.dec1 = block(c2 + c1, c1)
        self.dec0 = block(c1 + c0, c0)
        self.out = nn.Conv2d(c0, 1, 3, padding=1)

    def forward(self, x):
        h, w = x.shape[-2:]
        ph, pw = (-h) % 4, (-w) % 4
        if ph or pw:
            x = F.pad(x, (0, pw, 0, ph), mode="replicate")
        e0 = self.enc0(x)
        e1 = self.enc1(F.avg_pool2d(e0, 2))
        m = self.mid(F.avg_pool2d(e1, 2))
        d1 = self.dec1(torch.cat([F.interpolate(m, scale_factor=2, mode="nearest"), e1], 1))
        d0 = self.dec0(torch.cat([F.interpolate(d1, scale_factor=2, mode="nearest"), e0], 1))
        y = x[:, BASE:BASE + 1] + self.out(d0)
        return y[..., :h, :w]

    def parameters_count(self):
        return sum(p.numel() for p in self.parameters())


def export(model, path, ranges, extra):
    """Writes `model` as the project's safetensors file: the state dict
    (f32) and the metadata Rust checks (format, architecture, channels,
    checkpoints, ranges as JSON) plus `extra` (how it was trained)."""
    from safetensors.torch import save_file

    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "architecture": ARCHITECTURE,
        "channels": ",".join(str(c) for c in model.channels),
        "inputs": str(INPUTS),
        "checkpoints": ",".join(str(c) for c in CHECKPOINTS),
        "ranges": json.dumps(ranges),
    }
    meta.update({k: str(v) for k, v in extra.items()})
    tensors = {k: v.detach().to(torch.float32).contiguous() for k, v in model.state_dict().items()}
    save_file(tensors, path, metadata=meta)
