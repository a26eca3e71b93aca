"""Writes the images of `scatterscope bench-recon` as 8-bit grey PNGs with a
manifest.csv (name, source, category, split, licence).

    pip install scikit-image PyWavelets matplotlib scikit-learn pydicom
    python3 scripts/bench_images.py DIR [SIZE]

Every image comes from a file that a PyPI package ships (nothing is
downloaded at run time) or from a seeded generator here; none is committed
to this repository. Each is centre-cropped to a square, resized with
anti-aliasing to SIZE x SIZE (default 384: a 256-pixel sensor plus 64
pixels of object beyond each edge) and scaled to [0, 1] by its own range.

The split was written down before any reconstruction was run on these
images and must not change after looking at results:
- tuning (10 images, one third): the project's four built-in scenes and
  six scikit-image images that the embedded FFDNet was trained on (an image
  the prior has seen cannot be held out);
- held-out (20 images): everything else, from five sources.

Second round (2026-11-24), added before any reconstruction ran on them:
the first tuning set is biased (six of its ten images are in the prior's
training set, so a strong prior looks better on them than on unseen
scenes). Six tuning images the prior has never seen and twelve new
held-out images were added, keeping tuning at one third (16 of 48):
- tuning: two pydicom scans (MR, CT), seeded binary blobs, a seeded sparse
  point field, a seeded fractal terrain and scikit-image's checkerboard;
- held-out: four more pydicom scans (ultrasound, CT, nuclear medicine,
  a secondary capture), a liver segmentation mask, scikit-image's colour
  wheel, matplotlib's logo, and five more seeded scenes (points, lines,
  terrain, blobs, points).

Third round (2026-11-24, eleventh session), added before any
reconstruction ran on them: the two largest held-out losses are very
smooth scenes (the nuclear-medicine image and the colour wheel), and no
tuning image was of that kind. Three smooth tuning images and six smooth
held-out ones were added, keeping tuning at one third (19 of 57):
- tuning: a seeded smooth random field, seeded wide glows on black and a
  seeded smooth ramp in a disk;
- held-out: two more of each generator with other seeds, and matplotlib's
  15 x 15 bivariate-normal sample upsampled (a low-resolution smooth
  image, as nuclear-medicine images are).
"""

import csv
import gzip
import os
import sys

import numpy as np
from PIL import Image

TUNING = "tuning"
HELD_OUT = "held-out"


def skimage_image(name):
    from skimage import data
    img = getattr(data, name)()
    return img[0] if isinstance(img, tuple) else img


def pywt_image(name):
    import pywt.data
    return getattr(pywt.data, name)()


def mpl_sample(name):
    from matplotlib import cbook
    if name == "s1045":
        # 256 x 256 big-endian uint16 MRI slice (matplotlib's mri demo).
        with cbook.get_sample_data("s1045.ima.gz") as f:
            raw = f.read()
        if raw[:2] == b"\x1f\x8b":
            raw = gzip.decompress(raw)
        return np.frombuffer(raw, np.uint16).reshape(256, 256).astype(np.float64)
    if name == "jacksboro_fault_dem":
        return cbook.get_sample_data("jacksboro_fault_dem.npz")["elevation"]
    if name == "topobathy":
        return cbook.get_sample_data("topobathy.npz")["topo"]
    with cbook.get_sample_data(name) as f:
        return np.asarray(Image.open(f))


def sklearn_image(name):
    from sklearn.datasets import load_sample_image
    return load_sample_image(name)


def pydicom_image(name):
    import pydicom
    from pydicom.data import get_testdata_file
    return pydicom.dcmread(get_testdata_file(name)).pixel_array


def star_field(seed, size=384):
    """Sparse bright points of random brightness on black (a fluorescence
    or astronomy-like scene), seeded."""
    rng = np.random.default_rng(seed)
    img = np.zeros((size, size))
    for _ in range(60):
        y, x = rng.integers(4, size - 4, 2)
        r = rng.uniform(0.8, 3.0)
        yy, xx = np.mgrid[:size, :size]
        img += rng.uniform(0.2, 1.0) * np.exp(-((yy - y) ** 2 + (xx - x) ** 2) / (2 * r * r))
    return img


