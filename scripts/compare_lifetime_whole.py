#!/usr/bin/env python3
"""`scatterscope lifetime` against the independent readers and PhasorPy,
whole process against whole process.

For each FLIM image in ../shared/data/flim-samples (the PicoHarp PTU and
the SPC-150 `.sdt`), runs, alternating:
- `scatterscope lifetime FILE --no-figures --min-photons 1` (maps as
  OME-TIFF and .npy with its sidecar), and the same with the figures;
- a Python process that decodes FILE with ptufile (`decode_image`) or
  sdtfile, computes PhasorPy's `phasor_from_signal` at harmonics 1 and 2
  with the bins' phases, and saves the mean, g and s with numpy.save.

Each process is timed from start to exit, its peak memory read from
`/usr/bin/time -v`; prints the median of RUNS runs of each. Equality of
the maps is checked by tests/lifetime.rs; this script times only.

With `--repeat 1,16,256`, instead: peak memory against file size. The
shared PTU's records are written K times over into one file (its frames
repeated, `TTResult_NumberOfRecords` set to K times its count; the
maps' image stays the same), and both sides run on each; with
`--sdt-blocks 1,4,16`, `.sdt` files of that many 256 x 256 x 256 blocks
(compare_bh_whole.py's writer; ours given `--frequency 80e6`, which
they do not record).

Usage: PYTHONPATH=target/pydeps python3 scripts/compare_lifetime_whole.py [--runs N] [--repeat K,K,...]
"""

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
SHARED = os.path.join(ROOT, "..", "shared", "data", "flim-samples")
FILES = [
    ("ptu", os.path.join(SHARED, "picoquant", "hazelnut_flim_z1.ptu")),
    ("sdt", os.path.join(SHARED, "becker-hickl", "SDT_c01.sdt")),
]

PYTHON = """
import sys, numpy
from phasorpy.phasor import phasor_from_signal
kind, path, out = sys.argv[1:4]
if kind == "ptu":
    import ptufile
    with ptufile.PtuFile(path) as f:
        stacks = [f.decode_image(dtype="uint32").sum(axis=0)[:, :, 0, :]]
        res = f.tags["MeasDesc_Resolution"]
        freq = f.tags["TTResult_SyncRate"]
    times = numpy.arange(stacks[0].shape[-1]) * res
else:
    import sdtfile
    f = sdtfile.SdtFile(path)
    stacks = f.data
    times = f.times[0]
    freq = float(numpy.ravel(f.measure_info[0]["StopInfo"]["max_sync_rate"])[0])
centres = times + (times[1] - times[0]) / 2
for i, s in enumerate(stacks):
    maps = []
    for h in (1, 2):
        mean, g, s_ = phasor_from_signal(s, axis=-1, sample_phase=2 * numpy.pi * h * freq * centres)
        maps += [g, s_]
    numpy.save(f"{out}/maps_{i}.npy", numpy.stack([mean] + maps).astype(numpy.float32))
"""


