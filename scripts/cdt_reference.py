#!/usr/bin/env python3
"""Independent numpy implementation of the published confocal diffuse
tomography reconstruction (Lindell and Wetzstein, Nature Communications 11,
4517 (2020)): crop the scan to 417 bins of 16 ps, resample each histogram to
128 samples, Wiener-deconvolve the slab's in-and-out diffusion kernel, then
f-k (Stolt) migration of the confocal free-space propagation.

Written from the paper's description and the steps listed in
../shared/data/cdt-scenes/README.md, to check `scatterscope hidden --method
published` against a second implementation that shares no code with it
(tests/confocal_published.rs). It needs numpy and h5py
(`bash scripts/fetch_python_deps.sh` installs them under target/pydeps).

    python3 scripts/cdt_reference.py SCAN.mat SCAN_SIDE_M SNR OUT.npy

writes the volume, float64, shape (depth 128, row 32, column 32), rows and
columns as the Rust side orders them (HDF5 axis 1, HDF5 axis 0), and prints
the wall time of the reconstruction (file reading excluded) in seconds.
"""

import sys
import time

import h5py
import numpy as np

LIGHT_SPEED = 3e8  # m/s, as the published code rounds it
INDEX = 1.12  # foam refractive index
MU_A = 0.53  # 1/m
MU_S_PRIME = 262.0  # 1/m
EXTRAPOLATION = 0.0036  # m
THICKNESS = 0.0254  # m
IMAGE_PAIRS = 20  # image sources on each side
CROP_BINS = 417  # 16 ps bins kept: 1 m of depth
DEPTH_SAMPLES = 128
PATH_RANGE = 2.0  # m of round-trip path the kernel's time axis spans / 2
TRIMMED_TAIL = 15  # last depth slices zeroed (amplified noise)


def resample(scan):
    """(t, r, c) counts: first CROP_BINS bins, linearly resampled to
    DEPTH_SAMPLES samples spanning the same interval."""
    kept = scan[:CROP_BINS]
    position = np.linspace(0.0, CROP_BINS - 1.0, DEPTH_SAMPLES)
    low = np.minimum(np.floor(position).astype(int), CROP_BINS - 2)
    frac = (position - low)[:, None, None]
    return kept[low] * (1.0 - frac) + kept[low + 1] * frac


def slab_kernel(nt, nr, nc, side):
    """In-and-out diffusion kernel on the padded grid, origin at index 0,
    as its 3-D FFT."""
    v = LIGHT_SPEED / INDEX
    t = np.linspace(0.0, 2.0 * PATH_RANGE, nt) / v
    t[0] = 1.0  # the t = 0 sample set to a time where the kernel is ~0
    lateral_r = np.linspace(-side, side, nr)
    lateral_c = np.linspace(-side, side, nc)
    rho2 = lateral_r[None, :, None] ** 2 + lateral_c[None, None, :] ** 2
    diffusion = 1.0 / (3.0 * (MU_A + MU_S_PRIME))
    source = 1.0 / MU_S_PRIME
    images = 0.0
    for m in range(-IMAGE_PAIRS, IMAGE_PAIRS + 1):
        z_pos = THICKNESS * (1 - 2 * m) - 4 * m * EXTRAPOLATION - source
        z_neg = THICKNESS * (1 - 2 * m) - (4 * m - 2) * EXTRAPOLATION + source
        images = images + z_pos * np.exp(-z_pos**2 / (4 * diffusion * v * t)) - z_neg * np.exp(
            -z_neg**2 / (4 * diffusion * v * t)
        )
    t3 = t[:, None, None]
    kernel = (
        (4 * np.pi * diffusion * v) ** -1.5
        * t3**-2.5
        * np.exp(-MU_A * v * t3 - rho2 / (4 * diffusion * v * t3))
        * images[:, None, None]
    )
    kernel = kernel / kernel.sum()
    kernel = np.roll(kernel, (-(nr // 2), -(nc // 2)), axis=(1, 2))
    twice = np.abs(np.fft.ifftn(np.fft.fftn(kernel) ** 2))
    return np.fft.fftn(twice)


def stolt(volume, side):
    """f-k migration of a padded (2M, 2N, 2N) confocal measurement; returns
    the |.|^2 volume on the same grid."""
    nt, nr, nc = volume.shape
    half_t, half_r = nt // 2, nr // 2
    spectrum = np.fft.fftshift(np.fft.fftn(np.sqrt(np.maximum(volume, 0.0))))
    kz = (np.arange(nt) - half_t)[:, None, None] / half_t
    kr = (np.arange(nr) - half_r)[None, :, None] / half_r
    kc = (np.arange(nc) - half_r)[None, None, :] / half_r
    scale = (half_r * 2.0 * PATH_RANGE) / (half_t * side * 4.0)
    source_kz = np.sqrt(scale**2 * (kr**2 + kc**2) + kz**2)
    index = (source_kz + 1.0) * half_t  # fractional row of the spectrum
    inside = index <= nt - 1
    low = np.clip(np.floor(index).astype(int), 0, nt - 1)
    high = np.clip(low + 1, 0, nt - 1)
    frac = np.clip(index, 0, nt - 1) - low
    rows = np.broadcast_to(np.arange(nr)[None, :, None], index.shape)
    cols = np.broadcast_to(np.arange(nc)[None, None, :], index.shape)
    moved = spectrum[low, rows, cols] * (1 - frac) + spectrum[high, rows, cols] * frac
    moved = moved * inside
    moved = moved * np.abs(kz) / np.maximum(source_kz, 1e-8) * (kz > 0)
    field = np.fft.ifftn(np.fft.ifftshift(moved))
    return np.abs(field) ** 2


def reconstruct(scan, side, snr):
    """scan: (t, r, c) counts; side: scanned side (m, calibrated); snr: the
    Wiener constant. Returns the (128, r, c) volume."""
    nr, nc = scan.shape[1], scan.shape[2]
    measured = resample(scan)
    measured = measured / measured.max()
    padded = np.zeros((2 * DEPTH_SAMPLES, 2 * nr, 2 * nc))
    padded[:DEPTH_SAMPLES, :nr, :nc] = measured
    transfer = slab_kernel(2 * DEPTH_SAMPLES, 2 * nr, 2 * nc, side)
    wiener = np.conj(transfer) / (np.abs(transfer) ** 2 + 1.0 / snr)
    deconvolved = np.real(np.fft.ifftn(np.fft.fftn(padded) * wiener))
    volume = stolt(deconvolved, side)[:DEPTH_SAMPLES, :nr, :nc]
    volume[-TRIMMED_TAIL:] = 0.0
    return volume


def main():
    if len(sys.argv) != 5:
        sys.exit(__doc__)
    path, side, snr, out = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
    with h5py.File(path, "r") as f:
        stored = np.asarray(f["meas"], dtype=np.float64)  # (axis 0, axis 1, t)
    scan = stored.transpose(2, 1, 0)  # (t, row = axis 1, column = axis 0)
    start = time.perf_counter()
    volume = reconstruct(scan, side, snr)
    elapsed = time.perf_counter() - start
    np.save(out, volume)
    print(f"{elapsed:.4f}")


if __name__ == "__main__":
    main()
