#!/usr/bin/env bash
# Sustained rate of a PicoQuant acquisition through the stand-in vendor
# library: the FIFO read loop, decode -> bin, and the PTU written as the
# records arrive, on this machine.
#
#   bash scripts/bench_picoquant.sh [RUNS]
#
# The stand-in delivers full FIFO reads as fast as they are asked for
# (SCATTERSCOPE_PQ_MOCK=rate=max) of a 2 M photons/s, 80 MHz-sync
# measurement of 100 s (207 M records). Three destinations for the PTU: a
# RAM disk (/dev/shm), the disk (target/), none. Prints each run's
# records/s from acquisition.json and the median per destination, and
# checks that no record was lost (the ledger balances, the PTU holds every
# record read).
set -euo pipefail
cd "$(dirname "$0")/.."
runs="${1:-5}"
# Two builds: `--bin` would also filter out the stand-in's cdylib.
# SCATTERSCOPE_BIN runs another build of the CLI (a before/after
# comparison) against the same stand-in.
cargo build --release --quiet -p scatterscope-mock-picoquant
cargo build --release --quiet -p scatterscope --bin scatterscope
lib=target/release/libscatterscope_mock_picoquant.so
bin="${SCATTERSCOPE_BIN:-target/release/scatterscope}"
work=target/bench-picoquant
mkdir -p "$work"
for dest in ramdisk disk none; do
    rates=()
    for _ in $(seq "$runs"); do
        case $dest in
            ramdisk) ptu=(--ptu /dev/shm/scatterscope-bench.ptu) ;;
            disk) ptu=(--ptu "$work/bench.ptu") ;;
            none) ptu=(--no-ptu) ;;
        esac
        SCATTERSCOPE_PQ_MOCK=rate=max "$bin" acquire \
            --device picoquant --vendor-lib "$lib" --duration 100s \
            "${ptu[@]}" --out "$work/out" >/dev/null
        rate=$(python3 - "$work/out/acquisition.json" "$dest" <<'PY'
import json, sys
a = json.load(open(sys.argv[1]))
l = a["ledger"]
bal = l["photons"] == l["binned"] + l["outside_window"] + l["other_channel"] + l["outside_region"]
assert bal, "photons lost between decoding and binning"
if sys.argv[2] != "none":
    r = l["recordings"][0]
    assert r["whole"] and r["records"] == l["records"], "records missing from the PTU"
print(f'{a["records_per_s"] / 1e6:.1f}')
PY
)
        rates+=("$rate")
        rm -f /dev/shm/scatterscope-bench.ptu "$work/bench.ptu"
    done
    median=$(printf '%s\n' "${rates[@]}" | sort -n | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}')
    echo "$dest: ${rates[*]} M records/s; median $median M records/s"
done
