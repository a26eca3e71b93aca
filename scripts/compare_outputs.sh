#!/bin/bash
# Outputs of two `scatterscope` binaries on the same inputs, file for file:
# the paper preset's simulation, every reconstruction method on it, and
# `hidden` on the shared confocal scans (auto and published on all twelve,
# poisson on two, thinned to 10 %). Prints `same FILE` or `DIFF FILE` for
# every output, then compares the traces without their wall times.
# For a change that must keep outputs byte-identical (issue 51's check).
#
#   bash scripts/compare_outputs.sh OLD_BINARY NEW_BINARY OUT_DIR
set -u
OLD=$1
NEW=$2
OUT=$3
SCANS=$(dirname "$0")/../../shared/data/cdt-scenes
rm -rf "$OUT"
mkdir -p "$OUT/old" "$OUT/new"
run() { # run LOG ARGS...: both binaries, outputs under old/ and new/
  local log=$1
  shift
  for side in old new; do
    local bin=$OLD
    [ "$side" = new ] && bin=$NEW
    "$bin" "${@//@OUT@/$OUT/$side}" >"$OUT/$side/$log.log" 2>&1 || echo "FAIL $side $log"
  done
}
run sim simulate --scene usaf --preset paper --seed 1 --out @OUT@/sim
STACK=$OUT/new/sim/counts.exr
for m in auto pnp pnp-sum pnp-slice rl rl-sum rl-stack scaled-counts; do
  extra=()
  case $m in pnp-slice | rl) extra=(--bin 5) ;; esac
  run "rec-$m" reconstruct "$STACK" --method $m "${extra[@]}" --out "@OUT@/rec-$m"
done
# `--bin-ps`, the bin width's old spelling, which binaries from before the
# twenty-eighth session read too (newer ones note the new name).
for scan in letter_s letters_ut cones resolution_50 letter_u_50 letter_u_52 letter_u_54 \
  letter_u_56 letter_u_58 letter_u_60 letter_u_62 letter_u_64; do
  for m in auto published; do
    run "hid-$scan-$m" hidden "$SCANS/$scan.mat" --scan-side 63.6cm --slab-thickness 1in \
      --bin-ps 16 --method $m --out "@OUT@/hid-$scan-$m"
  done
done
for scan in letter_s cones; do
  run "hid-$scan-poisson" hidden "$SCANS/$scan.mat" --scan-side 63.6cm --slab-thickness 1in \
    --bin-ps 16 --method poisson --thin 0.1 --out "@OUT@/hid-$scan-poisson"
done
(cd "$OUT/old" && find . -type f ! -name "*.log" | sort | while read -r f; do
  if cmp -s "$f" "../new/$f"; then echo "same $f"; else echo "DIFF $f"; fi
done)
python3 - "$OUT" <<'PY'
import csv, glob, json, re, sys
out = sys.argv[1]
timed = lambda k: "wall" in k or k.endswith("_s") or k == "notes"
def rows(p):
    r = list(csv.reader(open(p)))
    keep = [i for i, c in enumerate(r[0]) if not timed(c)]
    return [[x[i] for i in keep] for x in r]
def untimed(o):
    if isinstance(o, dict):
        return {k: untimed(v) for k, v in o.items() if not timed(k)}
    return [untimed(x) for x in o] if isinstance(o, list) else o
notes = lambda o: [re.sub(r"\d+\.\d+ s", "X s", n) for n in o.get("notes", [])]
bad = 0
for p in sorted(glob.glob(f"{out}/old/**/trace.*", recursive=True)):
    q = p.replace(f"{out}/old/", f"{out}/new/", 1)
    if p.endswith(".csv"):
        same = rows(p) == rows(q)
    else:
        a, b = json.load(open(p)), json.load(open(q))
        same = untimed(a) == untimed(b) and notes(a) == notes(b)
    if not same:
        bad += 1
        print(f"trace differs beyond its times: {p}")
print(f"traces differing beyond their times: {bad}")
PY
