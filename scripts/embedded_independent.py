#!/usr/bin/env python3
"""Cubes of the object inside the medium from a forward model written
apart from the project's: numpy and scipy only, no code shared.

Where `scatterscope simulate-embedded` integrates the diffusion kernels
over each bin and pixel and takes the beam's light at the object plane as
a fixed map times the front slab's time profile, this model samples the
slab Green's functions at points (pixel centres, 10 ps steps), puts the
faces at zero fluence on the physical boundaries (no extrapolation
distance) with five image pairs, and keeps the light at the object plane
time-varying (its Gaussian widens as the front slab's light arrives): the
cube is the 3-D convolution, in space and time, of the back slab's Green's
function with the object times that light. The camera: Poisson counts of
the light plus per-pixel dark counts scaled by a gain, the dark level
subtracted less a per-pixel residual, filtered, hot and dead pixels, as
labs publish it (scipy.io.savemat: a level 5 cube of rows x columns x bins
and the pixel centres in mm).

    python3 scripts/embedded_independent.py OUT --target letter:X --seed 101

Needs numpy and scipy (scripts/fetch_python_deps.sh puts them under
target/pydeps).
"""

import argparse
import os

import numpy as np
import scipy.io as sio

C_CM_PER_PS = 0.0299792458


def slab_green(rho2, t, thickness, mus_red, mu_a, n):
    """Transmitted flux density per cm^2 per ps through a slab at lateral
    squared distance rho2 (cm^2) and time t (ps) after a pencil beam's
    entry: zero fluence on the faces, an isotropic source one transport
    mean free path deep, five image pairs."""
    c = C_CM_PER_PS / n
    d = 1.0 / (3.0 * (mu_a + mus_red))
    z0 = 1.0 / (mu_a + mus_red)
    t = np.maximum(t, 1e-9)
    s = 0.0
    for m in range(-5, 6):
        z1 = (1 - 2 * m) * thickness - 4 * m * 0.0 - z0
        z2 = (1 - 2 * m) * thickness + z0
        s = s + z1 * np.exp(-z1**2 / (4 * d * c * t)) - z2 * np.exp(-z2**2 / (4 * d * c * t))
    return (
        (4 * np.pi * d * c) ** -1.5
        * t**-2.5
        * np.exp(-mu_a * c * t - rho2 / (4 * d * c * t))
        * s
        / 2.0
    )


