"""Opens a live view in headless Chromium (Debian's package, driven by
playwright with the system browser) and reports what the page showed, as
JSON on stdout: whether rates, decay, image and reconstruction appeared and
updated, the reconstructions shown while the run went on, and the ledger
as the page printed it once the run ended; with a
SCREENSHOT path, the page as it ended. With MODE `close`, it only opens the
page, sees it update and closes the browser mid-run.

    python3 browser_check.py URL EXPECT_RECONSTRUCTION(0|1) [MODE] [SCREENSHOT]
"""
import json
import sys
import time

from playwright.sync_api import sync_playwright

url, expect_recon = sys.argv[1], sys.argv[2] == "1"
mode = sys.argv[3] if len(sys.argv) > 3 else "watch"
screenshot = sys.argv[4] if len(sys.argv) > 4 else None
CHROMIUM = "/usr/bin/chromium"
ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]

# How many pixels of a canvas are not blank: a plot that was drawn.
INKED = """id => {
  const c = document.getElementById(id);
  const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  let n = 0;
  for (let i = 3; i < d.length; i += 4) if (d[i] > 0) n++;
  return n;
}"""

report = {}
with sync_playwright() as p:
    browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url)
    page.wait_for_function("window.liveUpdates >= 3 && window.liveState.counters.photons > 0", timeout=60000)
    if mode == "close":
        report["closed_at_s"] = page.evaluate("window.liveState.elapsed_s")
        report["done_when_closed"] = page.evaluate("window.liveState.done")
        browser.close()
        print(json.dumps(report))
        sys.exit(0)
    first = page.evaluate("window.liveState")
    first_updates = page.evaluate("window.liveUpdates")
    # Three more states, however loaded the machine (a 2-core CI runs other
    # tests beside this one).
    page.wait_for_function(
        f"window.liveUpdates >= {first_updates + 3} && window.liveState.elapsed_s > {first['elapsed_s'] + 0.5}",
        timeout=60000)
    second = page.evaluate("window.liveState")
    report["updates"] = page.evaluate("window.liveUpdates") - first_updates
    report["photons_grew"] = second["counters"]["photons"] > first["counters"]["photons"]
    report["decay_grew"] = sum(second["decay"]["counts"]) > sum(first["decay"]["counts"])
    report["image_grew"] = sum(second["image"]["values"]) > sum(first["image"]["values"])
    report["rate_points_grew"] = len(second["rates"]) > len(first["rates"])
    report["inked"] = {c: page.evaluate(INKED, c) for c in ["rates", "decay", "image"]}
    if expect_recon:
        page.wait_for_function("window.liveState.reconstruction !== null", timeout=240000)
        r = page.evaluate("window.liveState.reconstruction")
        report["reconstruction"] = {
            "method": r["method"], "psnr_db": r["psnr_db"], "notes": len(r["notes"]),
            "photons": r["photons"],
        }
        report["inked"]["recon"] = page.evaluate(INKED, "recon")
        report["recon_info"] = page.inner_text("#recon-info")
        # Each reconstruction the page showed while the run went on (by
        # the acquisition time of its snapshot), looked at 5 times a second.
        shown = set()
        while True:
            done, at = page.evaluate(
                "[window.liveState.done, window.liveState.reconstruction && window.liveState.reconstruction.acquired_s]")
            if done:
                break
            if at is not None:
                shown.add(at)
            time.sleep(0.2)
        report["shown_during_run"] = sorted(shown)
    page.wait_for_function("window.liveState.done", timeout=240000)
    if expect_recon:
        # The whole run's reconstruction follows the end.
        page.wait_for_function(
            "window.liveState.trace.length >= 2 && window.liveState.reconstruction.photons === window.liveState.ledger.photons",
            timeout=240000)
        report["trace"] = page.evaluate("window.liveState.trace")
    time.sleep(0.6)
    cells = page.eval_on_selector_all(
        "#ledger td[data-field]", "tds => tds.map(t => [t.dataset.field, t.textContent])")
    report["ledger_on_page"] = {k: v for k, v in cells}
    report["status"] = page.inner_text("#status")
    if screenshot:
        page.screenshot(path=screenshot, full_page=True)
    report["errors"] = errors
    browser.close()
print(json.dumps(report))
