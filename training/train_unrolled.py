"""Trains the learned reconstruction's unrolled network (design (b):
`unrolled_model.py`) on this machine's CPU, from stacks simulated with
more than one discretisation of the physics. Resumable: everything it
has done lives in `--work`, and the same command carries on from there.

    python train_unrolled.py --work /tmp/unrolled --out ../weights/learned-unrolled.safetensors \\
        [--cases 3000] [--steps 6000] [--threads 2] [--tuning IMAGES_DIR]

Data (nothing downloaded; no benchmark image is read but the tuning
images of `--tuning`, and those only scored):
- objects on a 352 x 352 grid whose centre a 128 x 128 sensor sees, at
  the paper's pixel pitch: crops of the ten scikit-image images the
  benchmark does not use, design (a)'s drawn scenes, and the kinds labs
  image that design (a) lost on: point fields sparse and dense, beads of
  several sizes and brightnesses, thin curved fibres, flat and slowly
  varying fields (not stretched to [0, 1]), scenes of high dynamic range,
  dark fields with a few small objects, and letters;
- each simulated by `scatterscope.learned_case` at a light level drawn
  log-uniformly from 0.02x to 20x the preset's (the thinned halves of the
  guard reach 0.025x), the slab jittered around the paper preset, in a
  quarter of the cases an IRF and a background, in a fifth the light
  crossing a medium a few per cent off the stated one; the kernels
  integrated over pixel and bin (the reconstruction's own model) in 40 %
  of the cases, point-sampled in 30 %, and point-sampled on a grid of half
  the pitch whose 2 x 2 blocks the sensor sums, half a pixel off or not,
  in 30 % (IRF cases are integrated: point sampling has no IRF).

`--medium monte-carlo` trains on light as it travels instead: every case
(and the tuning set) simulated and modelled with the library's Monte Carlo
medium (`physics::transport`, kernels cached on disk by physics), the
preset's bins moved to where its light arrives. So that the kernels can
be reused, the medium is drawn from a lattice (mu_a x0.7/1/1.4, mu_s
x0.8/1/1.25, thickness x0.9/1/1.1; an IRF of 20, 40 or 60 ps; the
mismatched medium one of four corners of the jitter box) rather than
continuously, and every case is integrated over pixel and bin (the
transport's tallies are; point sampling does not apply). The work folder
records its medium and refuses to mix cases of two.

Training: Adam (5e-4, gradients clipped at norm 10), one-cycle cosine
schedule, batches of 8 with random flips and quarter turns of the object
and the counts together (the kernels are radially symmetric), loss the
mean over the batch of log(MSE) against the truth. A checkpoint (model,
optimiser, schedule, random state, curve) is written every
`--checkpoint-every` steps, whole or not at all.
"""

import argparse
import csv
import glob
import json
import math
import multiprocessing as mp
import os
import platform
import time

import numpy as np

OBJECT_PX = 352
SENSOR_PX = 128
GRID_PX = 216  # the common grid the batches share (>= any case's model grid: 200 at the widest jitter with an IRF)
PAPER_FOV_CM = 50.0
PAPER_PHOTONS = 450.0
PAPER = {"mu_a": 1.0, "mu_s": 5.0, "thickness_cm": 3.0}
LEVELS = (0.02, 20.0)
# The medium every case is simulated and modelled with: None for the
# preset's own (Eq. 6), or a `--medium` name; set once in `main` before the
# workers fork.
MEDIUM = None
MONTE_CARLO = "monte-carlo"
# Under the Monte Carlo medium: the jitter's lattice (factors on the
# preset), the IRFs, and the mismatched media's factors (mu_a, mu_s,
# thickness), so that the transport cache serves most cases.
LATTICE = {"mu_a": (0.7, 1.0, 1.4), "mu_s": (0.8, 1.0, 1.25), "thickness_cm": (0.9, 1.0, 1.1)}
LATTICE_IRF_PS = (20.0, 40.0, 60.0)
LATTICE_MISMATCH = ((0.9, 0.93, 0.97), (1.1, 1.07, 1.03), (0.9, 1.07, 1.03), (1.1, 0.93, 0.97))
SKIMAGE_TRAIN = [
    "clock_motion.png", "color.png", "grass.png", "gravel.png", "ihc.png",
    "microaneurysms.png", "motorcycle_left.png", "motorcycle_right.png",
    "retina.jpg", "text.png",
]
SHARD = 128  # cases per cache file


# ---------------------------------------------------------------- scenes
# Each generator returns an image with values in [0, 1].