def render(target, size, pitch_cm):
    yy, xx = np.mgrid[0:size, 0:size]
    x = (xx - (size - 1) / 2) * pitch_cm
    y = (yy - (size - 1) / 2) * pitch_cm
    kind, value = target.split(":")
    if kind == "slits":
        sep = float(value)
        return ((np.abs(y) <= 1.0) & (np.abs(np.abs(x) - sep / 2) <= sep / 4)).astype(float)
    # Letters as strokes of width 0.5 cm over a 3.4 cm square.
    strokes = {
        "X": [((-1.5, -1.7), (1.5, 1.7)), ((-1.5, 1.7), (1.5, -1.7))],
        "T": [((-1.6, -1.6), (1.6, -1.6)), ((0.0, -1.6), (0.0, 1.7))],
        "H": [((-1.3, -1.7), (-1.3, 1.7)), ((1.3, -1.7), (1.3, 1.7)), ((-1.3, 0.0), (1.3, 0.0))],
        "L": [((-1.2, -1.7), (-1.2, 1.6)), ((-1.2, 1.6), (1.4, 1.6))],
        "V": [((-1.5, -1.7), (0.0, 1.7)), ((0.0, 1.7), (1.5, -1.7))],
    }[value]
    img = np.zeros((size, size))
    for (ax, ay), (bx, by) in strokes:
        px, py = x - ax, y - ay
        dx, dy = bx - ax, by - ay
        u = np.clip((px * dx + py * dy) / (dx * dx + dy * dy), 0, 1)
        dist = np.hypot(px - u * dx, py - u * dy)
        img = np.maximum(img, (dist <= 0.25).astype(float))
    return img


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out")
    ap.add_argument("--target", required=True, help="letter:X|T|H|L|V or slits:CM")
    ap.add_argument("--seed", type=int, default=101)
    ap.add_argument("--photons", type=float, default=4e5)
    ap.add_argument("--gain", type=float, default=1.0)
    ap.add_argument("--bins", type=int, default=160)
    ap.add_argument("--bin-ps", type=float, default=50.0)
    ap.add_argument("--time-zero-ps", type=float, default=1000.0)
    a = ap.parse_args()
    size, pitch = 32, 0.14
    front = back = dict(thickness=2.5, mus_red=71.0, mu_a=0.14, n=1.0)
    beam_sigma = 6.0 / np.sqrt(8 * np.log(2))
    pad = 40
    g = size + 2 * pad
    step = 10.0
    t_fine = np.arange(int((a.bins * a.bin_ps - a.time_zero_ps) / step)) * step + step / 2
    # The light at the object plane: the front slab's Green's function
    # convolved with the Gaussian beam, exactly (both Gaussians in space).
    yy, xx = np.mgrid[0:g, 0:g]
    r2 = ((xx - (g - 1) / 2) ** 2 + (yy - (g - 1) / 2) ** 2) * pitch**2
    c = C_CM_PER_PS / front["n"]
    d = 1.0 / (3.0 * (front["mu_a"] + front["mus_red"]))
    flux = np.array([slab_green(0.0, t, **front) * 4 * np.pi * d * c * t for t in t_fine])
    var = beam_sigma**2 + 2 * d * c * t_fine
    light = flux[:, None, None] * np.exp(-r2[None] / (2 * var[:, None, None])) / (2 * np.pi * var[:, None, None])
    obj = np.zeros((g, g))
    obj[pad : pad + size, pad : pad + size] = render(a.target, size, pitch)
    source = light * obj[None]
    # The back slab's Green's function at pixel-centre offsets.
    off = (np.arange(g) - g // 2) * pitch
    rho2 = off[None, :] ** 2 + off[:, None] ** 2
    kern = slab_green(rho2[None], t_fine[:, None, None], **back) * pitch**2
    kern = np.fft.ifftshift(kern, axes=(1, 2))
    nt = 2 * len(t_fine)
    cube_fine = np.fft.irfftn(
        np.fft.rfftn(source, s=(nt, g, g), axes=(0, 1, 2))
        * np.fft.rfftn(kern, s=(nt, g, g), axes=(0, 1, 2)),
        s=(nt, g, g),
        axes=(0, 1, 2),
    )[: len(t_fine), pad : pad + size, pad : pad + size]
    cube_fine = np.maximum(cube_fine, 0.0)
    # Into the camera's bins on its clock.
    per_bin = int(round(a.bin_ps / step))
    lead = int(round(a.time_zero_ps / step))
    fine = np.zeros((a.bins * per_bin, size, size))
    fine[lead : lead + len(t_fine)] = cube_fine[: a.bins * per_bin - lead]
    expected = fine.reshape(a.bins, per_bin, size, size).sum(axis=1)
    expected *= a.photons / expected.sum()
    rng = np.random.default_rng(a.seed)
    dark = rng.uniform(10, 30, (size, size))
    residual = rng.uniform(2.6, 8.7, (size, size))
    inner = [(i, j) for i in range(2, size - 2) for j in range(2, size - 2)]
    picks = rng.choice(len(inner), 24, replace=False)
    bad = [inner[p] for p in picks]
    for p in bad[20:22]:
        dark[p] *= 50
    raw = a.gain * rng.poisson((expected + dark[None]) / a.gain)
    cube = raw - (dark - residual)[None]
    for i, j in bad[22:]:
        cube[:, i, j] = -(dark[i, j] - residual[i, j])
    for i, j in bad[:20]:
        near = [(i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1)][: rng.integers(2, 5)]
        cube[:, i, j] = np.mean([cube[:, q[0], q[1]] for q in near], axis=0)
    os.makedirs(a.out, exist_ok=True)
    sio.savemat(os.path.join(a.out, "cube.mat"), {"cube": np.transpose(cube, (1, 2, 0))}, do_compression=True)
    xs = np.arange(size) * pitch * 10
    sio.savemat(
        os.path.join(a.out, "positions.mat"),
        {"x": np.tile(xs, (size, 1)), "y": np.tile(xs[:, None], (1, size))},
    )
    np.save(os.path.join(a.out, "truth.npy"), obj[pad : pad + size, pad : pad + size].astype(np.float32))


if __name__ == "__main__":
    main()
