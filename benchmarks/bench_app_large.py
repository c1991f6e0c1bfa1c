"""The app with a phone-size photo: first view, full resolution, and the page's longest task.

Starts ``shadeform app`` (the real command, ``--port 0``), drives Debian's Chromium (headless,
``/usr/bin/chromium``) with Playwright, and uploads a 12 Mpx photo (4000x3000 8-bit PNG: the
synthetic vase rendered at 1000 px and resized) through the Open image input, ``--runs`` times,
each in a fresh page, after one warm-up upload (the kernels and the solver process loaded). Timed
in the page from the file input's change event:

- first view: the first model drawn (the quick look, solved on the photo downsampled);
- full resolution: the full solve (in the background, with progress) drawn in its place;
- longest task: ``PerformanceObserver({type: 'longtask'})`` over the whole run, from the file
  chosen to the full model drawn and turned a little with the mouse (the page's own start-up is
  reported apart). ``OBSERVE`` is the observer, run before the page's scripts; the browser tests
  (``tests/test_app_browser_large.py``) import it and ``phone_photo`` from here.

One more upload is cancelled two seconds into its full solve: how long the server took to end it,
and whether the page then takes a new setting (a new quick look) at once. Prints a Markdown table
and writes it to ``benchmarks/results/app-large.md``; screenshots go to ``--shots``.

Run with ``make web`` first, then ``.venv/bin/python benchmarks/bench_app_large.py``.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).parent))
from bench_app import CHROMIUM, running_app
from shadeform import synth

FIRST_VIEW_BAR_MS = 1000

#: What the traces said about the long tasks left (printed with the table).
LONG_TASKS_NOTE = "Where the long tasks went (Chromium traces of the same flow, Playwright's tracing with the V8 sampler): at the issue's last figure (257 ms) they were the commits of the 3D view's frames, where the page waited for the GPU process to draw the canvas and read it back (GLES2::ReadPixels in LayerTreeHost::DoUpdateLayers; WebGL in software, SwiftShader, on the same 2 cores): 210-290 ms for each frame of the 273k-vertex model, the first and every frame of an orbit. The view is now drawn in a render worker on an OffscreenCanvas (web/src/renderWorker.ts), so those waits are the worker's. Also moved off the page's thread: the 12 Mpx photo's small copy (createImageBitmap's resize runs where its promise resolves: 500 ms on the page; now in web/src/pictureWorker.ts), the copy of the mesh the renderer takes (made in the mesh worker), the mask's layer (shown as the mask worker's bitmap, no longer drawn into a canvas), and the app's start-up split in two tasks. What is left on the page's thread is style, layout, paint and the image pane's 2D canvas, 20-45 ms a task on this machine under load. The intermittent 60-360 ms tasks seen in about 1 flow in 4 during the full solve (traced: 7-22 ms of thread time in 50-220 ms of wall time, the rest the page's thread waiting for a core, and once an 83 ms paint) were frames of the busy bar's sweep, which animated left: the page was restyled, laid out and painted at every frame (about 900 main-thread paints a flow); it now moves by transform, on the compositor. The benchmark's wait for the full result polls every 100 ms (Playwright's default polls at every animation frame, which also drew a frame each 16 ms). The page's start-up (traced the same way, CDP's profiler for the lines): its longest tasks were the bundle's first task (46-50 ms median at a load of 2-3: three.js's renderer and shaders evaluated at load for the fallback drawing on the page, now in a chunk only a browser without OffscreenCanvas loads: 25 ms), the first result's (the page's first toLocaleString set up number formatting, 12-25 ms: now set up by the mesh worker, for the whole renderer process, before the first result), the app's build (its first read of localStorage, 1-20 ms: now a task of its own while the options are fetched), and, left, the first style and layout of the whole page (25-50 ms under load) and the opening of the first image (its requests and the image pane, 25-45 ms under load). Since (traced again, thread and wall time): the app is built in three tasks (13 ms of thread time in one before), the image pane takes its size from its ResizeObserver (no style and layout forced while an image opens), the unsure areas' tags are drawn once into sprites (3-5 ms a frame), and the results with a mesh are fetched by the mesh worker (the page read the full result's bytes, 10-29 ms of thread time a chunk). Every page task is then at most about 16 ms of thread time; under a load of 2-8 its wall time runs 3-7 times that, the first style and layout (12-17 ms of thread time) the largest.\n"
LONG_TASK_BAR_MS = 50

#: The page's long tasks from its first script on, and when the file input changed (run before the
#: page's scripts: ``context.add_init_script``); tests/test_app_browser_large.py uses it too.
OBSERVE = """
window.__longTasks = [];
new PerformanceObserver((list) => {
  for (const entry of list.getEntries()) window.__longTasks.push({ start: entry.startTime, ms: entry.duration });
}).observe({ type: 'longtask', buffered: true });
document.addEventListener('change', (event) => {
  if (event.target && event.target.id === 'file-image') window.__fileChosen = performance.now();
}, true);
"""


def phone_photo(path: Path, width: int = 4000, height: int = 3000) -> None:
    """The synthetic vase at 1000 px, resized to ``width`` x ``height`` (centre crop), 8-bit sRGB."""
    scene = synth.scene("vase", size=1000)
    image = Image.fromarray(np.rint(np.clip(scene.image, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8))
    side = max(width, height)
    big = image.resize((side, side), Image.Resampling.BILINEAR)
    left, top = (side - width) // 2, (side - height) // 2
    big.crop((left, top, left + width, top + height)).save(path, compress_level=1)


def run_once(browser, url: str, photo: Path, *, cancel_after: float | None = None, shots: Path | None = None):
    context = browser.new_context(viewport={"width": 1440, "height": 860})
    context.add_init_script(OBSERVE)
    page = context.new_page()
    page.goto(url)
    # the page starts untouched: the harness's first script in it (Playwright's own world, 8-10 ms
    # of thread time, traced at 35-56 ms of wall time in the start's burst) is not the page's
    time.sleep(2)
    page.evaluate("window.shadeform.ready")
    # the image the server was started with is solved first; then the page is idle
    page.wait_for_function(
        "window.shadeform.applied() >= 1 && !window.shadeform.state().busy", timeout=120_000, polling=100
    )
    page.wait_for_timeout(1000)
    before = page.evaluate("window.shadeform.applied()")
    page.set_input_files("#file-image", str(photo))
    page.wait_for_function(f"window.shadeform.applied() > {before}", timeout=120_000, polling=100)
    quick = page.evaluate("window.shadeform.timeline()")
    chosen = page.evaluate("window.__fileChosen")
    row = {"first": quick["firstRendered"] - chosen, "quick_server": quick["serverTimings"]}
    if cancel_after is not None:
        page.wait_for_function("window.shadeform.solveProgress().shown", timeout=60_000)
        page.wait_for_timeout(1000 * cancel_after)
        if shots:
            page.screenshot(path=str(shots / "app-large-progress.png"))
        job = page.evaluate("window.shadeform.solveProgress().job")
        started = time.perf_counter()
        page.click("#solve-cancel")
        while (
            page.evaluate(f"fetch('/api/solves/{job}').then((r) => r.json()).then((j) => j.state)")
            == "running"
        ):
            time.sleep(0.01)
        row["cancel"] = 1000 * (time.perf_counter() - started)
        page.wait_for_function("window.shadeform.modelState().status === 'stale'", timeout=10_000)
        if shots:
            page.screenshot(path=str(shots / "app-large-cancelled.png"))
        # a new setting: its quick look
        applied = page.evaluate("window.shadeform.applied()")
        page.evaluate("window.__changed = performance.now()")
        page.evaluate(
            "() => { const s = document.getElementById('refine'); s.value = '2'; s.dispatchEvent(new Event('change')); }"
        )
        page.wait_for_function(f"window.shadeform.applied() > {applied}", timeout=60_000)
        row["after_cancel"] = page.evaluate("window.shadeform.timeline().firstRendered - window.__changed")
        page.click("#solve-cancel")
    else:
        # the full solve's end is asked of the server from here, not polled in the page: the
        # harness's polls there are tasks of the page's thread (Playwright's injected script: 5-9
        # ms of thread time, stretched to 50-100 ms of wall time while the solver takes the
        # cores, traced), which the observer counts as the page's. Then the timeline, the page's
        # record of a result drawn (the full result is applied a frame before the render worker
        # has drawn it), polled every 100 ms, not at every animation frame (Playwright's default)
        page.wait_for_function("window.shadeform.solveProgress().job !== null", timeout=60_000, polling=100)
        wait_for_job(url, page.evaluate("window.shadeform.solveProgress().job"))
        page.wait_for_function(
            "window.shadeform.state().image.width === 4000 && !window.shadeform.lastResult().preview"
            " && window.shadeform.timeline() && !window.shadeform.timeline().preview",
            timeout=600_000,
            polling=100,
        )
        full = page.evaluate("window.shadeform.timeline()")
        row["full"] = full["rendered"] - chosen
        row["full_server"] = full["serverTimings"]
        row["vertices"] = page.evaluate("window.shadeform.lastResult().vertex_count")
        page.wait_for_timeout(1000)  # the mask arrives after the model: its tasks count too
        orbit(page)
    tasks = page.evaluate("window.__longTasks")
    row["longest"] = max((t["ms"] for t in tasks if t["start"] + t["ms"] > chosen), default=0.0)
    row["startup"] = max((t["ms"] for t in tasks if t["start"] + t["ms"] <= chosen), default=0.0)
    context.close()
    # the page's processes and workers wound down before the next page starts: started at once,
    # 4 of 20 fresh pages had a 50-75 ms task in their first 100 ms, 1 of 20 after a pause of 2 s
    time.sleep(2)
    return row


def wait_for_job(url: str, job: str, timeout: float = 600.0) -> None:
    """Until the server's background solve ``job`` is no longer running (``GET /api/solves/{job}``)."""
    import json
    import urllib.request

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with urllib.request.urlopen(f"{url.rstrip('/')}/api/solves/{job}") as response:
            if json.load(response)["state"] != "running":
                return
        time.sleep(0.1)
    raise TimeoutError(f"solve {job} still running after {timeout:.0f} s")