def unit(img):
    img = np.asarray(img, dtype=np.float64)
    lo, hi = img.min(), img.max()
    return (img - lo) / (hi - lo) if hi > lo else np.zeros_like(img)


def gray(img):
    img = np.asarray(img, dtype=np.float64)
    if img.ndim == 3:
        img = img[..., :3].mean(axis=2)
    return img


def skimage_crop(rng, images):
    from skimage.transform import resize
    img = images[rng.integers(len(images))]
    h, w = img.shape
    side = int(rng.uniform(0.35, 1.0) * min(h, w))
    y, x = rng.integers(0, h - side + 1), rng.integers(0, w - side + 1)
    return unit(resize(img[y:y + side, x:x + side], (OBJECT_PX, OBJECT_PX), anti_aliasing=True))


def grid_yx(n=OBJECT_PX):
    return np.mgrid[:n, :n].astype(np.float64)


def dead_leaves(rng):
    n = OBJECT_PX
    img = np.full((n, n), rng.uniform(0, 1))
    yy, xx = grid_yx()
    for _ in range(rng.integers(30, 160)):
        r = n * rng.uniform(0.01, 0.25) ** 1.5 * 2
        cy, cx = rng.uniform(-0.1, 1.1, 2) * n
        if rng.random() < 0.5:
            mask = (yy - cy) ** 2 + (xx - cx) ** 2 < r * r
        else:
            a, b = r, r * rng.uniform(0.3, 1.0)
            t = rng.uniform(0, np.pi)
            u = (xx - cx) * np.cos(t) + (yy - cy) * np.sin(t)
            v = -(xx - cx) * np.sin(t) + (yy - cy) * np.cos(t)
            mask = (np.abs(u) < a) & (np.abs(v) < b)
        shade = rng.uniform(0, 1) + rng.uniform(-1, 1) * ((xx - cx) / n) * rng.random()
        img[mask] = shade[mask]
    return unit(img)


def shapes_on_black(rng):
    n = OBJECT_PX
    img = np.zeros((n, n))
    yy, xx = grid_yx()
    for _ in range(rng.integers(2, 14)):
        cy, cx = rng.uniform(0, 1, 2) * n
        r = rng.uniform(3, 40)
        kind = rng.integers(3)
        if kind == 0:
            mask = (yy - cy) ** 2 + (xx - cx) ** 2 < r * r
        elif kind == 1:
            mask = (np.abs(yy - cy) < r) & (np.abs(xx - cx) < r * rng.uniform(0.2, 1.5))
        else:
            mask = np.abs(yy - cy) + np.abs(xx - cx) < r
        img[mask] = rng.uniform(0.2, 1.0)
    return img


def lines(rng):
    from skimage.draw import line_aa
    n = OBJECT_PX
    img = np.zeros((n, n))
    for _ in range(rng.integers(5, 40)):
        r0, c0, r1, c1 = rng.integers(0, n, 4)
        rr, cc, val = line_aa(r0, c0, r1, c1)
        img[rr, cc] = np.maximum(img[rr, cc], val * rng.uniform(0.3, 1.0))
    if rng.random() < 0.5:
        from scipy.ndimage import gaussian_filter
        img = gaussian_filter(img, rng.uniform(0.5, 2.0))
    return unit(img)


def points(rng):
    from scipy.ndimage import gaussian_filter
    n = OBJECT_PX
    img = np.zeros((n, n))
    k = rng.integers(10, 150)
    ys, xs = rng.integers(0, n, (2, k))
    img[ys, xs] = rng.uniform(0.1, 1.0, k)
    return unit(gaussian_filter(img, rng.uniform(0.6, 3.0)))


def smooth(rng):
    n = OBJECT_PX
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(n), np.fft.fftfreq(n)))
    spec = rng.normal(size=(n, n)) + 1j * rng.normal(size=(n, n))
    if rng.random() < 0.5:
        spec *= np.exp(-((f * rng.uniform(40, 200)) ** 2))
    else:
        f[0, 0] = 1.0
        spec *= f ** -rng.uniform(1.2, 2.0)
        spec[0, 0] = 0
    return unit(np.fft.ifft2(spec).real)


def glows(rng):
    n = OBJECT_PX
    yy, xx = grid_yx()
    img = np.zeros((n, n))
    for _ in range(rng.integers(1, 9)):
        cy, cx = rng.uniform(0.1, 0.9, 2) * n
        r = rng.uniform(0.02, 0.2) * n
        img += rng.uniform(0.2, 1.0) * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * r * r))
    return unit(img)


