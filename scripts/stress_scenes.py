"""Stacks from an independent forward model, of kinds of scene labs image
that no benchmark image is: a check of the reconstructions off the
project's own simulator.

    python3 scripts/stress_scenes.py OUT_DIR --seed 1 [--levels 0.1,1,10]

The forward model is written here in numpy from the paper's Eq. 6 and
shares no code with the library: the infinite-medium ST-PSF
h(x, y, t) = c (4 pi D c t)^(-3/2) exp(-(x^2 + y^2 + z0^2) / (4 D c t) - mu_a c t)
of the paper preset (mu_a 1/cm, mu_s 5/cm, g 0.99, n 1.4, 3 cm; 256
pixels over 50 cm; 30 bins of 4 ps from 0), evaluated at the points of a
grid of half the pixel pitch and at eight times in each bin (midpoints),
scaled so that the kernels of all 30 bins carry 450 photons per unit
object pixel at 1x, convolved with an object drawn on that fine grid
(periodic on a grid 64 pixels wider than the sensor on each side), each
sensor pixel the sum of 2 x 2 fine pixels whose blocks start one fine
pixel off the object grid's, the bins carrying less than one photon per
unit pixel left out (as the preset's min-bin-photons does), and Poisson
counts drawn by numpy. The truth is the object averaged over each sensor
pixel's area.

Each stack is written as KIND_LEVELx/counts.npy (float32, bins x rows x
cols) with counts.json, the stack metadata `scatterscope reconstruct`
reads, and KIND_LEVELx/truth.npy (float64). Nine kinds: beads (sigma 1.5
px, brightness over 1.3 decades), flat (a flat field with a faint
gradient), terrain (fractal), fibres (thin curves), points (sparse),
dark (one small object on black), letters, dim_bright (a dim texture with
bright spots), mosaic (piecewise-flat cells). `--seed` draws other scenes
of the same kinds.
"""

import argparse
import json
import math
import os

import numpy as np

SENSOR = 256
MARGIN = 64
FINE = 2
PITCH_CM = 50.0 / SENSOR
MEDIUM = {"mu_a": 1.0, "mu_s": 5.0, "g": 0.99, "n": 1.4, "z0": 3.0}
BIN_PS = 4.0
BINS = 30
PHOTONS = 450.0
TIMES_PER_BIN = 8
C_CM_PER_PS = 299792458.0 * 100.0 / 1e12


def kernels():
    """The fine grid's kernels of every bin (bins, n, n), origin-centred,
    each fine pixel's share of a unit coarse pixel's 450 photons over all
    bins, and each bin's photons per unit coarse pixel."""
    m = MEDIUM
    d = 1.0 / (3.0 * (m["mu_a"] + (1.0 - m["g"]) * m["mu_s"]))
    c = C_CM_PER_PS / m["n"]
    n = (SENSOR + 2 * MARGIN) * FINE
    p = PITCH_CM / FINE
    f = np.fft.fftfreq(n) * n * p
    r2 = f[:, None] ** 2 + f[None, :] ** 2
    out = np.zeros((BINS, n, n))
    for k in range(BINS):
        for j in range(TIMES_PER_BIN):
            t = (k + (j + 0.5) / TIMES_PER_BIN) * BIN_PS
            four_dct = 4.0 * d * c * t
            h = c / (math.pi * four_dct) ** 1.5 * np.exp(-(r2 + m["z0"] ** 2) / four_dct - m["mu_a"] * c * t)
            out[k] += h * p * p * BIN_PS / TIMES_PER_BIN
    # Photons per unit coarse pixel: FINE^2 fine pixels of the kernel's sum.
    per_bin = out.sum(axis=(1, 2)) * FINE * FINE
    scale = PHOTONS / per_bin.sum()
    return out * scale, per_bin * scale


# ----------------------------------------------------------------- scenes
# Drawn on the fine grid ((SENSOR + 2 MARGIN) * FINE pixels), values in
# [0, 1]; lengths below are in sensor pixels.

N = (SENSOR + 2 * MARGIN) * FINE


def yx():
    return (np.mgrid[:N, :N].astype(np.float64) + 0.5) / FINE


def centre_points(rng, k, spread=0.45):
    """k points over the sensor's field (sensor pixels, object grid)."""
    return MARGIN + SENSOR * (0.5 + rng.uniform(-spread, spread, (k, 2)))


def beads(rng):
    y, x = yx()
    img = np.zeros((N, N))
    for cy, cx in centre_points(rng, 60):
        a = 10 ** rng.uniform(-1.3, 0.0)
        img += a * np.exp(-((y - cy) ** 2 + (x - cx) ** 2) / (2 * 1.5**2))
    return np.clip(img, 0, 1)


def flat(rng):
    y, x = yx()
    t = rng.uniform(0, 2 * np.pi)
    u = ((x - MARGIN) * np.cos(t) + (y - MARGIN) * np.sin(t)) / SENSOR
    return np.clip(0.5 + 0.05 * u, 0, 1)


def terrain(rng):
    fy = np.fft.fftfreq(N)[:, None]
    fx = np.fft.fftfreq(N)[None, :]
    f = np.hypot(fy, fx)
    f[0, 0] = 1.0
    spec = (rng.normal(size=(N, N)) + 1j * rng.normal(size=(N, N))) * f**-1.6
    spec[0, 0] = 0
    z = np.fft.ifft2(spec).real
    z = (z - z.min()) / (z.max() - z.min())
    return z


