#!/usr/bin/env python3
"""`scatterscope bin` of Becker & Hickl files against the independent
readers, whole process against whole process.

Writes under target/bh-compare (if missing) a `.spc` FIFO file of the
SPC-130 family (RECORDS records: photons on 4 routing channels with a
decay, macro-time overflows, a few invalid records) and an `.sdt` file of
one image block of 256 u16 points per pixel (64 x 64 and 256 x 256
pixels by default), both from B&H's documented layouts. Then runs, alternating, `scatterscope bin FILE --no-preview
--pixels channel` (`.spc`, with `--micro-unit`) or `bin FILE
--no-preview` (`.sdt`) and a Python process that decodes the same file
with tttrlib (micro times histogrammed per routing channel with
numpy.bincount) or sdtfile, and saves it with numpy.save. Each process is
timed from start to exit; prints the median of RUNS runs of each and the
ratio. Decode-for-decode equality is checked by tests/becker_hickl.rs;
this script times only.

Usage: PYTHONPATH=target/pydeps python3 scripts/compare_bh_whole.py [--runs N] [--records N]
"""

import argparse
import os
import statistics
import struct
import subprocess
import sys
import tempfile
import time

import numpy

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
DIR = os.path.join(ROOT, "target", "bh-compare")

TTTRLIB_SAVE = """
import sys, numpy, tttrlib
t = tttrlib.TTTR(sys.argv[1], "SPC-130")
ch = t.routing_channels.astype(numpy.int64)
micro = t.micro_times.astype(numpy.int64)
photons = t.event_types == 0
h = numpy.bincount(micro[photons] * 16 + ch[photons], minlength=4096 * 16).reshape(4096, 1, 16)
numpy.save(sys.argv[2], h.astype(numpy.uint32))
"""

SDTFILE_SAVE = """
import sys, numpy, sdtfile
f = sdtfile.SdtFile(sys.argv[1])
numpy.save(sys.argv[2], numpy.ascontiguousarray(numpy.moveaxis(f.data[0], -1, 0)))
"""


def write_spc(path, records):
    """SPC-130 records: header (50 ns clock, 2 routing bits), then photons
    on channels 0-3 (ADC counted back from the sync), an MTOV flag every
    4096 clocks, 1 % invalid records."""
    rng = numpy.random.default_rng(5)
    mt = numpy.cumsum(rng.integers(1, 400, records, dtype=numpy.int64))
    mtov = numpy.diff(mt // 4096, prepend=0) > 0
    adc = 4095 - numpy.minimum(rng.exponential(600, records), 4095).astype(numpy.uint32)
    rec = (
        (mt % 4096).astype(numpy.uint32)
        | (rng.integers(0, 4, records, dtype=numpy.uint32) << 12)
        | (adc << 16)
        | (mtov.astype(numpy.uint32) << 30)
    )
    invalid = (rng.random(records) < 0.01) & ~mtov
    rec[invalid] |= numpy.uint32(1 << 31)
    with open(path, "wb") as f:
        f.write(struct.pack("<I", (1 << 31) | (2 << 27) | 500))
        rec.astype("<u4").tofile(f)


def write_sdt(path, side=256, points=256, blocks=1):
    """`blocks` IMG blocks of side x side curves of `points` u16 counts
    (the same counts in each, chained by their headers)."""
    rng = numpy.random.default_rng(6)
    data = rng.poisson(20 * numpy.exp(-numpy.arange(points) / 40.0), (side * side, points)).astype("<u2")
    info = b"*IDENTIFICATION\r\n  ID        : SPC Setup & Data File\r\n*END\r\n"
    meas = bytearray(512)
    struct.pack_into("<f", meas, 64, 12.5e-9)
    struct.pack_into("<h", meas, 68, 1)
    struct.pack_into("<h", meas, 82, points)
    struct.pack_into("<iiii", meas, 173, side, side, 1, 1)
    info_offs, meas_offs = 42, 42 + len(info)
    block_offs = meas_offs + 512
    header = struct.pack(
        "<hihihihIihhHIHH",
        (0x28 << 4) | 15, info_offs, len(info), 0, 0, block_offs, blocks, data.nbytes,
        meas_offs, 1, 512, 0x5555, 1, 0, 0x55AA,
    )
    step = 22 + data.nbytes
    with open(path, "wb") as f:
        f.write(header + info + bytes(meas))
        for k in range(blocks):
            at = block_offs + k * step
            # The first two bytes extend the offsets past 4 GB (0 here).
            f.write(struct.pack("<BBIIHhII", 0, 0, at + 22, at + step, 0x61, 0, k + 1, data.nbytes))
            data.tofile(f)


def wall(cmd):
    start = time.perf_counter()
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    seconds = time.perf_counter() - start
    if done.returncode not in (0, 4):
        sys.exit(f"{' '.join(cmd)}: exit {done.returncode}: {done.stderr.decode()}")
    return seconds


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--records", type=int, default=20_000_000)
    parser.add_argument("--sdt-sides", default="64,256", help="image sides of the .sdt files (256 points each)")
    parser.add_argument("--cli", default=os.path.join(ROOT, "target", "release", "scatterscope"))
    args = parser.parse_args()
    os.makedirs(DIR, exist_ok=True)
    spc = os.path.join(DIR, f"fifo_{args.records}.spc")
    if not os.path.exists(spc):
        write_spc(spc, args.records)
    sdts = []
    for side in (int(v) for v in args.sdt_sides.split(",")):
        sdt = os.path.join(DIR, f"image_{side}.sdt")
        if not os.path.exists(sdt):
            write_sdt(sdt, side)
        sdts.append(sdt)
    print("| file | size | `bin --no-preview` (s) | independent reader + numpy.save (s) | ratio |")
    print("| --- | --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as tmp:
        for path, ours, theirs, name in [
            (spc, ["--micro-unit", "12.2ps", "--pixels", "channel"], TTTRLIB_SAVE, "tttrlib"),
        ] + [(sdt, [], SDTFILE_SAVE, "sdtfile") for sdt in sdts]:
            a, b = [], []
            for _ in range(args.runs):
                a.append(wall([args.cli, "bin", path, "--no-preview", "--out", os.path.join(tmp, "o")] + ours))
                b.append(wall([sys.executable, "-c", theirs, path, os.path.join(tmp, "h.npy")]))
            ma, mb = statistics.median(a), statistics.median(b)
            size = os.path.getsize(path) / 1e6
            print(f"| {os.path.basename(path)} | {size:.0f} MB | {ma:.3f} | {mb:.3f} ({name}) | {mb / ma:.1f}x |")


if __name__ == "__main__":
    main()