def terrain(seed, size=384):
    """A fractal surface: Gaussian noise with a 1/f^3 power spectrum
    (smooth hills with detail at every scale, like a height map), seeded."""
    rng = np.random.default_rng(seed)
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(size), np.fft.fftfreq(size)))
    f[0, 0] = 1.0
    spectrum = (rng.normal(size=(size, size)) + 1j * rng.normal(size=(size, size))) * f ** -1.5
    spectrum[0, 0] = 0.0
    return np.fft.ifft2(spectrum).real


def blobs(seed, size=384):
    """Binary blobs (scikit-image's generator), seeded."""
    from skimage.data import binary_blobs
    return binary_blobs(length=size, blob_size_fraction=0.08, volume_fraction=0.3, rng=seed).astype(float)


def line_art(seed, size=384):
    """Thin random lines and rectangles outlines on black, seeded."""
    from skimage.draw import line_aa, rectangle_perimeter
    rng = np.random.default_rng(seed)
    img = np.zeros((size, size))
    for _ in range(25):
        r0, c0, r1, c1 = rng.integers(0, size, 4)
        rr, cc, val = line_aa(r0, c0, r1, c1)
        img[rr, cc] = np.maximum(img[rr, cc], val)
    for _ in range(8):
        r0, c0 = rng.integers(10, size - 80, 2)
        h, w = rng.integers(20, 70, 2)
        rr, cc = rectangle_perimeter((r0, c0), extent=(h, w), shape=img.shape)
        img[rr, cc] = 1.0
    return img


def smooth_field(seed, size=384):
    """A very smooth random surface: Gaussian noise with a Gaussian power
    spectrum (correlation length about 25 pixels at 384), seeded."""
    rng = np.random.default_rng(seed)
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(size), np.fft.fftfreq(size)))
    spectrum = (rng.normal(size=(size, size)) + 1j * rng.normal(size=(size, size))) * np.exp(-((f * 110) ** 2))
    return np.fft.ifft2(spectrum).real


def glows(seed, size=384):
    """A few wide Gaussian glows of random size and brightness on black
    (an uptake image: nuclear medicine, fluorescence at depth), seeded."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:size, :size]
    img = np.zeros((size, size))
    for _ in range(rng.integers(3, 7)):
        y, x = rng.uniform(0.2, 0.8, 2) * size
        r = rng.uniform(0.04, 0.15) * size
        img += rng.uniform(0.3, 1.0) * np.exp(-((yy - y) ** 2 + (xx - x) ** 2) / (2 * r * r))
    return img


def ramp(seed, size=384):
    """A smooth angular and radial ramp inside a soft-edged disk on black,
    at a random angle and centre, seeded."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:size, :size] / size
    cy, cx = rng.uniform(0.4, 0.6, 2)
    r = np.hypot(yy - cy, xx - cx)
    angle = np.arctan2(yy - cy, xx - cx) + rng.uniform(0, 2 * np.pi)
    inside = 1 / (1 + np.exp((r - rng.uniform(0.3, 0.4)) * size / 4))
    return inside * (0.6 + 0.4 * np.cos(angle)) * (1 - r)


def mpl_array(name):
    import matplotlib.cbook as cbook
    return np.load(cbook.get_sample_data(name, asfileobj=False))


SK = ("scikit-image", "scikit-image data licence (public domain or CC0 for these files)")
PYWT = ("PyWavelets", "PyWavelets data (MIT licence; ascent from SciPy, BSD)")
MPL = ("matplotlib", "matplotlib sample data (matplotlib licence / public domain)")
SKL = ("scikit-learn", "scikit-learn sample images (CC BY 2.0 / public domain)")
DCM = ("pydicom", "pydicom test files (MIT licence)")
GEN = ("generated", "generated by this script (no licence needed)")
SCENE = ("scatterscope", "the project's built-in scene (written by bench-recon)")

