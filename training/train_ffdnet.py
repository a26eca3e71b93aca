"""Train scatterscope's embedded FFDNet-gray weights on CPU (or GPU if present).

Data: procedurally generated dead-leaves images plus scikit-image's bundled
images, EXCLUDING the evaluation images (camera, astronaut, coffee, chelsea,
rocket). Noise levels are drawn uniformly in [0, 75]/255 and each sample's MSE
is divided by (sigma + 2/255)^2, so every noise level weighs about the same in
dB; an unweighted MSE lets sigma = 75 dominate and starves low noise levels.

Writes a safetensors file in scatterscope's format (metadata names the
architecture, the sigma range and the training run).

    python train_ffdnet.py --minutes 35 --layers 12 --channels 32 --out ffdnet_small.safetensors
"""

import argparse
import math
import time

import numpy as np
import torch
from safetensors.torch import save_file
from scipy.ndimage import gaussian_filter
from skimage import color, data, transform

from ffdnet_model import SIGMA_MAX, FFDNet

EVALUATION_IMAGES = {"camera", "astronaut", "coffee", "chelsea", "rocket"}
TRAINING_IMAGES = [
    "brick", "clock", "coins", "grass", "gravel", "hubble_deep_field",
    "immunohistochemistry", "moon", "page", "text", "retina",
    "stereo_motorcycle", "cell", "microaneurysms",
]


def gray01(img):
    if isinstance(img, tuple):
        img = img[0]
    img = np.asarray(img)
    if img.ndim == 3:
        img = color.rgb2gray(img[..., :3])
    img = img.astype(np.float64)
    if img.max() > 1.0:
        img = img / 255.0
    return img.astype(np.float32)


def natural_images():
    assert not EVALUATION_IMAGES & set(TRAINING_IMAGES)
    out = []
    for name in TRAINING_IMAGES:
        img = gray01(getattr(data, name)())
        out.append(img)
        # A half-size copy adds coarser textures at the same patch size.
        if min(img.shape) >= 256:
            out.append(transform.rescale(img, 0.5, anti_aliasing=True).astype(np.float32))
    return out


def dead_leaves(rng, size, rmin=1.0, rmax=None, alpha=3.0, shaded=False):
    """Occluding discs with power-law radii (density r^-alpha) and random grey levels.

    With `shaded`, each disc's grey level varies linearly across it and the whole
    image is multiplied by a smooth illumination field: flat discs alone teach the
    network that the world is piecewise constant.
    """
    rmax = rmax or size / 2
    img = np.full((size, size), np.nan, dtype=np.float32)
    a1 = 1 - alpha
    while True:
        empty = np.isnan(img)
        if empty.mean() < 0.002:
            break
        # Inverse CDF of r^-alpha on [rmin, rmax].
        r = ((rmax**a1 - rmin**a1) * rng.random() + rmin**a1) ** (1 / a1)
        cx, cy = rng.uniform(-r, size + r, 2)
        x0, x1 = max(int(cx - r), 0), min(int(cx + r) + 1, size)
        y0, y1 = max(int(cy - r), 0), min(int(cy + r) + 1, size)
        if x0 >= x1 or y0 >= y1:
            continue
        yy, xx = np.mgrid[y0:y1, x0:x1]
        mask = ((xx - cx) ** 2 + (yy - cy) ** 2 <= r * r) & empty[y0:y1, x0:x1]
        if shaded:
            gx, gy = rng.uniform(-0.5, 0.5, 2)
            value = rng.random() + (gx * (xx - cx) + gy * (yy - cy)) / max(r, 1.0)
            img[y0:y1, x0:x1][mask] = value[mask]
        else:
            img[y0:y1, x0:x1][mask] = rng.random()
    img[np.isnan(img)] = rng.random()
    if shaded:
        light = gaussian_filter(rng.standard_normal((size, size)), rng.uniform(16, 64), mode="wrap")
        light = (light - light.min()) / max(light.max() - light.min(), 1e-12)
        img = np.clip(img, 0.0, 1.0) * (0.3 + 0.7 * light).astype(np.float32)
    # Mild blur on some leaves images so edges are not always pixel-sharp.
    if rng.random() < 0.5:
        img = gaussian_filter(img, rng.uniform(0.3, 1.2))
    return img


