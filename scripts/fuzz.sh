#!/usr/bin/env bash
# Runs every cargo-fuzz target (or the ones named) for SECONDS each, two at
# a time, with memory and time limits, and prints executions, rate and
# findings per target. Installs the nightly toolchain and cargo-fuzz when
# missing. Crashes land in fuzz/artifacts/TARGET/; turn each into a test.
#
#   scripts/fuzz.sh SECONDS [TARGET...]
#
# Environment: JOBS (targets at once, default: number of cores),
# RSS_MB (per-target memory limit, default 2048).
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:?usage: scripts/fuzz.sh SECONDS [TARGET...]}
shift
jobs=${JOBS:-$(nproc)}
rss=${RSS_MB:-2048}
if [ $# -gt 0 ]; then
    targets=("$@")
else
    mapfile -t targets < <(sed -n 's/^name = "\(.*\)"$/\1/p' fuzz/Cargo.toml | grep -v scatterscope-fuzz)
fi
rustup toolchain list | grep -q '^nightly' || rustup toolchain install nightly --profile minimal
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz
cargo build --release --quiet
python3 scripts/fuzz_seeds.py fuzz/seeds target/release/scatterscope
# Release builds with overflow checks and debug assertions (-a); no
# sanitizer (-s none): the code under test is safe Rust (unsafe code lives
# only in the FFDNet convolution kernels, which no target reaches), so
# AddressSanitizer would find nothing that Rust does not already check,
# at 2-3x the cost per execution.
flags=(-O -a -s none)
(cd fuzz && cargo +nightly fuzz build "${flags[@]}")
mkdir -p fuzz/logs
run_one() {
    local t=$1
    mkdir -p "fuzz/corpus/$t" "fuzz/seeds/$t"
    (cd fuzz && cargo +nightly fuzz run $flags_str "$t" "corpus/$t" "seeds/$t" -- \
        -max_total_time="$secs" -rss_limit_mb="$rss" -timeout=10 -max_len=262144 \
        -print_final_stats=1) >"fuzz/logs/$t.log" 2>&1 && echo "$t: ok" || echo "$t: FAILED (fuzz/logs/$t.log)"
}
export -f run_one
export secs rss
export flags_str="${flags[*]}"
printf '%s\n' "${targets[@]}" | xargs -P "$jobs" -I{} bash -c 'run_one {}'
printf '\n| target | executions | exec/s | peak RSS (MB) | result |\n|---|---|---|---|---|\n'
for t in "${targets[@]}"; do
    log=fuzz/logs/$t.log
    runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
    peak=$(sed -n 's/^stat::peak_rss_mb: *//p' "$log" | tail -1)
    if grep -qE 'ERROR: libFuzzer|panicked|SUMMARY: ' "$log"; then result="finding: see $log"; else result="no crash"; fi
    echo "| $t | ${runs:-?} | ${rate:-?} | ${peak:-?} | $result |"
done