def disc_ramp(rng):
    n = OBJECT_PX
    yy, xx = grid_yx() / n
    cy, cx = rng.uniform(0.3, 0.7, 2)
    r = np.hypot(yy - cy, xx - cx)
    a = np.arctan2(yy - cy, xx - cx) * rng.integers(1, 4) + rng.uniform(0, 6.3)
    edge = rng.uniform(0.15, 0.45)
    return unit((r < edge) * (0.5 + 0.5 * np.cos(a)) * (1 - r) + (r >= edge) * rng.uniform(0, 0.2))


def bars(rng):
    n = OBJECT_PX
    img = np.zeros((n, n)) + rng.uniform(0, 0.3)
    for _ in range(rng.integers(2, 8)):
        period = rng.uniform(4, 30)
        y0, x0 = rng.integers(0, n - 60, 2)
        h, w = rng.integers(20, 90, 2)
        yy, xx = np.mgrid[:h, :w]
        pattern = (np.sin(2 * np.pi * (xx if rng.random() < 0.5 else yy) / period) > 0) * 1.0
        img[y0:y0 + h, x0:x0 + w] = pattern[: n - y0, : n - x0] * rng.uniform(0.4, 1.0)
    return unit(img)


def sparse_points(rng):
    """A few isolated points of one or a few pixels on black."""
    n = OBJECT_PX
    img = np.zeros((n, n))
    k = rng.integers(3, 60)
    ys, xs = rng.integers(0, n, (2, k))
    img[ys, xs] = np.exp(rng.uniform(np.log(0.1), 0.0, k))
    if rng.random() < 0.4:
        from scipy.ndimage import gaussian_filter
        img = gaussian_filter(img, rng.uniform(0.3, 0.8))
        img /= max(img.max(), 1e-12)
    return img


def dense_points(rng):
    n = OBJECT_PX
    img = np.zeros((n, n))
    k = rng.integers(300, 4000)
    ys, xs = rng.integers(0, n, (2, k))
    np.maximum.at(img, (ys, xs), rng.uniform(0.1, 1.0, k))
    if rng.random() < 0.5:
        from scipy.ndimage import gaussian_filter
        img = unit(gaussian_filter(img, rng.uniform(0.4, 1.2)))
    return img


def beads(rng):
    """Gaussian beads of one or several sizes (sigma 0.7-4 px), brightness
    varied over up to two decades, on black or a faint floor."""
    n = OBJECT_PX
    yy, xx = grid_yx()
    img = np.zeros((n, n))
    k = rng.integers(5, 150)
    sizes = rng.uniform(0.7, 4.0, rng.integers(1, 4))
    for _ in range(k):
        cy, cx = rng.uniform(0, n, 2)
        s = sizes[rng.integers(len(sizes))]
        a = np.exp(rng.uniform(np.log(0.01 if rng.random() < 0.5 else 0.3), 0.0))
        y0, y1 = int(max(cy - 5 * s, 0)), int(min(cy + 5 * s + 1, n))
        x0, x1 = int(max(cx - 5 * s, 0)), int(min(cx + 5 * s + 1, n))
        img[y0:y1, x0:x1] += a * np.exp(-((yy[y0:y1, x0:x1] - cy) ** 2 + (xx[y0:y1, x0:x1] - cx) ** 2) / (2 * s * s))
    img /= max(img.max(), 1e-12)
    if rng.random() < 0.3:
        img = 0.9 * img + rng.uniform(0.0, 0.1)
    return np.clip(img, 0, 1)


def fibres(rng):
    """Thin curved fibres: smooth random curves, about a pixel wide."""
    from scipy.ndimage import gaussian_filter
    n = OBJECT_PX
    img = np.zeros((n, n))
    for _ in range(rng.integers(1, 15)):
        y, x = rng.uniform(0, n, 2)
        angle = rng.uniform(0, 2 * np.pi)
        turn = rng.uniform(0.005, 0.08)
        a = rng.uniform(0.3, 1.0)
        for _ in range(int(rng.uniform(50, 2 * n) * 2)):
            angle += rng.normal(0, turn)
            y += 0.5 * np.sin(angle)
            x += 0.5 * np.cos(angle)
            if 0 <= y < n and 0 <= x < n:
                img[int(y), int(x)] = max(img[int(y), int(x)], a)
    img = gaussian_filter(img, rng.uniform(0.3, 1.0))
    return np.clip(img / max(img.max(), 1e-12), 0, 1)