def timed(cmd, env=None):
    """(wall seconds, peak resident MB) of `cmd` under /usr/bin/time -v."""
    t = time.perf_counter()
    r = subprocess.run(["/usr/bin/time", "-v"] + cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t
    if r.returncode != 0:
        sys.exit(f"{cmd} failed:\n{r.stdout}\n{r.stderr}")
    peak = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", r.stderr).group(1))
    return wall, peak / 1024


def repeated_ptu(src, k, dst):
    """`src`'s records written `k` times over into `dst` (T3 records carry
    sync counts relative to overflow records, so the copies follow one
    another in time)."""
    import struct
    data = open(src, "rb").read()
    off, count_at = 16, None
    while True:  # PTU tags: 32-byte name, index, type, 8-byte value
        ident = data[off:off + 32].split(b"\0")[0]
        kind = struct.unpack("<I", data[off + 36:off + 40])[0]
        value = struct.unpack("<q", data[off + 40:off + 48])[0]
        if ident == b"TTResult_NumberOfRecords":
            count_at = off + 40
        off += 48
        if kind in (0x4001FFFF, 0x4002FFFF, 0xFFFFFFFF):  # strings and blobs follow their tag
            off += value
        if ident == b"Header_End":
            break
    header = bytearray(data[:off])
    records = data[off:]
    header[count_at:count_at + 8] = struct.pack("<q", k * (len(records) // 4))
    with open(dst, "wb") as f:
        f.write(header)
        for _ in range(k):
            f.write(records)


def memory_against_size(args, repeats):
    src = FILES[0][1]
    with tempfile.TemporaryDirectory() as tmp:
        for k in repeats:
            path = f"{tmp}/x{k}.ptu"
            repeated_ptu(src, k, path)
            mb = os.path.getsize(path) / 1e6
            ours = [timed([args.program, "lifetime", path, "--no-figures", "--min-photons", "1", "--out", f"{tmp}/o{k}"])
                    for _ in range(args.runs)]
            theirs = [timed([sys.executable, "-c", PYTHON, "ptu", path, tmp], env=dict(os.environ))
                      for _ in range(args.runs)]
            for name, runs in (("ours", ours), ("ptufile + PhasorPy + numpy.save", theirs)):
                print(f"x{k} ({mb:.1f} MB): {name}: median {statistics.median(w for w, _ in runs):.3f} s, "
                      f"peak {statistics.median(p for _, p in runs):.0f} MB ({args.runs} runs)")


def memory_against_blocks(args, counts):
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from compare_bh_whole import write_sdt
    with tempfile.TemporaryDirectory() as tmp:
        for k in counts:
            path = f"{tmp}/b{k}.sdt"
            write_sdt(path, blocks=k)
            mb = os.path.getsize(path) / 1e6
            ours = [timed([args.program, "lifetime", path, "--no-figures", "--min-photons", "1",
                           "--frequency", "80e6", "--out", f"{tmp}/o{k}"]) for _ in range(args.runs)]
            theirs = [timed([sys.executable, "-c", PYTHON, "sdt", path, tmp], env=dict(os.environ))
                      for _ in range(args.runs)]
            for name, runs in (("ours", ours), ("sdtfile + PhasorPy + numpy.save", theirs)):
                print(f"{k} blocks ({mb:.0f} MB): {name}: median {statistics.median(w for w, _ in runs):.3f} s, "
                      f"peak {statistics.median(p for _, p in runs):.0f} MB ({args.runs} runs)")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--program", default=os.path.join(ROOT, "target", "release", "scatterscope"))
    ap.add_argument("--repeat", help="K,K,...: peak memory against file size instead")
    ap.add_argument("--sdt-blocks", help="K,K,...: peak memory against .sdt blocks instead")
    args = ap.parse_args()
    if args.sdt_blocks:
        memory_against_blocks(args, [int(k) for k in args.sdt_blocks.split(",")])
        return
    if args.repeat:
        memory_against_size(args, [int(k) for k in args.repeat.split(",")])
        return
    for kind, path in FILES:
        results = {"ours (maps)": [], "ours (maps and figures)": [], "ptufile/sdtfile + PhasorPy + numpy.save": []}
        with tempfile.TemporaryDirectory() as tmp:
            for _ in range(args.runs):
                results["ours (maps)"].append(
                    timed([args.program, "lifetime", path, "--no-figures", "--min-photons", "1", "--out", f"{tmp}/a"])
                )
                results["ours (maps and figures)"].append(
                    timed([args.program, "lifetime", path, "--min-photons", "1", "--out", f"{tmp}/b"])
                )
                results["ptufile/sdtfile + PhasorPy + numpy.save"].append(
                    timed([sys.executable, "-c", PYTHON, kind, path, tmp], env=dict(os.environ))
                )
        for name, runs in results.items():
            wall = statistics.median(w for w, _ in runs)
            peak = statistics.median(p for _, p in runs)
            print(f"{os.path.basename(path)}: {name}: median {wall:.3f} s, peak {peak:.0f} MB ({args.runs} runs)")


main()