# (name, loader, source, category, split)
IMAGES = [
    # Tuning: built-in scenes (rendered by bench-recon itself) ...
    ("usaf", None, SCENE, "line art", TUNING),
    ("star", None, SCENE, "line art", TUNING),
    ("text", None, SCENE, "text", TUNING),
    ("disks", None, SCENE, "sparse/dark background", TUNING),
    # ... and images the embedded prior was trained on.
    ("coins", lambda: skimage_image("coins"), SK, "natural photo", TUNING),
    ("moon", lambda: skimage_image("moon"), SK, "natural photo", TUNING),
    ("cell", lambda: skimage_image("cell"), SK, "microscopy", TUNING),
    ("hubble_deep_field", lambda: skimage_image("hubble_deep_field"), SK, "sparse/dark background", TUNING),
    ("page", lambda: skimage_image("page"), SK, "text", TUNING),
    ("brick", lambda: skimage_image("brick"), SK, "texture", TUNING),
    # Held out.
    ("camera", lambda: skimage_image("camera"), SK, "natural photo", HELD_OUT),
    ("astronaut", lambda: skimage_image("astronaut"), SK, "natural photo", HELD_OUT),
    ("coffee", lambda: skimage_image("coffee"), SK, "natural photo", HELD_OUT),
    ("chelsea", lambda: skimage_image("chelsea"), SK, "natural photo", HELD_OUT),
    ("rocket", lambda: skimage_image("rocket"), SK, "natural photo", HELD_OUT),
    ("horse", lambda: skimage_image("horse"), SK, "line art", HELD_OUT),
    ("phantom", lambda: skimage_image("shepp_logan_phantom"), SK, "medical/dark background", HELD_OUT),
    ("logo", lambda: skimage_image("logo"), SK, "line art", HELD_OUT),
    ("aero", lambda: pywt_image("aero"), PYWT, "aerial photo", HELD_OUT),
    ("ascent", lambda: pywt_image("ascent"), PYWT, "natural photo", HELD_OUT),
    ("grace_hopper", lambda: mpl_sample("grace_hopper.jpg"), MPL, "portrait photo", HELD_OUT),
    ("mri_s1045", lambda: mpl_sample("s1045"), MPL, "medical/dark background", HELD_OUT),
    ("jacksboro_dem", lambda: mpl_sample("jacksboro_fault_dem"), MPL, "terrain", HELD_OUT),
    ("topobathy", lambda: mpl_sample("topobathy"), MPL, "terrain", HELD_OUT),
    ("present", lambda: mpl_sample("Minduka_Present_Blue_Pack.png"), MPL, "natural photo", HELD_OUT),
    ("china", lambda: sklearn_image("china.jpg"), SKL, "natural photo", HELD_OUT),
    ("flower", lambda: sklearn_image("flower.jpg"), SKL, "natural photo", HELD_OUT),
    ("ct_small", lambda: pydicom_image("CT_small.dcm"), DCM, "medical/dark background", HELD_OUT),
    ("star_field", lambda: star_field(11), GEN, "sparse/dark background", HELD_OUT),
    ("line_art", lambda: line_art(12), GEN, "line art/sparse", HELD_OUT),
    # Second round: tuning images the prior has never seen ...
    ("mr_overlay", lambda: pydicom_image("examples_overlay.dcm"), DCM, "medical/dark background", TUNING),
    ("ct_693", lambda: pydicom_image("693_J2KI.dcm"), DCM, "medical/dark background", TUNING),
    ("blobs_21", lambda: blobs(21), GEN, "sparse/dark background", TUNING),
    ("points_31", lambda: star_field(31), GEN, "sparse/dark background", TUNING),
    ("terrain_41", lambda: terrain(41), GEN, "terrain", TUNING),
    ("checkerboard", lambda: skimage_image("checkerboard"), SK, "line art", TUNING),
    # ... and more held-out images.
    ("us_palette", lambda: pydicom_image("examples_palette.dcm"), DCM, "medical/ultrasound", HELD_OUT),
    ("ct_pixelrep", lambda: pydicom_image("J2K_pixelrep_mismatch.dcm"), DCM, "medical/dark background", HELD_OUT),
    ("nm_jpeg2000", lambda: pydicom_image("JPEG2000.dcm"), DCM, "medical/dark background", HELD_OUT),
    ("sc_dfl", lambda: pydicom_image("image_dfl.dcm"), DCM, "medical", HELD_OUT),
    ("liver_mask", lambda: pydicom_image("liver_1frame.dcm"), DCM, "sparse/dark background", HELD_OUT),
    ("colorwheel", lambda: skimage_image("colorwheel"), SK, "smooth synthetic", HELD_OUT),
    ("mpl_logo", lambda: mpl_sample("logo2.png"), MPL, "line art", HELD_OUT),
    ("points_51", lambda: star_field(51), GEN, "sparse/dark background", HELD_OUT),
    ("lines_52", lambda: line_art(52), GEN, "line art/sparse", HELD_OUT),
    ("terrain_53", lambda: terrain(53), GEN, "terrain", HELD_OUT),
    ("blobs_54", lambda: blobs(54), GEN, "sparse/dark background", HELD_OUT),
    ("points_55", lambda: star_field(55), GEN, "sparse/dark background", HELD_OUT),
    # Third round: smooth scenes, tuning ...
    ("smooth_61", lambda: smooth_field(61), GEN, "smooth", TUNING),
    ("glows_62", lambda: glows(62), GEN, "smooth/dark background", TUNING),
    ("ramp_63", lambda: ramp(63), GEN, "smooth/dark background", TUNING),
    # ... and held out.
    ("smooth_71", lambda: smooth_field(71), GEN, "smooth", HELD_OUT),
    ("glows_72", lambda: glows(72), GEN, "smooth/dark background", HELD_OUT),
    ("ramp_73", lambda: ramp(73), GEN, "smooth/dark background", HELD_OUT),
    ("smooth_74", lambda: smooth_field(74), GEN, "smooth", HELD_OUT),
    ("glows_75", lambda: glows(75), GEN, "smooth/dark background", HELD_OUT),
    ("bivariate_normal", lambda: mpl_array("axes_grid/bivariate_normal.npy"), MPL, "smooth (low resolution)", HELD_OUT),
]


