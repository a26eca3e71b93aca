#!/usr/bin/env bash
# Installs numpy and h5py under target/pydeps for scripts/cdt_reference.py,
# the independent numpy implementation the confocal test compares against.
# Nothing is installed system-wide; the test sets PYTHONPATH to that folder.
set -euo pipefail
cd "$(dirname "$0")/.."
dest=target/pydeps
if PYTHONPATH="$dest" python3 -c "import numpy, h5py" 2>/dev/null; then
    echo "already present: numpy and h5py under $dest"
    exit 0
fi
mkdir -p "$dest"
python3 -m pip install --quiet --disable-pip-version-check --target "$dest" numpy h5py
echo "installed numpy and h5py under $dest"
