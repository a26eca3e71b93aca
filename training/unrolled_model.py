"""The learned reconstruction's unrolled network in PyTorch, as the Rust
engine runs it (src/reconstruct/learned/), and its safetensors export.

Design (b): the counts in every stage. From the last Richardson-Lucy
iterate of the time-summed stack (on the model's whole grid), each of
`stages` stages
  1. gives a small two-scale U-Net (shared by the stages) the current estimate, the log of its EM ratio (where the
     counts ask for more or less light), the 10th and 40th iterates, the
     scaled counts, the light level and the blur width, and adds its
     output times the stage's own learned weight to the estimate on the
     sensor window, floored at `FLOOR` (an EM step cannot revive a zero);
  2. takes `em_steps` exact Richardson-Lucy (EM) steps through the
     reconstruction's own padded operator: the time-summed kernel on the
     model's grid, observed on the sensor window, the background in the
     denominator, `H^T 1` the normaliser.
So the output is an EM iterate of the counts: its last steps are exact
Poisson steps. Every image channel is divided by the base iterate's mean
(`scale`), as design (a) does; the data steps work in counts.
"""

import json

import torch
import torch.nn as nn
import torch.nn.functional as F


FORMAT = "scatterscope-learned"
FORMAT_VERSION = "2"
ARCHITECTURE = "unrolled-em"
CHECKPOINTS = (10, 40, 150)
# Stage inputs: estimate, log EM ratio, iterates 10 and 40, scaled
# counts, light level, blur width.
STAGE_INPUTS = 7
# The estimate's floor after a correction (normalised units).
FLOOR = 1e-3
# The EM ratio's logarithm is clamped to +-LOG_RATIO_CLAMP.
LOG_RATIO_CLAMP = 5.0


def block(cin, cout):
    """Two 3x3 convolutions with ReLUs (the U-Net's unit)."""
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, padding=1),
        nn.ReLU(),
        nn.Conv2d(cout, cout, 3, padding=1),
        nn.ReLU(),
    )
# The EM denominator's guard, times the mean count (as the library's
# DENOMINATOR_GUARD).
DENOMINATOR_GUARD = 1e-6
# Pixels of the grid whose sensitivity is at most this times the kernel
# mass keep their value: the sensor barely sees them, and in float32 their
# EM ratio would be the transforms' rounding over a tiny number.
UNSEEN = 1e-4


class SharedUNet(nn.Module):
    """The two-scale U-Net of design (a) with STAGE_INPUTS inputs and a
    plain correction output (the stage adds it)."""

    def __init__(self, channels):
        super().__init__()
        c0, c1, c2 = channels
        self.enc0 = block(STAGE_INPUTS, c0)
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
        return self.out(d0)[..., :h, :w]


class Operator:
    """The time-summed model of a batch on a common grid: `kernel` (B, G,
    G, origin-centred), the sensor window at `offset` of side `side`,
    `background` (B,) summed per pixel, `counts` (B, side, side)."""

    def __init__(self, kernel, offset, side, background, counts):
        self.spec = torch.fft.rfft2(kernel)
        self.grid = kernel.shape[-2:]
        self.offset = offset
        self.side = side
        self.background = background[:, None, None]
        self.counts = counts
        self.mass = kernel.sum(dim=(-2, -1))
        # H^T 1 in float64: its small values decide which pixels are seen.
        ones = torch.ones_like(counts, dtype=torch.float64)
        padded = self._pad(ones)
        spec64 = torch.fft.rfft2(kernel.double())
        self.sensitivity = torch.fft.irfft2(torch.fft.rfft2(padded) * spec64.conj(), s=self.grid).to(kernel.dtype)
        mean = counts.mean(dim=(-2, -1))
        self.guard = (DENOMINATOR_GUARD * mean)[:, None, None]
        self.seen = self.sensitivity > (UNSEEN * self.mass)[:, None, None]

    def window(self, g):
        o, n = self.offset, self.side
        return g[..., o[0]:o[0] + n, o[1]:o[1] + n]

    def apply(self, x):
        y = torch.fft.irfft2(torch.fft.rfft2(x) * self.spec, s=self.grid)
        return self.window(y)

    def _pad(self, r):
        o, n = self.offset, self.side
        return F.pad(r, (o[1], self.grid[1] - o[1] - n, o[0], self.grid[0] - o[0] - n))

    def adjoint(self, r):
        return torch.fft.irfft2(torch.fft.rfft2(self._pad(r)) * self.spec.conj(), s=self.grid)

    def ratio(self, x):
        """The EM factor `H^T(m / (H x + bg)) / H^T 1` on the grid (1 where
        the sensor does not see)."""
        d = torch.clamp(self.apply(x) + self.background, min=self.guard)
        back = self.adjoint(self.counts / d)
        return torch.where(self.seen, back / torch.where(self.seen, self.sensitivity, 1.0), 1.0)

    def em(self, x):
        return x * torch.clamp(self.ratio(x), min=0.0)


class UnrolledNet(nn.Module):
    def __init__(self, channels=(16, 32, 48), stages=3, em_steps=2):
        super().__init__()
        self.channels = tuple(channels)
        self.stages = stages
        self.em_steps = em_steps
        self.cnn = SharedUNet(channels)
        self.stage_weights = nn.Parameter(torch.ones(stages))

    def forward(self, base, features, op, scale, return_grid=False):
        """`base` (B, G, G): the last RL iterate in counts' units;
        `features` (B, 6, n, n): design (a)'s inputs (iterates 10, 40, 150,
        scaled counts, level, width, each image over `scale`); `scale`
        (B,). Returns the estimate on the window over `scale`."""
        s = scale[:, None, None]
        x = base
        fixed = torch.cat([features[:, 0:2], features[:, 3:6]], 1)
        for k in range(self.stages):
            r = op.window(op.ratio(x))
            log_r = torch.clamp(torch.log(torch.clamp(r, min=1e-30)), -LOG_RATIO_CLAMP, LOG_RATIO_CLAMP)
            win = op.window(x) / s
            inp = torch.cat([win[:, None], log_r[:, None], fixed], 1)
            corrected = torch.clamp(win + self.stage_weights[k] * self.cnn(inp)[:, 0], min=FLOOR) * s
            o, n = op.offset, op.side
            x = x.clone()
            x[..., o[0]:o[0] + n, o[1]:o[1] + n] = corrected
            for _ in range(self.em_steps):
                x = op.em(x)
        out = op.window(x) / s
        return (out, x) if return_grid else out

    def parameters_count(self):
        return sum(p.numel() for p in self.parameters())


def export(model, path, ranges, extra):
    """Writes `model` as the project's safetensors file: the shared CNN's
    tensors, `stage_weights`, and the metadata Rust checks (format,
    architecture, channels, stages, EM steps, checkpoints, ranges as JSON)
    plus `extra` (how it was trained)."""
    from safetensors.torch import save_file

    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "architecture": ARCHITECTURE,
        "channels": ",".join(str(c) for c in model.channels),
        "stages": str(model.stages),
        "em_steps": str(model.em_steps),
        "inputs": str(STAGE_INPUTS),
        "checkpoints": ",".join(str(c) for c in CHECKPOINTS),
        "ranges": json.dumps(ranges),
    }
    meta.update({k: str(v) for k, v in extra.items()})
    tensors = {k: v.detach().to(torch.float32).contiguous() for k, v in model.state_dict().items()}
    tensors = {k.removeprefix("cnn."): v for k, v in tensors.items()}
    save_file(tensors, path, metadata=meta)
