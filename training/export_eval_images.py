"""Writes the five natural evaluation images (scikit-image's bundled camera,
astronaut, coffee, chelsea, rocket) as 256x256 8-bit gray PNGs: centre crop
to a square, then an anti-aliased resize. None of them is used in training.

    python export_eval_images.py DIR
"""

import os
import sys

import numpy as np
from PIL import Image
from skimage import color, data, transform

EVALUATION_IMAGES = ["camera", "astronaut", "coffee", "chelsea", "rocket"]


def main(out):
    os.makedirs(out, exist_ok=True)
    for name in EVALUATION_IMAGES:
        img = getattr(data, name)()
        if img.ndim == 3:
            img = color.rgb2gray(img[..., :3])
        img = img.astype(np.float64)
        if img.max() > 1.0:
            img /= 255.0
        h, w = img.shape
        s = min(h, w)
        y, x = (h - s) // 2, (w - s) // 2
        img = transform.resize(img[y:y + s, x:x + s], (256, 256), anti_aliasing=True)
        Image.fromarray(np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)).save(
            os.path.join(out, f"{name}.png"))
    print("wrote", out)


if __name__ == "__main__":
    main(sys.argv[1])