def flat(rng):
    """A flat field with a faint gradient or slow variation (not stretched:
    the faint part stays faint)."""
    n = OBJECT_PX
    yy, xx = grid_yx() / n
    level = rng.uniform(0.1, 1.0)
    t = rng.uniform(0, 2 * np.pi)
    img = level * (1 + rng.uniform(0, 0.3) * ((yy - 0.5) * np.sin(t) + (xx - 0.5) * np.cos(t)))
    if rng.random() < 0.4:
        img *= 1 + rng.uniform(0, 0.15) * unit(smooth(rng)) - 0.075
    return np.clip(img / max(img.max(), 1.0), 0, 1)


def high_dynamic_range(rng):
    """A dim scene (a hundredth to a tenth) with a few bright spots."""
    from scipy.ndimage import gaussian_filter
    n = OBJECT_PX
    base = [dead_leaves, smooth, shapes_on_black, lines][rng.integers(4)](rng)
    img = base * np.exp(rng.uniform(np.log(0.01), np.log(0.1)))
    spots = np.zeros((n, n))
    k = rng.integers(1, 12)
    ys, xs = rng.integers(0, n, (2, k))
    spots[ys, xs] = rng.uniform(0.5, 1.0, k)
    spots = gaussian_filter(spots, rng.uniform(0.5, 3.0))
    img = img + spots / max(spots.max(), 1e-12)
    return np.clip(img, 0, 1)


def dark_small(rng):
    """A dark field with one to three small objects."""
    n = OBJECT_PX
    yy, xx = grid_yx()
    img = np.zeros((n, n))
    for _ in range(rng.integers(1, 4)):
        cy, cx = rng.uniform(0.3, 0.7, 2) * n
        r = rng.uniform(1.5, 10)
        if rng.random() < 0.5:
            mask = (yy - cy) ** 2 + (xx - cx) ** 2 < r * r
        else:
            mask = (np.abs(yy - cy) < r) & (np.abs(xx - cx) < r * rng.uniform(0.3, 1.5))
        img[mask] = rng.uniform(0.3, 1.0)
    return img


def letters(rng):
    from PIL import Image, ImageDraw, ImageFont
    n = OBJECT_PX
    im = Image.new("L", (n, n), 0)
    draw = ImageDraw.Draw(im)
    alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijkmnopqrstuvwxyz0123456789"
    for _ in range(rng.integers(1, 12)):
        size = int(rng.uniform(10, 90))
        font = ImageFont.load_default(size=size)
        text = "".join(alphabet[i] for i in rng.integers(0, len(alphabet), rng.integers(1, 6)))
        xy = tuple(int(v) for v in rng.uniform(0, n * 0.8, 2))
        draw.text(xy, text, fill=int(rng.uniform(80, 255)), font=font)
    img = np.asarray(im, dtype=np.float64) / 255.0
    if rng.random() < 0.3:
        img = 1.0 - img * rng.uniform(0.5, 1.0)
    return img


OLD = [dead_leaves, shapes_on_black, lines, points, smooth, glows, disc_ramp, bars]
NEW = [sparse_points, dense_points, beads, fibres, flat, high_dynamic_range, dark_small, letters]


def scene(rng, images):
    u = rng.random()
    if u < 0.3:
        img = skimage_crop(rng, images)
    elif u < 0.6:
        img = OLD[rng.integers(len(OLD))](rng)
    else:
        img = NEW[rng.integers(len(NEW))](rng)
    if rng.random() < 0.3:
        img = img ** rng.uniform(0.5, 2.0)
    img = np.rot90(img, rng.integers(4))
    if rng.random() < 0.5:
        img = img[:, ::-1]
    return np.ascontiguousarray(np.clip(img, 0.0, 1.0))


def load_skimage():
    import skimage
    from skimage import io
    folder = os.path.join(os.path.dirname(skimage.__file__), "data")
    return [unit(gray(io.imread(os.path.join(folder, f)))) for f in SKIMAGE_TRAIN]


# ----------------------------------------------------------- simulation


def medium_of():
    """The physics keyword naming the medium, if `--medium` gave one."""
    return {} if MEDIUM is None else {"medium": MEDIUM}


