#!/usr/bin/env bash
# Installs numpy and h5py under target/pydeps for scripts/cdt_reference.py,
# the independent numpy implementation the confocal test compares against,
# ptufile, the independent PTU reader the PicoQuant acquisition test
# decodes our PTU files with, OpenEXR, the OpenEXR project's own library
# that reads our stack files back in a test, and playwright, which drives the system's
# Chromium (Debian's package; its own browser download is never used) in
# the live view's browser test.
# Nothing is installed system-wide; the test sets PYTHONPATH to that folder.
set -euo pipefail
cd "$(dirname "$0")/.."
dest=target/pydeps
if PYTHONPATH="$dest" python3 -c "import numpy, h5py, ptufile, OpenEXR, playwright" 2>/dev/null; then
    echo "already present: numpy, h5py, ptufile, OpenEXR and playwright under $dest"
    exit 0
fi
mkdir -p "$dest"
python3 -m pip install --quiet --disable-pip-version-check --target "$dest" numpy h5py ptufile OpenEXR playwright
echo "installed numpy, h5py, ptufile, OpenEXR and playwright under $dest"
