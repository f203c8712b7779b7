"""Speed of ``animegraph studio`` in headless Chromium: page ready, click to play, fps.

Usage::

    python scripts/bench_studio.py [--db PATH] [--loads 5] [--clicks 8] [--json OUT]

Starts ``animegraph studio --port 0 --no-browser`` on the database (default: the demo's,
``animegraph demo`` builds it) and drives Debian's chromium (``/usr/bin/chromium``) with
Playwright, WebGL through SwiftShader (software, as on a machine without a GPU). Prints:

* **page ready**: from the navigation's start to the page's ready mark (overview,
  mesh, clip table filled, the face drawn: ``window.studio.readyAt``), over ``--loads``
  fresh pages;
* **click to play**: from the click on a clip's row to the first frame drawn playing it
  (``window.studio.lastPlay``), over ``--clicks`` different clips (none is cached: the
  server deforms each clip when asked), and the part of it until the clip's vertices
  arrived. The page asks for a clip's vertices when the pointer comes onto its row (a
  hand's move to click gives it a head start of a few hundred milliseconds): the script
  empties that cache between the pointer's arrival and the click, so every click here
  is cold;
* **playback fps**: display frames a second while a clip plays, from the page's
  ``requestAnimationFrame`` timestamps (``window.studio.face.frameTimes``), with the
  page's own work per frame (vertices, normals, draw: ``face.workTimes``); and the rate
  of an empty ``requestAnimationFrame`` loop in the same browser (the ceiling there).

Targets: ready <= 1 s, play <= 300 ms, 60 fps. The machine's load average is printed:
the figures are of a shared machine.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--use-gl=swiftshader", "--enable-unsafe-swiftshader",
        "--autoplay-policy=no-user-gesture-required"]
EMPTY_LOOP = """() => new Promise(done => { const t = [];
  const f = now => { t.push(now); if (t.length < 180) requestAnimationFrame(f); else done(t); };
  requestAnimationFrame(f); })"""


def start(db: Path) -> tuple[subprocess.Popen, str]:
    log = Path(os.environ.get("TMPDIR", "/tmp")) / f"bench-studio-{os.getpid()}.log"
    proc = subprocess.Popen([sys.executable, "-m", "animegraph", "studio", "--db", str(db),
                             "--port", "0", "--no-browser"], stdout=log.open("w"),
                            stderr=subprocess.STDOUT, env={**os.environ,
                                                           "PYTHONUNBUFFERED": "1"})
    deadline = time.monotonic() + 120
    while not (url := re.search(r"http://\S+\?token=\S+", log.read_text())):
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            sys.exit(f"the studio did not start: {log.read_text()}")
        time.sleep(0.1)
    return proc, url.group(0)


def wait_until(page, expression: str, bound_s: float = 120.0):
    """Poll ``expression`` in the page until truthy (Playwright's ``wait_for_function``
    evaluates a string, which the page's content policy forbids)."""
    deadline = time.monotonic() + bound_s
    while not (value := page.evaluate(expression)):
        if time.monotonic() > deadline:
            sys.exit(f"gave up waiting for {expression}")
        page.wait_for_timeout(10)
    return value


def fps(stamps: list[float]) -> float:
    return 1000.0 * (len(stamps) - 1) / (stamps[-1] - stamps[0])


def main() -> None:
    from playwright.sync_api import sync_playwright

    from animegraph.apps.cache import default_database

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--db", type=Path, default=None)
    parser.add_argument("--loads", type=int, default=5)
    parser.add_argument("--clicks", type=int, default=8)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    db = args.db or default_database()[0]
    proc, url = start(db)
    out: dict = {"db": str(db), "load_average_before": os.getloadavg()}
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path="/usr/bin/chromium", args=ARGS)
            ready = []
            for _ in range(args.loads):
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                page.goto(url)
                wait_until(page, "document.body.dataset.ready === '1'")
                ready.append(page.evaluate("window.studio.readyAt"))
                page.close()
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            page.goto(url)
            wait_until(page, "document.body.dataset.ready === '1'")
            page.click("nav button[data-tab=clips]")
            latency, fetch, rates, work = [], [], [], []
            for k in range(args.clicks):
                row = f"#clip-table tbody tr:nth-child({1 + 7 * k})"
                page.hover(row)
                page.evaluate("window.studio.faces.clear()")  # a cold click: no head start
                page.click(row)
                wait_until(page, "window.studio.lastPlay && window.studio.lastPlay.started "
                           "&& window.studio.lastPlay.clicked > (window._last || 0)")
                play = page.evaluate("window._last = window.studio.lastPlay.clicked, "
                                     "window.studio.lastPlay")
                latency.append(play["started"] - play["clicked"])
                fetch.append(play["fetched"] - play["clicked"])
                wait_until(page, "!window.studio.face.playing")
                stamps = page.evaluate("window.studio.face.frameTimes")
                rates.append(fps(stamps))
                work += page.evaluate("window.studio.face.workTimes")
            empty = fps(page.evaluate(EMPTY_LOOP))
            renderer = page.evaluate("""(() => { const gl = document.createElement('canvas')
                .getContext('webgl2'); const d = gl.getExtension('WEBGL_debug_renderer_info');
                return d ? gl.getParameter(d.UNMASKED_RENDERER_WEBGL) : ''; })()""")
            browser.close()
    finally:
        proc.terminate()
        proc.wait()
    out.update({
        "ready_ms": ready, "click_to_play_ms": latency, "click_to_vertices_ms": fetch,
        "playback_fps": rates,
        "work_ms_per_frame_median": statistics.median(work) if work else None,
        "empty_raf_fps": empty, "webgl": renderer, "load_average_after": os.getloadavg(),
    })
    print(f"database: {db}; WebGL: {renderer}")
    print(f"load average before {out['load_average_before'][0]:.1f}, after "
          f"{out['load_average_after'][0]:.1f} ({os.cpu_count()} cores)")
    print(f"page ready:     median {statistics.median(ready):.0f} ms, range "
          f"{min(ready):.0f}-{max(ready):.0f} ms over {len(ready)} loads (target <= 1000)")
    print(f"click to play:  median {statistics.median(latency):.0f} ms, range "
          f"{min(latency):.0f}-{max(latency):.0f} ms over {len(latency)} clips (target <= 300); "
          f"of which the clip's vertices arrived after {statistics.median(fetch):.0f} ms "
          "(median: the server reads and deforms the clip)")
    print(f"playback:       median {statistics.median(rates):.1f} fps, range "
          f"{min(rates):.1f}-{max(rates):.1f} (target 60); page work "
          f"{out['work_ms_per_frame_median']:.1f} ms a frame (median); an empty "
          f"requestAnimationFrame loop runs at {empty:.1f} fps in this browser")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