def orbit(page) -> None:
    """Turn the model a little with the mouse (a drag across the 3D view), and let it draw."""
    box = page.locator("#view-host").bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x, y)
    page.mouse.down()
    page.mouse.move(x + 120, y + 30, steps=8)
    page.mouse.up()
    page.wait_for_timeout(1000)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "app-large.md")
    parser.add_argument("--shots", type=Path, default=Path(tempfile.gettempdir()))
    args = parser.parse_args(argv)
    if not Path(CHROMIUM).is_file():
        raise SystemExit(f"{CHROMIUM} is not installed (Debian package chromium); it runs the benchmark")
    from playwright.sync_api import sync_playwright

    folder = Path(tempfile.mkdtemp())
    photo = folder / "vase-4000x3000.png"
    phone_photo(photo)
    small = folder / "vase-256.png"
    Image.fromarray(np.rint(synth.scene("vase", size=256).image * 255).astype(np.uint8)).save(small)
    load_before = os.getloadavg()[0]
    with running_app(small) as url, sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True, args=["--no-sandbox"])
        warm = run_once(browser, url, photo)  # the kernels and the solver process loaded
        print("warm-up:", {k: v for k, v in warm.items() if "server" not in k}, file=sys.stderr)
        rows = []
        for _ in range(args.runs):
            rows.append(run_once(browser, url, photo))
            print({k: v for k, v in rows[-1].items() if "server" not in k}, file=sys.stderr)
        cancelled = run_once(browser, url, photo, cancel_after=2.0, shots=args.shots)
        print(cancelled, file=sys.stderr)
        version = browser.version
        browser.close()
    load_after = os.getloadavg()[0]

    def stat(key):
        values = [row[key] for row in rows]
        return statistics.median(values), max(values)

    first, full, longest = stat("first"), stat("full"), stat("longest")
    quick_stages = rows[0]["quick_server"]
    full_stages = rows[0]["full_server"]
    table = (
        f"`shadeform app` with a 12 Mpx photo (4000x3000 8-bit PNG, {photo.stat().st_size / 1e6:.1f} MB: the "
        f"synthetic vase rendered at 1000 px and resized) uploaded through Open image; automatic mask, "
        f"step 2. Median and worst of {args.runs} uploads, each in a fresh page after one warm-up upload, "
        f"timed in the page from the file input's change event. Headless Chromium {version} (WebGL in "
        f"software: SwiftShader), server, solver process and browser on the same {os.cpu_count()} cores "
        f"(1-minute load average {load_before:.1f} before, {load_after:.1f} after: other work on the machine "
        f"counts in); Python {platform.python_version()}. At the issue's filing: 24 s per solve, the page "
        f"frozen for 1.9 s.\n\n"
        "| photo | first view ms (median / worst) | full resolution ms (median / worst) | longest task ms, "
        "photo chosen to model turned (median / worst) | full mesh vertices | page start-up's longest task ms |\n"
        "|---|---:|---:|---:|---:|---:|\n"
        f"| 4000x3000 | **{first[0]:.0f}** / {first[1]:.0f} | {full[0]:.0f} / {full[1]:.0f} | "
        f"**{longest[0]:.0f}** / {longest[1]:.0f} | {rows[0]['vertices']:,} | "
        f"{max(row['startup'] for row in rows):.0f} |\n\n"
        f"Bars: first view <= {FIRST_VIEW_BAR_MS} ms, no long task > {LONG_TASK_BAR_MS} ms.\n\n"
        f"Cancel two seconds into the full solve: the server ended it {cancelled['cancel']:.0f} ms after the "
        f"click (the solver process is terminated); a new setting then drew its quick look "
        f"{cancelled['after_cancel']:.0f} ms after the change; longest task of that run "
        f"{cancelled['longest']:.0f} ms.\n\n"
        f"{LONG_TASKS_NOTE}\n"
        "Server seconds of the first run, quick look (on the photo downsampled) and full resolution (in the "
        "solver process; mesh and encode in the server):\n\n"
        "| result | " + " | ".join(full_stages) + " |\n|---|" + "---:|" * len(full_stages) + "\n"
        "| quick look | " + " | ".join(f"{quick_stages.get(k, 0):.2f}" for k in full_stages) + " |\n"
        "| full | " + " | ".join(f"{full_stages[k]:.2f}" for k in full_stages) + " |\n"
    )
    print(table)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
