#!/usr/bin/env bash
# `scatterscope bin` of a large single-pixel T3 file against a plain C
# decode + histogram loop (scripts/decode_floor.c), each a whole process
# timed from start to exit, page cache warm, alternating runs, medians:
#
#   bash scripts/compare_floor.sh [RECORDS] [RUNS]
#
# Both run on one core (`taskset -c 0`); `scatterscope bin` also runs on
# every core (it bins parts of the file at once). Prints M records/s.
set -euo pipefail
cd "$(dirname "$0")/.."
records="${1:-200000000}"
runs="${2:-5}"
work=target/floor-compare
mkdir -p "$work"
cargo build --release --quiet --example synthetic_ptu --bin scatterscope
cc -O2 -o "$work/decode_floor" scripts/decode_floor.c
file="$work/synthetic.ptu"
if [ ! -f "$file" ] || [ "$(cat "$work/records" 2>/dev/null)" != "$records" ]; then
    target/release/examples/synthetic_ptu "$file" "$records" >/dev/null
    echo "$records" >"$work/records"
fi
cat "$file" >/dev/null # into the page cache
present=$(( ($(stat -c %s "$file") - $(head -c 65536 "$file" | grep -abo Header_End | head -1 | cut -d: -f1) - 48) / 4 ))

seconds() { # command... -> wall seconds of the whole process
    local t0 t1
    t0=$(date +%s.%N)
    "$@" >/dev/null
    t1=$(date +%s.%N)
    awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.4f\n", b - a }'
}
bin() { target/release/scatterscope bin "$file" --bin-width 4ps --bins 3125 --pixels single --no-preview --out "$work/bin"; }
: >"$work/c" ; : >"$work/one" ; : >"$work/all"
for _ in $(seq "$runs"); do
    seconds taskset -c 0 "$work/decode_floor" "$file" 3125 >>"$work/c"
    seconds taskset -c 0 bash -c "$(declare -f bin); file=$file work=$work bin" >>"$work/one"
    seconds bash -c "$(declare -f bin); file=$file work=$work bin" >>"$work/all"
done
median() { sort -n "$1" | awk '{ v[NR] = $1 } END { print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
for which in c one all; do
    m=$(median "$work/$which")
    case $which in
        c) label="plain C loop, one core" ;;
        one) label="scatterscope bin, one core" ;;
        all) label="scatterscope bin, $(nproc) cores" ;;
    esac
    awk -v l="$label" -v m="$m" -v n="$present" 'BEGIN { printf "%-32s median %.3f s  %4.0f M records/s\n", l, m, n / m / 1e6 }'
done
