#!/usr/bin/env bash
# Decode + bin of the same T3 file by scatterscope and by Python's ptufile
# (Christoph Gohlke's reader, C-accelerated), on this machine, one core.
#
#   bash scripts/compare_ptufile.sh [RECORDS]
#
# Installs ptufile and numpy into a throwaway venv under target/, writes the
# synthetic Generic T3 file the tag benchmarks use, then times three runs of
# each: `scatterscope bin` (its own decode + bin timer, 3125 x 4 ps bins,
# one pixel) and `PtuFile.decode_histogram` (all records, histogram of one
# period per channel). Prints the best of three and the ratio.
set -euo pipefail
cd "$(dirname "$0")/.."
records="${1:-20000000}"
work=target/ptufile-compare
venv="$work/venv"
mkdir -p "$work"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install --quiet ptufile numpy
fi
cargo build --release --quiet --example synthetic_ptu --bin scatterscope
file="$work/synthetic.ptu"
target/release/examples/synthetic_ptu "$file" "$records" >/dev/null
cat "$file" >/dev/null # into the page cache

best_ours=""
for _ in 1 2 3; do
    # "N records (R M records/s): ...": the decode + bin time is N / R.
    line=$(target/release/scatterscope bin "$file" --bin-width 4ps --bins 3125 --pixels single --no-preview --out "$work/bin" | grep "M records/s")
    secs=$(echo "$line" | sed -E 's/^([0-9]+) records \(([0-9.]+) M records\/s\).*/\1 \2/' | awk '{ printf "%.4f", $1 / ($2 * 1e6) }')
    if [ -z "$best_ours" ] || awk "BEGIN{exit !($secs < $best_ours)}"; then best_ours=$secs; fi
done

best_py=$("$venv/bin/python" - "$file" <<'PY'
import sys, time
import ptufile
best = None
for _ in range(3):
    t = time.perf_counter()
    with ptufile.PtuFile(sys.argv[1]) as ptu:
        h = ptu.decode_histogram(dtype="uint32")
    dt = time.perf_counter() - t
    best = dt if best is None else min(best, dt)
print(f"{best:.4f}")
PY
)
ver=$("$venv/bin/python" -c "import ptufile; print(ptufile.__version__)")
awk -v n="$records" -v a="$best_ours" -v b="$best_py" -v v="$ver" 'BEGIN {
    printf "records: %d\n", n
    printf "scatterscope bin:              %.3f s  (%.0f M records/s)\n", a, n / a / 1e6
    printf "ptufile %s decode_histogram: %.3f s  (%.0f M records/s)\n", v, b, n / b / 1e6
    printf "ratio (ptufile time / scatterscope time): %.2f\n", b / a
}'
