#!/usr/bin/env bash
# Flame graphs of the two commands users run most, for docs/figures/:
#   - `reconstruct` with the default method (auto) on the paper preset's
#     text scene at its light (the demo's reconstruction);
#   - `bin` of a synthetic Generic T3 file of 100 M records (4 channels).
#
#   bash scripts/flamegraphs.sh [OUT_DIR]     (default docs/figures)
#
# Needs perf (linux-perf) and inferno (`cargo install inferno`). The stacks
# are unwound from DWARF (the release profile keeps line tables); frames
# narrower than 2 pixels are left out.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-docs/figures}"
for tool in perf inferno-collapse-perf inferno-flamegraph; do
    command -v "$tool" >/dev/null || { echo "flamegraphs.sh: $tool not found" >&2; exit 2; }
done
cargo build --release --quiet -p scatterscope --bin scatterscope --example synthetic_ptu
bin=target/release/scatterscope
work=target/flamegraphs
mkdir -p "$work" "$out"

graph() { # name, title, sampling rate (Hz), command...
    local name=$1 title=$2 rate=$3
    shift 3
    perf record -F "$rate" --call-graph dwarf,8192 -o "$work/$name.perf" -- "$@" >/dev/null
    perf script -i "$work/$name.perf" 2>/dev/null | inferno-collapse-perf >"$work/$name.folded"
    inferno-flamegraph --title "$title" --width 1400 --minwidth 2 <"$work/$name.folded" >"$work/$name.svg"
    mv "$work/$name.svg" "$out/flame-$name.svg"
    echo "wrote $out/flame-$name.svg"
}

"$bin" simulate --preset paper --scene text --out "$work/text" >/dev/null
graph reconstruct "scatterscope reconstruct (auto) of the paper preset's text scene" 99 \
    "$bin" reconstruct "$work/text/counts.exr" --out "$work/text-recon"

target/release/examples/synthetic_ptu "$work/synthetic.ptu" 100000000 >/dev/null
graph bin "scatterscope bin of a 100 M-record Generic T3 file (4 channels)" 1999 \
    "$bin" bin "$work/synthetic.ptu" --out "$work/synthetic-bin"
rm -f "$work/synthetic.ptu"
