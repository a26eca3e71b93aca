"""What a notebook does with scatterscope: read a PTU, bin it, simulate a
scene through the paper's slab, reconstruct it, and plot.

    python python/examples/notebook_demo.py [FILE.ptu] [--out DIR]

Without a PTU argument it uses ../shared's HydraHarp sample when present,
else records one from the emulated device first. Writes notebook_demo.png
(matplotlib, no display needed) into --out (default: out/python-demo).
"""

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import scatterscope  # noqa: E402

REPO = Path(__file__).resolve().parents[2]


def some_ptu(work: Path) -> Path:
    sample = REPO.parent / "shared" / "data" / "picoquant-sample-data" / "hydraharp" / "v20_t3.ptu"
    if sample.exists():
        return sample
    # No sample here: record 0.3 s from the mock device and convert it.
    cli = REPO / "target" / "release" / "scatterscope"
    tags = work / "mock.sstags"
    subprocess.run([str(cli), "acquire", "--size", "7", "--duration", "300ms", "--tags", str(tags),
                    "--out", str(work / "acq")], check=True, capture_output=True)
    ptu = work / "mock.ptu"
    subprocess.run([str(cli), "convert", str(tags), "--out", str(ptu)], check=True, capture_output=True)
    return ptu


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("ptu", nargs="?", type=Path)
    parser.add_argument("--out", type=Path, default=Path("out/python-demo"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    with tempfile.TemporaryDirectory() as tmp:
        ptu = args.ptu or some_ptu(Path(tmp))
        tags = scatterscope.read_tags(ptu)
        binned = scatterscope.bin_file(ptu, pixels="single")
    print(f"{ptu.name}: {len(tags['channel'])} photons; " + binned["summary"][0])
    histogram = binned["stacks"][0][:, 0, 0]
    bin_ps = binned["meta"][0]["bin_width_ps"]

    sim = scatterscope.simulate("usaf", seed=1, size=128)
    image, trace, notes = scatterscope.reconstruct(sim["counts"], sim["meta"], method="rl-stack")
    for note in notes:
        print("note:", note)
    rows = trace["rows"]
    print(f"{trace['method']}: {len(rows['iteration'])} iterations in {trace['wall_s']:.2f} s")

    fig, ax = plt.subplots(1, 4, figsize=(16, 4))
    ax[0].semilogy(np.arange(len(histogram)) * bin_ps / 1000.0, np.maximum(histogram, 0.5))
    ax[0].set(xlabel="micro time (ns)", ylabel="photons", title=ptu.name)
    ax[1].imshow(sim["truth"], cmap="gray")
    ax[1].set_title("scene")
    ax[2].imshow(sim["counts"].sum(axis=0), cmap="gray")
    ax[2].set_title("counts through 3 cm of skin-like slab")
    ax[3].imshow(image, cmap="gray")
    ax[3].set_title(f"{trace['method']} reconstruction")
    for a in ax[1:]:
        a.axis("off")
    fig.tight_layout()
    png = args.out / "notebook_demo.png"
    fig.savefig(png, dpi=80)
    print(f"wrote {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