def random_patch(rng, images, patch):
    img = images[rng.integers(len(images))]
    h, w = img.shape
    y = rng.integers(0, h - patch + 1)
    x = rng.integers(0, w - patch + 1)
    p = img[y:y + patch, x:x + patch]
    p = np.rot90(p, rng.integers(4))
    if rng.random() < 0.5:
        p = p[:, ::-1]
    return np.ascontiguousarray(p)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=35.0)
    ap.add_argument("--layers", type=int, default=12)
    ap.add_argument("--channels", type=int, default=32)
    ap.add_argument("--patch", type=int, default=64)
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--lr", type=float, default=2e-3)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--init", help="continue from a safetensors file this script wrote")
    ap.add_argument("--shaded-leaves", type=float, default=0.0,
                    help="fraction of dead-leaves images with shaded discs and smooth illumination")
    ap.add_argument("--shift-consistency", type=float, default=0.0,
                    help="weight of the penalty on f(shift x) - shift f(x) for a one-pixel shift "
                         "(FFDNet's 2x2 unshuffle grid is not shift-equivariant)")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()

    if args.threads:
        torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    device = "cuda" if torch.cuda.is_available() else "cpu"

    naturals = natural_images()
    # No draw when shading is off, so the default run reproduces the embedded weights' data.
    leaves = [dead_leaves(rng, 256, shaded=args.shaded_leaves > 0 and rng.random() < args.shaded_leaves)
              for _ in range(48)]
    print(f"{len(naturals)} natural images, {len(leaves)} dead-leaves images", flush=True)

    model = FFDNet(args.layers, args.channels)
    if args.init:
        model.load_safetensors(args.init)
        print(f"continuing from {args.init}", flush=True)
    model = model.to(device)
    opt = torch.optim.Adam(model.parameters(), lr=args.lr)
    budget = args.minutes * 60.0
    start = time.time()
    step = 0
    running = None
    while True:
        elapsed = time.time() - start
        if elapsed > budget:
            break
        # Cosine decay over the wall-clock budget.
        lr = args.lr * 0.5 * (1 + math.cos(math.pi * min(elapsed / budget, 1.0)))
        for g in opt.param_groups:
            g["lr"] = lr
        clean = np.stack([
            random_patch(rng, naturals if rng.random() < 0.5 else leaves, args.patch)
            for _ in range(args.batch)
        ])[:, None]
        sigma = rng.uniform(0, SIGMA_MAX, args.batch).astype(np.float32)
        noisy = clean + rng.standard_normal(clean.shape).astype(np.float32) * sigma[:, None, None, None]
        clean_t = torch.from_numpy(clean).to(device)
        noisy_t = torch.from_numpy(noisy).to(device)
        sigma_t = torch.from_numpy(sigma).to(device)
        out = model(noisy_t, sigma_t)
        mse = ((out - clean_t) ** 2).mean(dim=(1, 2, 3))
        weight = 1.0 / (sigma_t + 2.0 / 255.0) ** 2
        loss = (mse * weight).mean()
        if args.shift_consistency > 0:
            # One-pixel shift (down, right or both), cropped so no wrapped pixel counts.
            dy, dx = [(1, 0), (0, 1), (1, 1)][rng.integers(3)]
            shifted = model(torch.roll(noisy_t, (dy, dx), dims=(2, 3)), sigma_t)
            diff = shifted[:, :, 2:-2, 2:-2] - torch.roll(out, (dy, dx), dims=(2, 3))[:, :, 2:-2, 2:-2]
            loss = loss + args.shift_consistency * ((diff ** 2).mean(dim=(1, 2, 3)) * weight).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        step += 1
        running = loss.item() if running is None else 0.98 * running + 0.02 * loss.item()
        if step % 100 == 0:
            print(f"step {step} t={elapsed:.0f}s lr={lr:.2e} weighted loss {running:.4f}", flush=True)
            save(model, args, step, time.time() - start)
    save(model, args, step, time.time() - start)
    print(f"done: {step} steps in {time.time() - start:.0f} s", flush=True)


def save(model, args, step, seconds):
    model.eval()
    # Re-estimate BatchNorm statistics is unnecessary: running stats were tracked in training.
    meta = model.safetensors_metadata(
        "scatterscope training/train_ffdnet.py",
        {"steps": step, "seconds": round(seconds), "init": args.init or "", "patch": args.patch, "batch": args.batch,
         "lr": args.lr, "seed": args.seed, "threads": torch.get_num_threads(),
         "loss": "mse/(sigma+2/255)^2", "shift_consistency": args.shift_consistency,
         "data": f"dead leaves ({args.shaded_leaves:g} shaded) + skimage " + ",".join(TRAINING_IMAGES)},
    )
    tensors = {k: v.cpu() for k, v in model.safetensors_dict().items()}
    save_file(tensors, args.out, metadata=meta)
    model.train()


if __name__ == "__main__":
    main()