def fibres(rng):
    y, x = yx()
    img = np.zeros((N, N))
    for _ in range(6):
        (cy, cx), = centre_points(rng, 1, 0.3)
        a0, a1 = rng.uniform(0, 2 * np.pi, 2)
        amp = rng.uniform(10, 40)
        s = np.linspace(-1, 1, 4000)
        py = cy + 110 * s * np.sin(a0) + amp * np.sin(3 * s + a1)
        px = cx + 110 * s * np.cos(a0) + amp * np.cos(2 * s + a1)
        iy = np.clip((py * FINE).astype(int), 0, N - 1)
        ix = np.clip((px * FINE).astype(int), 0, N - 1)
        img[iy, ix] = rng.uniform(0.6, 1.0)
    from scipy.ndimage import grey_dilation
    return grey_dilation(img, size=(FINE, FINE))


def points(rng):
    img = np.zeros((N, N))
    for cy, cx in centre_points(rng, 25):
        iy, ix = int(cy) * FINE, int(cx) * FINE
        img[iy:iy + FINE, ix:ix + FINE] = rng.uniform(0.3, 1.0)
    return img


def dark(rng):
    y, x = yx()
    (cy, cx), = centre_points(rng, 1, 0.2)
    return 0.8 * (((y - cy) ** 2 + (x - cx) ** 2) < 4.0**2)


def letters(rng):
    from PIL import Image, ImageDraw, ImageFont
    im = Image.new("L", (N, N), 0)
    draw = ImageDraw.Draw(im)
    words = ["SCAT", "LAB", "FOAM", "PULSE", "SPAD"]
    for i in range(3):
        word = words[rng.integers(len(words))]
        font = ImageFont.load_default(size=int(FINE * rng.uniform(24, 48)))
        xy = (int((MARGIN + 20 + rng.uniform(0, 80)) * FINE), int((MARGIN + 30 + 70 * i) * FINE))
        draw.text(xy, word, fill=255, font=font)
    return np.asarray(im, dtype=np.float64) / 255.0


def dim_bright(rng):
    y, x = yx()
    base = 0.05 * terrain(rng)
    for cy, cx in centre_points(rng, 5):
        base += np.exp(-((y - cy) ** 2 + (x - cx) ** 2) / (2 * 1.0**2))
    return np.clip(base, 0, 1)


def mosaic(rng):
    from scipy.spatial import cKDTree
    y, x = yx()
    seeds = MARGIN + rng.uniform(-0.2, 1.2, (40, 2)) * SENSOR
    values = rng.uniform(0, 1, len(seeds))
    _, idx = cKDTree(seeds).query(np.stack([y.ravel(), x.ravel()], 1))
    return values[idx].reshape(N, N)


KINDS = [beads, flat, terrain, fibres, points, dark, letters, dim_bright, mosaic]


# ------------------------------------------------------------- the stacks


def blocks(a, offset):
    """Each sensor pixel's FINE x FINE block of `a` (..., N, N), summed,
    the blocks starting `offset` fine pixels off the object grid's."""
    start = MARGIN * FINE + offset
    a = a[..., start:start + SENSOR * FINE, start:start + SENSOR * FINE]
    shape = a.shape[:-2] + (SENSOR, FINE, SENSOR, FINE)
    return a.reshape(shape).sum(axis=(-3, -1))


def stack_meta(kept, seed, source):
    """The metadata `scatterscope reconstruct` reads for these counts."""
    m = MEDIUM
    return {
        "version": 1,
        "kind": "counts",
        "bin_starts_ps": [k * BIN_PS for k in kept],
        "bin_width_ps": BIN_PS,
        "pixel_pitch_cm": PITCH_CM,
        "setup": {
            "medium": {
                "mu_a_per_cm": m["mu_a"], "mu_s_per_cm": m["mu_s"], "g": m["g"],
                "refractive_index": m["n"], "thickness_cm": m["z0"], "model": "infinite",
            },
            "sensor": {"fov_cm": 50.0, "width_px": SENSOR, "height_px": SENSOR},
            "bins": {"start_ps": 0.0, "width_ps": BIN_PS, "count": BINS},
            "total_photons": PHOTONS,
            "min_bin_photons": 1.0,
            "irf": None,
        },
        "sampling": "integrated",
        "dropped_bins": [],
        "clamped_negative": 0,
        "seed": seed,
        "source": source,
        "boundary": "sensor",
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out")
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--levels", default="0.1,1,10")
    args = ap.parse_args()
    levels = [float(v) for v in args.levels.split(",")]
    kern, per_bin = kernels()
    kept = [k for k in range(BINS) if per_bin[k] >= 1.0]
    spectra = np.fft.rfft2(kern[kept])
    for i, kind in enumerate(KINDS):
        rng = np.random.default_rng([args.seed, i])
        obj = kind(rng)
        expected = np.fft.irfft2(np.fft.rfft2(obj)[None] * spectra, s=(N, N))
        window = np.maximum(blocks(expected, 1), 0.0)
        truth = blocks(obj, 1) / FINE**2
        for j, level in enumerate(levels):
            name = f"{kind.__name__}_{level:g}x"
            folder = os.path.join(args.out, name)
            os.makedirs(folder, exist_ok=True)
            seed = 1000 * args.seed + 10 * i + j
            counts = np.random.default_rng(seed).poisson(window * level).astype(np.float32)
            np.save(os.path.join(folder, "counts.npy"), counts)
            meta = stack_meta(kept, seed, f"stress_scenes.py {kind.__name__} seed {args.seed} level {level:g}")
            meta["setup"]["total_photons"] = PHOTONS * level
            with open(os.path.join(folder, "counts.json"), "w") as fh:
                json.dump(meta, fh, indent=1)
            np.save(os.path.join(folder, "truth.npy"), truth)
            print(f"{name}: {counts.sum():.0f} photons, {len(kept)} bins")


if __name__ == "__main__":
    main()
