#!/usr/bin/env python3
"""Writes the OpenEXR test fixtures in tests/data/openexr/ with the OpenEXR
project's own library (`pip install OpenEXR`), so that the stack reader is
tested on files another writer made.

Values: bin k, row r, column c holds (k + 1) * 100 + r * 10 + c, exact in
float32 and in half (all below 2048). No scatterscope metadata attribute.
"""
import sys
from pathlib import Path

import numpy as np
import OpenEXR

BINS, HEIGHT, WIDTH = 3, 8, 8


def values(k):
    r, c = np.mgrid[0:HEIGHT, 0:WIDTH]
    return ((k + 1) * 100 + r * 10 + c).astype(np.float32)


def write(path, dtype, compression):
    channels = {f"t{k:03d}": values(k).astype(dtype) for k in range(BINS)}
    header = {"compression": compression, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, channels) as f:
        f.write(str(path))


def main():
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "tests/data/openexr")
    out.mkdir(parents=True, exist_ok=True)
    write(out / "float_zip.exr", np.float32, OpenEXR.ZIP_COMPRESSION)
    write(out / "half_piz.exr", np.float16, OpenEXR.PIZ_COMPRESSION)
    print(f"wrote {out}/float_zip.exr and {out}/half_piz.exr (OpenEXR {OpenEXR.__version__})")


if __name__ == "__main__":
    main()
