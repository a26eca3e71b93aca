"""The live view's cost to the acquisition: sustained rate of the unpaced
mock (400 M photons a run by default) without `--live` and with it, with
nothing connected, with an event stream read by a plain client, with the
page open in headless Chromium (Debian's package, through playwright),
and with that browser open on a blank page beside the view; one run of
each in turn, RUNS rounds. The browser only shows the page, as a lab's
would: no script polls it.

    PYTHONPATH=target/pydeps python3 scripts/bench_live.py [RUNS] [PHOTONS] [SET-UPS]

Prints each round's rates (photons / elapsed seconds from
acquisition.json) and each set-up's median, in M photons/s.
"""
import json
import socket
import statistics
import subprocess
import sys
import tempfile
import threading

from playwright.sync_api import sync_playwright

RUNS = int(sys.argv[1]) if len(sys.argv) > 1 else 5
PHOTONS = sys.argv[2] if len(sys.argv) > 2 else "400000000"
# Only these set-ups (off, none, events, page, blank), comma-separated.
ONLY = sys.argv[3].split(",") if len(sys.argv) > 3 else []
CLI = "target/release/scatterscope"
ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]
ALL_SETUPS = {
    "without the view": None,
    "view, nothing connected": "none",
    "view, one event stream read": "events",
    "view, Chromium on the page": "page",
    "view, Chromium on a blank page": "blank",
}


def read_events(url):
    host, port = url.removeprefix("http://").split("/")[0].split(":")
    with socket.create_connection((host, int(port))) as s:
        s.sendall(b"GET /events HTTP/1.1\r\nHost: x\r\n\r\n")
        while s.recv(65536):
            pass


def run(out, view, browser):
    cmd = [CLI, "acquire", "--size", "32", "--fov", "6cm", "--unpaced", "--mock-replay", "16",
           "--max-photons", PHOTONS, "--duration", "0", "--out", out]
    if view is not None:
        cmd += ["--live"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    page = None
    if view is not None:
        url = proc.stdout.readline().strip().removeprefix("live view: ")
        if view == "events":
            threading.Thread(target=read_events, args=(url,), daemon=True).start()
        elif view in ("page", "blank"):
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(url if view == "page" else "about:blank")
    proc.stdout.read()
    proc.wait()
    if page is not None:
        page.close()
    record = json.load(open(f"{out}/acquisition.json"))
    return record["ledger"]["photons"] / record["elapsed_s"] / 1e6


SETUPS = {k: v for k, v in ALL_SETUPS.items() if not ONLY or v in ONLY or (v is None and "off" in ONLY)}
rates = {name: [] for name in SETUPS}
with sync_playwright() as p, tempfile.TemporaryDirectory() as tmp:
    browser = p.chromium.launch(executable_path="/usr/bin/chromium", args=ARGS)
    for i in range(RUNS):
        for n, (name, view) in enumerate(SETUPS.items()):
            rates[name].append(run(f"{tmp}/{i}-{n}", view, browser))
        print(f"round {i + 1}: " + ", ".join(f"{r[-1]:.1f}" for r in rates.values()), flush=True)
    browser.close()
for name, r in rates.items():
    print(f"{name}: {', '.join(f'{x:.1f}' for x in r)}; median {statistics.median(r):.1f} M photons/s")