def to_gray01(img, size):
    from skimage import color, transform
    img = np.asarray(img, dtype=np.float64)
    if img.ndim == 3:
        if img.shape[2] == 4:
            # Transparent pixels become white, as the picture is shown.
            alpha = img[..., 3:4] / (255.0 if img.max() > 1 else 1.0)
            img = img[..., :3] * alpha + (255.0 if img.max() > 1 else 1.0) * (1 - alpha)
        img = color.rgb2gray(img[..., :3] / (255.0 if img.max() > 1 else 1.0))
    h, w = img.shape
    s = min(h, w)
    y, x = (h - s) // 2, (w - s) // 2
    img = transform.resize(img[y:y + s, x:x + s], (size, size), anti_aliasing=True)
    lo, hi = np.nanmin(img), np.nanmax(img)
    return (img - lo) / (hi - lo) if hi > lo else np.zeros_like(img)


def main(out, size=384):
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "manifest.csv"), "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["name", "file", "source", "category", "split", "licence"])
        for name, load, (source, licence), category, split in IMAGES:
            file = ""
            if load is not None:
                img = to_gray01(load(), size)
                file = f"{name}.png"
                Image.fromarray(np.round(img * 255).astype(np.uint8)).save(os.path.join(out, file))
            writer.writerow([name, file, source, category, split, licence])
    tuning = sum(1 for i in IMAGES if i[4] == TUNING)
    print(f"wrote {len(IMAGES)} images ({tuning} tuning, {len(IMAGES) - tuning} held out) to {out}")


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 384)
