"""The live view's error against run time: runs a mock acquisition with
`--live` (no browser), reads the page's state twice a second, and prints
each reconstruction the page showed: when its snapshot was taken, how long
it took, its PSNR against the scene, and whether it was shown before the
run ended; then the whole run's reconstruction.

    python3 scripts/live_snapshots.py [--browser] [DURATION] [extra acquire arguments]

With --browser, headless Chromium has the page open all along (the live
view test's browser, `tests/live/browser_check.py`: Debian's chromium and
playwright under target/pydeps, `scripts/fetch_python_deps.sh`).
"""
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CLI = os.path.join(ROOT, "target", "release", "scatterscope")


def main():
    args = sys.argv[1:]
    browser = "--browser" in args
    args = [a for a in args if a != "--browser"]
    duration = args[0] if args else "20s"
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [CLI, "acquire", "--device", "mock", "--duration", duration, "--live", "127.0.0.1:0",
               "--linger", "1s", "--out", os.path.join(tmp, "acq")] + args[1:]
        child = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        url = None
        while url is None:
            line = child.stdout.readline()
            if not line:
                sys.exit(f"{' '.join(cmd)}: no live view address: {child.stderr.read()}")
            m = re.search(r"http://\S+", line)
            url = m and m.group(0)
        if browser:
            env = dict(os.environ, PYTHONPATH=os.path.join(ROOT, "target", "pydeps"))
            check = os.path.join(ROOT, "tests", "live", "browser_check.py")
            viewer = subprocess.Popen([sys.executable, check, url, "1", "watch"], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        during, state = set(), None
        while child.poll() is None:
            try:
                with urllib.request.urlopen(url + "state", timeout=5) as r:
                    state = json.load(r)
            except OSError:
                break
            if not state["done"]:
                during.update(p["acquired_s"] for p in state["trace"])
            time.sleep(0.5)
        child.wait()
        if browser:
            if viewer.poll() not in (None, 0):
                sys.exit(f"the browser failed: {viewer.stderr.read()}")
            viewer.terminate()
            viewer.wait()
        if child.returncode not in (0, 4):
            sys.exit(f"{' '.join(cmd)}: exit {child.returncode}: {child.stderr.read()}")
    print("| snapshot at (s of acquisition) | photons | run (s) | PSNR (dB) | shown during the run |")
    print("| --- | --- | --- | --- | --- |")
    for p in state["trace"]:
        psnr = "-" if p["psnr_db"] is None else f"{p['psnr_db']:.2f}"
        print(f"| {p['acquired_s']:.1f} | {p['photons']} | {p['run_s']:.1f} | {psnr} | "
              f"{'yes' if p['acquired_s'] in during else 'no'} |")
    print(f"\n{len(during)} reconstructions shown during the run")


if __name__ == "__main__":
    main()