def physics_of(rng):
    level = math.exp(rng.uniform(math.log(LEVELS[0]), math.log(LEVELS[1])))
    lattice = MEDIUM == MONTE_CARLO
    jitter = {"mu_a": (0.7, 1.4), "mu_s": (0.8, 1.25), "thickness_cm": (0.9, 1.1)}

    def factor(key):
        lo, hi = jitter[key]
        u = rng.uniform(lo, hi)
        return LATTICE[key][rng.integers(3)] if lattice else u

    p = {key: PAPER[key] * factor(key) for key in ("mu_a", "mu_s", "thickness_cm")}
    p["photons"] = PAPER_PHOTONS * level
    p["fov_cm"] = PAPER_FOV_CM * SENSOR_PX / 256
    p.update(medium_of())
    background = 0.0
    irf = rng.random() < 0.25
    if irf:
        fwhm = rng.uniform(15.0, 60.0)
        p["irf_fwhm_ps"] = LATTICE_IRF_PS[rng.integers(3)] if lattice else fwhm
        background = rng.uniform(0.0, 0.3)
    how = {"discretisation": "integrated"}
    # Draws in the order the embedded weights' run made them: the default
    # reproduces its cases exactly.
    u = rng.random()
    if not irf and not lattice and u < 0.3:
        how = {"discretisation": "point"}
    elif not irf and not lattice and u < 0.6:
        how = {"discretisation": "half-pitch", "offset": tuple(int(v) for v in rng.integers(0, 2, 2))}
    if rng.random() < 0.2:
        off = (rng.uniform(0.9, 1.1), rng.uniform(0.93, 1.07), rng.uniform(0.97, 1.03))
        fa, fs, ft = LATTICE_MISMATCH[rng.integers(4)] if lattice else off
        how["true_physics"] = {
            "preset": "paper",
            "mu_a": p["mu_a"] * fa,
            "mu_s": p["mu_s"] * fs,
            "thickness_cm": p["thickness_cm"] * ft,
            "fov_cm": p["fov_cm"],
            "photons": p["photons"],
            **medium_of(),
        }
    return p, level, background, how


