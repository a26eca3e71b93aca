#!/usr/bin/env bash
# Installs under target/pydeps the independent Python readers the tests
# check our files against, and what drives the browser test:
# - numpy and h5py, for scripts/cdt_reference.py (the independent numpy
#   implementation the confocal test compares against) and forged MATLAB
#   files;
# - scipy, whose scipy.io reads and writes MATLAB level 5 files
#   independently of our reader and writer, and whose FFTs make the
#   independent forward model of scripts/embedded_independent.py;
# - ptufile, the independent PTU reader our PTU files are decoded with;
# - OpenEXR, the OpenEXR project's own library, reading our stacks back;
# - tifffile and ome-types, reading our OME-TIFF files and parsing their
#   OME-XML;
# - tttrlib and sdtfile, decoding Becker & Hickl .spc and .sdt files
#   independently of our readers;
# - phasorpy, the phasor and lifetime reference the decay maps are held to;
# - flimlib (GPL-3), the lifetime-fitting reference `scatterscope fit` is
#   held to (scripts/fit_reference.py): installed here for tests only,
#   never linked, copied or shipped;
# - iadpython (MIT), Prahl's adding-doubling: the slab's total reflection
#   and transmission with mismatched faces, the reference the Monte Carlo
#   transport is held to (scripts/adding_doubling_reference.py);
# - playwright, which drives the system's Chromium (Debian's package; its
#   own browser download is never used) in the live view's browser test.
# Nothing is installed system-wide; the tests set PYTHONPATH to that folder.
set -euo pipefail
cd "$(dirname "$0")/.."
dest=target/pydeps
packages=(numpy scipy h5py ptufile OpenEXR tifffile ome-types tttrlib sdtfile phasorpy flimlib iadpython playwright)
modules="numpy, scipy, h5py, ptufile, OpenEXR, tifffile, ome_types, tttrlib, sdtfile, phasorpy, flimlib, iadpython, playwright"
if PYTHONPATH="$dest" python3 -c "import $modules" 2>/dev/null; then
    echo "already present under $dest: ${packages[*]}"
    exit 0
fi
mkdir -p "$dest"
python3 -m pip install --quiet --disable-pip-version-check --target "$dest" "${packages[@]}"
echo "installed under $dest: ${packages[*]}"
