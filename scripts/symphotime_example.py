"""Writes tests/data/symphotime/example.json: the few numbers of
PicoQuant's SymPhoTime 64 example that tests/symphotime.rs needs, read by
independent readers (ptufile for the PTU, tifffile for SymPhoTime's
exported TIFFs), never by scatterscope.

The example is in the public repository UU-cellbiology/PTU_Reader, folder
example_data/PicoHarp_SymPhoTime: Example_PTU_PicoHarp.ptu (PicoHarp 300,
written by SymPhoTime 64 1.6), SymPhoTime_fast_lifetime_ns.tif and
SymPhoTime_photon_count.tif (SymPhoTime's export of it). Only counts and
exported values are kept, no file.

Usage: python3 scripts/symphotime_example.py FOLDER COMMIT
(FOLDER holds the three files; PYTHONPATH=target/pydeps for ptufile).
"""
import json
import sys

import numpy as np
import ptufile
import tifffile

folder, commit = sys.argv[1], sys.argv[2]
ptu = ptufile.PtuFile(f"{folder}/Example_PTU_PicoHarp.ptu")
counts = ptu.decode_image()[0, :, :, 0, :].astype(np.int64)  # rows, cols, bins
fast_ns = tifffile.imread(f"{folder}/SymPhoTime_fast_lifetime_ns.tif")
photons = tifffile.imread(f"{folder}/SymPhoTime_photon_count.tif")
bins = counts.shape[-1]
n = counts.sum(-1)
# Pixels of several brightnesses, and each with a photon in the last,
# cut bin (SymPhoTime leaves that bin out).
order = np.argsort(n.ravel())[::-1]
chosen = list(order[:4]) + list(order[2000:8000:1000])
late = np.argwhere(counts[..., -1] > 0)
chosen += [r * counts.shape[1] + c for r, c in late[:3]]
pixels = []
for p in chosen:
    r, c = divmod(int(p), counts.shape[1])
    pixels.append({
        "row": r,
        "column": c,
        "counts": counts[r, c].tolist(),
        "symphotime_fast_lifetime_ns": float(fast_ns[r, c]),
        "symphotime_photons": float(photons[r, c]),
    })
out = {
    "source": f"UU-cellbiology/PTU_Reader @ {commit} : example_data/PicoHarp_SymPhoTime (read by ptufile {ptufile.__version__} and tifffile {tifffile.__version__})",
    "bin_width_ps": ptu.tcspc_resolution * 1e12,
    "sync_period_ps": ptu.global_resolution * 1e12,
    "bins": bins,
    "image_summed_decay": counts.sum((0, 1)).tolist(),
    "pixels": pixels,
}
json.dump(out, open("tests/data/symphotime/example.json", "w"), indent=1)
print(f"{len(pixels)} pixels, {bins} bins")