def on_grid(kernel, base, offset, side, grid):
    """The model's kernel (origin-centred) and base iterate on a common
    `grid` x `grid` whose centre holds the sensor window of `side`."""
    gh, gw = kernel.shape
    if gh > grid or gw > grid:
        raise ValueError(f"model grid {gh} x {gw} exceeds the common grid {grid}")
    k = np.zeros((grid, grid), np.float32)
    ys = np.arange(gh)
    xs = np.arange(gw)
    dy = np.where(ys <= gh // 2, ys, ys - gh)
    dx = np.where(xs <= gw // 2, xs, xs - gw)
    k[np.ix_(dy % grid, dx % grid)] = kernel
    g = np.zeros((grid, grid), np.float32)
    o = (grid - side) // 2
    y0, x0 = o - offset[0], o - offset[1]
    g[y0:y0 + gh, x0:x0 + gw] = base
    return k, g


def make_case(seed):
    import scatterscope
    rng = np.random.default_rng([0x82B, seed])
    images = _images()
    while True:
        obj = scene(rng, images)
        physics, level, background, how = physics_of(rng)
        m = (OBJECT_PX - SENSOR_PX) // 2
        if obj[m:-m, m:-m].mean() < 0.002:
            continue
        try:
            c = scatterscope.learned_case(
                obj, SENSOR_PX, seed=int(seed), background_share=background, preset="paper", **how, **physics
            )
        except scatterscope.ScatterscopeError as e:
            if "no photons" in str(e) or "kernels' support" in str(e) or "carries no light" in str(e):
                continue
            raise
        break
    kernel, base = on_grid(c["kernel"], c["base_grid"], c["sensor_offset"], SENSOR_PX, GRID_PX)
    return {
        "x": c["inputs"],
        "y": c["truth"].astype(np.float32),
        "m": c["counts"].astype(np.float32),
        "k": kernel,
        "g": base,
        "f": np.array(
            [c["scale"], c["photons_per_pixel"], c["kernel_width_px"], c["background_share"], level, c["background"]],
            dtype=np.float64,
        ),
        "kind": how["discretisation"],
    }


_IMAGES = None


def _images():
    global _IMAGES
    if _IMAGES is None:
        _IMAGES = load_skimage()
    return _IMAGES


def _init_worker():
    os.environ["RAYON_NUM_THREADS"] = "1"


def simulate(work, total, threads, say):
    """Simulates cases 0..total in shards of SHARD under `work`, skipping
    the shards already there; returns the stacked arrays."""
    ctx = mp.get_context("fork")
    shards = (total + SHARD - 1) // SHARD
    for s in range(shards):
        path = os.path.join(work, f"cases-{s:04d}.npz")
        if os.path.exists(path):
            continue
        seeds = list(range(s * SHARD, min((s + 1) * SHARD, total)))
        t = time.time()
        with ctx.Pool(threads, initializer=_init_worker) as pool:
            out = pool.map(make_case, seeds, chunksize=4)
        arrays = {key: np.stack([o[key] for o in out]) for key in ("x", "y", "m", "k", "g", "f")}
        arrays["kind"] = np.array([o["kind"] for o in out])
        tmp = path + ".tmp.npz"
        np.savez(tmp, **arrays)
        os.replace(tmp, path)
        say({"shard": s, "of": shards, "seconds": round(time.time() - t, 1)})
    parts = [np.load(os.path.join(work, f"cases-{s:04d}.npz")) for s in range(shards)]
    return {key: np.concatenate([p[key] for p in parts])[:total] for key in ("x", "y", "m", "k", "g", "f", "kind")}


# ------------------------------------------------------------ tuning set


def tuning_cases(folder, levels):
    """The benchmark's tuning images (split == tuning, nothing else read)
    as the benchmark simulates them: 256-pixel sensor on a 384 grid, paper
    preset (in `--medium`'s medium when given), seed 0."""
    import scatterscope
    from PIL import Image
    rows = list(csv.DictReader(open(os.path.join(folder, "manifest.csv"))))
    cases = []
    for r in rows:
        if r["split"] != "tuning" or not r["file"]:
            continue
        img = np.asarray(Image.open(os.path.join(folder, r["file"])).convert("L"), dtype=np.float64) / 255.0
        for level in levels:
            c = scatterscope.learned_case(
                img, 256, seed=0, preset="paper", photons=PAPER_PHOTONS * level, **medium_of()
            )
            cases.append((r["name"], level, c))
    return cases


def psnr(a, b):
    return -10 * math.log10(max(float(np.mean((a - b) ** 2)), 1e-12))


def run_case(model, c):
    """The network on one case from `learned_case` (its own grid)."""
    import torch
    import unrolled_model as um
    side = c["truth"].shape[0]
    op = um.Operator(
        torch.from_numpy(c["kernel"][None].astype(np.float32)),
        tuple(c["sensor_offset"]),
        side,
        torch.tensor([c["background"]], dtype=torch.float32),
        torch.from_numpy(c["counts"][None].astype(np.float32)),
    )
    out = model(
        torch.from_numpy(c["base_grid"][None].astype(np.float32)),
        torch.from_numpy(c["inputs"][None]),
        op,
        torch.tensor([c["scale"]], dtype=torch.float32),
    )
    return np.maximum(out[0].numpy().astype(np.float64) * c["scale"], 0)


def score_tuning(model, cases):
    import torch
    rows = []
    with torch.no_grad():
        for name, level, c in cases:
            image = run_case(model, c)
            base = np.maximum(c["inputs"][2] * c["scale"], 0)
            rows.append((name, level, psnr(image, c["truth"]), psnr(base, c["truth"])))
    return rows


# --------------------------------------------------------------- training


def augment(arrays, i, rng):
    """Case `i` turned and flipped as one: the sensor-sized maps and the
    common-grid maps (the grid's centre holds the window, so it turns in
    place)."""
    k = int(rng.integers(4))
    flip = rng.random() < 0.5

    def t(a):
        a = np.rot90(a, k, axes=(-2, -1))
        return a[..., ::-1] if flip else a

    out = {key: t(arrays[key][i]) for key in ("x", "y", "m", "g")}
    # The kernel is symmetric under turns and flips about its origin.
    out["k"] = arrays["k"][i]
    return {key: np.ascontiguousarray(v) for key, v in out.items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", required=True, help="folder of the run's cases and checkpoints (resumed when present)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--cases", type=int, default=3000)
    ap.add_argument("--validation", type=int, default=64)
    ap.add_argument("--steps", type=int, default=6000)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--lr", type=float, default=5e-4)
    ap.add_argument("--channels", default="16,32,48")
    ap.add_argument("--stages", type=int, default=3)
    ap.add_argument("--em-steps", type=int, default=2)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--tuning", help="folder of scripts/bench_images.py (only its tuning split is read)")
    ap.add_argument("--eval-every", type=int, default=1000)
    ap.add_argument("--checkpoint-every", type=int, default=200)
    ap.add_argument(
        "--medium",
        choices=(MONTE_CARLO,),
        help="simulate and model every case in this medium instead of the preset's (Eq. 6)",
    )
    args = ap.parse_args()
    global MEDIUM
    MEDIUM = args.medium

    import torch
    import unrolled_model as um

    os.makedirs(args.work, exist_ok=True)
    torch.set_num_threads(args.threads)
    log = open(os.path.join(args.work, "log.jsonl"), "a")

    def say(record):
        print(json.dumps(record), flush=True)
        log.write(json.dumps(record) + "\n")
        log.flush()

    # The cases of one work folder share one medium: resuming with another
    # would mix them.
    medium_file = os.path.join(args.work, "medium.json")
    medium_name = args.medium or "the preset's (Eq. 6)"
    if os.path.exists(medium_file):
        with open(medium_file) as f:
            recorded = json.load(f)["medium"]
        if recorded != medium_name:
            raise SystemExit(
                f"{args.work} holds cases simulated in {recorded}, not {medium_name}: use another --work folder"
            )
    else:
        with open(medium_file + ".tmp", "w") as f:
            json.dump({"medium": medium_name}, f)
        os.replace(medium_file + ".tmp", medium_file)
    say({"start": time.strftime("%Y-%m-%d %H:%M:%S"), "args": vars(args)})
    t0 = time.time()
    data = simulate(args.work, args.cases + args.validation, args.threads, say)
    sim_seconds = time.time() - t0
    n = args.cases
    train = {k: v[:n] for k, v in data.items()}
    val = {k: v[n:] for k, v in data.items()}
    tuning = tuning_cases(args.tuning, (0.1, 1.0, 10.0)) if args.tuning else []

    channels = tuple(int(c) for c in args.channels.split(","))
    torch.manual_seed(args.seed)
    model = um.UnrolledNet(channels, args.stages, args.em_steps)
    opt = torch.optim.Adam(model.parameters(), lr=args.lr)
    sched = torch.optim.lr_scheduler.OneCycleLR(
        opt, max_lr=args.lr, total_steps=args.steps, pct_start=0.05, final_div_factor=100
    )
    rng = np.random.default_rng(args.seed)
    state = {"step": 0, "curve": [], "train_seconds": 0.0, "sim_seconds": sim_seconds}
    ckpt = os.path.join(args.work, "checkpoint.pt")
    if os.path.exists(ckpt):
        saved = torch.load(ckpt, weights_only=False)
        model.load_state_dict(saved["model"])
        opt.load_state_dict(saved["opt"])
        sched.load_state_dict(saved["sched"])
        rng.bit_generator.state = saved["rng"]
        torch.set_rng_state(saved["torch_rng"])
        state = saved["state"]
        state["sim_seconds"] = state.get("sim_seconds", 0.0) + sim_seconds
        say({"resumed_at": state["step"]})

    def save():
        tmp = ckpt + ".tmp"
        torch.save(
            {
                "model": model.state_dict(),
                "opt": opt.state_dict(),
                "sched": sched.state_dict(),
                "rng": rng.bit_generator.state,
                "torch_rng": torch.get_rng_state(),
                "state": state,
            },
            tmp,
        )
        os.replace(tmp, ckpt)

    def batch_of(arrays, idx, augment_it):
        cases = [augment(arrays, i, rng) if augment_it else {k: arrays[k][i] for k in ("x", "y", "m", "k", "g")} for i in idx]
        b = {k: torch.from_numpy(np.stack([c[k] for c in cases]).astype(np.float32)) for k in ("x", "y", "m", "k", "g")}
        f = arrays["f"][idx]
        off = (GRID_PX - SENSOR_PX) // 2
        op = um.Operator(b["k"], (off, off), SENSOR_PX, torch.from_numpy(f[:, 5]).float(), b["m"])
        return b, op, torch.from_numpy(f[:, 0]).float()

    def loss_of(b, op, scale):
        out = model(b["g"], b["x"], op, scale)
        target = b["y"] / scale[:, None, None]
        mse = ((out - target) ** 2).mean(dim=(1, 2))
        return torch.log(mse + 1e-7 / scale**2).mean()

    def validate():
        model.eval()
        gains = []
        with torch.no_grad():
            for i in range(0, len(val["x"]), 8):
                idx = np.arange(i, min(i + 8, len(val["x"])))
                b, op, scale = batch_of(val, idx, False)
                out = model(b["g"], b["x"], op, scale).numpy()
                for j, c in enumerate(idx):
                    s = val["f"][c, 0]
                    t = val["y"][c]
                    gains.append(psnr(np.maximum(out[j] * s, 0), t) - psnr(np.maximum(val["x"][c, 2] * s, 0), t))
        model.train()
        return float(np.mean(gains))

    def tuning_point(step):
        if not tuning:
            return
        model.eval()
        rows = score_tuning(model, tuning)
        model.train()
        point = {"step": step, "minutes": round((time.time() - t0) / 60, 2)}
        for level in (0.1, 1.0, 10.0):
            sel = [r for r in rows if r[1] == level]
            point[f"{level}x"] = round(float(np.mean([r[2] for r in sel])), 3)
            point[f"{level}x_over_rl150"] = round(float(np.mean([r[2] - r[3] for r in sel])), 3)
        state["curve"].append(point)
        say({"tuning": point})

    if state["step"] == 0:
        tuning_point(0)
    running = []
    lap = time.time()
    while state["step"] < args.steps:
        idx = rng.integers(0, n, args.batch)
        b, op, scale = batch_of(train, idx, True)
        loss = loss_of(b, op, scale)
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 10.0)
        opt.step()
        sched.step()
        state["step"] += 1
        step = state["step"]
        running.append(float(loss.detach()))
        if step % 50 == 0:
            now = time.time()
            state["train_seconds"] += now - lap
            lap = now
            say({"step": step, "loss": round(float(np.mean(running)), 4), "train_minutes": round(state["train_seconds"] / 60, 2)})
            running = []
        if step % args.eval_every == 0 or step == args.steps:
            say({"step": step, "validation_gain_over_rl150_db": round(validate(), 3)})
            tuning_point(step)
            lap = time.time()
        if step % args.checkpoint_every == 0 or step == args.steps:
            save()

    f = train["f"]
    ranges = {
        "photons_per_pixel": [float(f[:, 1].min()), float(f[:, 1].max())],
        "kernel_width_px": [float(f[:, 2].min()), float(f[:, 2].max())],
        "background_share_max": float(f[:, 3].max()),
    }
    kinds = {str(k): int(v) for k, v in zip(*np.unique(train["kind"], return_counts=True))}
    total_minutes = (state["sim_seconds"] + state["train_seconds"]) / 60
    extra = {
        "trained": (
            f"trained here: {args.steps} steps of {args.batch} cases ({args.steps * args.batch} seen), "
            f"{args.cases} simulated stacks, {total_minutes:.0f} min on {args.threads} CPU threads"
            + (f", light by {args.medium} transport" if args.medium else "")
        ),
        "data": json.dumps({
            "cases": args.cases,
            "object_px": OBJECT_PX,
            "sensor_px": SENSOR_PX,
            "pitch_cm": PAPER_FOV_CM / 256,
            "levels": list(LEVELS),
            "paper": PAPER,
            "medium": medium_name,
            "jitter": (
                {"lattice": LATTICE} if args.medium == MONTE_CARLO
                else {"mu_a": [0.7, 1.4], "mu_s": [0.8, 1.25], "thickness_cm": [0.9, 1.1]}
            ),
            "instrument": (
                "a quarter of the cases with an IRF of "
                + ("20, 40 or 60" if args.medium == MONTE_CARLO else "15-60")
                + " ps FWHM and a background of 0-0.3 of the mean count"
            ),
            "mismatch": (
                f"a fifth of the cases through a medium off the stated one by one of {LATTICE_MISMATCH} (mu_a, mu_s, thickness)"
                if args.medium == MONTE_CARLO
                else "a fifth of the cases through a medium off the stated one (mu_a x0.9-1.1, mu_s x0.93-1.07, thickness x0.97-1.03)"
            ),
            "discretisations": kinds,
            "skimage": SKIMAGE_TRAIN,
            "generators": [g.__name__ for g in OLD + NEW],
        }),
        "run": json.dumps({
            "steps": args.steps,
            "batch": args.batch,
            "lr": args.lr,
            "seed": args.seed,
            "threads": args.threads,
            "stages": args.stages,
            "em_steps": args.em_steps,
            "simulate_minutes": round(state["sim_seconds"] / 60, 1),
            "train_minutes": round(state["train_seconds"] / 60, 1),
            "total_minutes": round(total_minutes, 1),
            "machine": f"{platform.machine()} {platform.processor() or ''} {os.cpu_count()} CPUs".strip(),
            "torch": torch.__version__,
            "parameters": model.parameters_count(),
        }),
        "tuning_curve": json.dumps(state["curve"]),
    }
    tmp = args.out + ".tmp"
    um.export(model, tmp, ranges, extra)
    os.replace(tmp, args.out)
    say({"wrote": args.out, "ranges": ranges, "total_minutes": round(total_minutes, 1)})


if __name__ == "__main__":
    main()
