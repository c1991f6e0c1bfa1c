"""End-to-end tests of the app with phone-size photos, in a real browser (headless Chromium).

A 12 Mpx upload (4000x3000, a synthetic vase rendered at 1000 px and resized) must show its first
model quickly (a quick look solved on a downsampled copy), run its full solve in the background
with a progress bar and a Cancel button that stops it and leaves the quick look, and never block
the page: every task the page runs is watched with ``PerformanceObserver({type: 'longtask'})``
from before the page loads. The full-resolution mesh's decoding is checked on a 2.1 Mpx photo
(large enough for the background path and for a full-size view mesh, quick enough to solve
whole here); the 12 Mpx full solve is timed in ``benchmarks/bench_app_large.py``. A photo over
the server's pixel limit is offered a downsample, which opens it.

Timing bars are the benchmark's. This machine is shared (load averages of 3 to 17 while these
tests run), so here the long tasks (from the moment the photo is chosen to the full model turned
with the mouse) and the first view are checked against ceilings a loaded CI machine keeps; what
blocked the page is checked directly: the results are parsed and decoded in the mesh worker, and
the 3D view is drawn in the render worker (its canvas handed over: in software WebGL each frame of
a full-size model held the page 200-300 ms at its commit when drawn on the page's thread).
Screenshots: ``tests/artifacts/app-large-progress.png``, ``app-large-cancelled.png``,
``app-large-fit-offer.png``.
"""

from __future__ import annotations

import io
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from helpers import browser as ui
from helpers.browser import ARTIFACTS, opened, require_built_client, serving

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
# the long-task observer and the photo are the benchmark's: the tests check what it measures
from bench_app_large import OBSERVE, orbit, phone_photo

browser = ui.browser

#: Longest task the page may run once a photo is chosen, ms. The issue's bar, 50 ms, is the
#: benchmark's (``benchmarks/bench_app_large.py``); here the browser shares 2 loaded cores with
#: the solver process and the other tests' work, and style, layout and paint alone then pass
#: 50 ms. 150 ms still fails a frame of the full model committed on the page's thread (200-300 ms
#: in software WebGL, measured before the render worker).
LONG_TASK_MS = 150


# one worker runs the module: its photos and server are made once (15 s)
pytestmark = pytest.mark.xdist_group("browser-large")


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    folder = tmp_path_factory.mktemp("large")
    paths = {"12mpx": folder / "vase-12mpx.png", "2.1mpx": folder / "vase-2.1mpx.png"}
    # the synthetic vase rendered at 1000 px and resized: a phone photo's size in seconds
    phone_photo(paths["12mpx"], 4000, 3000)
    phone_photo(paths["2.1mpx"], 1500, 1420)  # just over LARGE_PIXELS: quick to solve whole
    phone_photo(folder / "vase-14mpx.png", 4300, 3300)  # over the test server's limit
    paths["over"] = folder / "vase-14mpx.png"
    return paths


@pytest.fixture(scope="module")
def server():
    """The real server (uvicorn) with a pixel limit of 13 Mpx: the 12 Mpx photo fits, a 14 Mpx
    one is refused with the offer."""
    from shadeform.app.guard import AppLimits
    from shadeform.app.server import create_app, warm_up

    require_built_client()
    warm_up()  # the kernels loaded before the clock runs (``shadeform app`` warms them at start)
    with serving(create_app(limits=AppLimits(max_pixels=13_000_000, max_image_bytes=2 * 2**30))) as url:
        yield url


@pytest.fixture
def page(browser, server):
    """A fresh page that watches its long tasks from before it loads."""
    with opened(browser, server, init_script=OBSERVE) as fresh:
        yield fresh


def view_in_worker(page) -> bool:
    """Whether the 3D view's canvas was handed to a worker (a canvas whose control went to an
    OffscreenCanvas refuses a context on the page)."""
    return page.evaluate(
        """() => {
          try { document.querySelector('#view-host .viewer-canvas').getContext('webgl2'); return false; }
          catch (err) { return err.name === 'InvalidStateError'; }
        }"""
    )


def longest_task(page) -> float:
    """The longest task since the first photo was chosen (the page's start-up is not the photo's)."""
    tasks = page.evaluate("window.__longTasks.filter((t) => t.start + t.ms > window.__fileChosen)")
    return max((task["ms"] for task in tasks), default=0.0)


def progress(page) -> dict:
    return page.evaluate("window.shadeform.solveProgress()")


def open_photo(page, path) -> None:
    page.set_input_files("#file-image", str(path))


def wait_quick_look(page, after: int = 0) -> dict:
    page.wait_for_function(f"window.shadeform.applied() > {after}", timeout=60_000)
    return page.evaluate("window.shadeform.lastResult()")


def startup_tasks(page) -> list:
    """The page's long tasks from its first script to ready, and the first frames after it."""
    page.wait_for_timeout(300)
    return page.evaluate("window.__longTasks")


def test_start_up_runs_no_long_task_and_leaves_the_renderer_to_the_worker(page, browser, server):
    """The page's start-up (its first script to ready) stays under the ceiling, and its own bundle
    holds no renderer: three.js's WebGLRenderer and its shaders (their ``#include <...>`` chunks)
    are the render worker's, and in a chunk that only a browser without OffscreenCanvas loads
    (their evaluation was a third of the page's first task); the mesh worker sets up number
    formatting before the page's first result needs it.

    A task over the ceiling must come back in a second fresh page to fail: work moved back onto
    the page's thread (a frame of the renderer's, its bundle evaluated there) does so in every
    page, while a task stretched by the other tests' work on the shared cores does not (one such
    task, 184 ms, in 1 of 5 local runs of the suite under ``-n 2``)."""
    startup = startup_tasks(page)
    if max((task["ms"] for task in startup), default=0.0) > LONG_TASK_MS:
        context = browser.new_context(viewport={"width": 1440, "height": 860})
        context.add_init_script(OBSERVE)
        again = context.new_page()
        again.goto(server)
        again.evaluate("window.shadeform.ready")
        second = startup_tasks(again)
        context.close()
        assert max((task["ms"] for task in second), default=0.0) <= LONG_TASK_MS, (startup, second)
    assert view_in_worker(page)
    entry = page.evaluate("document.querySelector('script[type=module]').src")
    main_js = page.evaluate("(url) => fetch(url).then((r) => r.text())", entry)
    # three.js's core is there (it registers __THREE__: the camera's maths, OrbitControls), not its renderer
    assert "__THREE__" in main_js and "#include <" not in main_js
    worker_js = page.evaluate(
        "() => fetch(performance.getEntriesByType('resource').map((e) => e.name)"
        ".find((name) => /renderWorker-[^/]*\\.js$/.test(name))).then((r) => r.text())"
    )
    assert "#include <" in worker_js  # the marker is the renderer's: the worker has it
    loaded = page.evaluate("performance.getEntriesByType('resource').map((e) => e.name)")
    assert not any("renderScene" in name for name in loaded), loaded
    # the page's first number formatted for its locale (a mesh's counts) set up ICU's number
    # formatting on the page, 11-18 ms: the mesh worker does it first, for the whole renderer
    # process. A bundler drops the call if its result goes unused: it must be in the worker's bundle
    mesh_worker = re.search(r"meshWorker-[\w-]+\.js", main_js)
    assert mesh_worker, "the mesh worker's script is not named in the page's bundle"
    mesh_js = page.evaluate("(url) => fetch(url).then((r) => r.text())", "assets/" + mesh_worker.group(0))
    assert "toLocaleString()" in mesh_js


def test_12mpx_photo_quick_look_progress_cancel(page, photos):
    open_photo(page, photos["12mpx"])
    quick = wait_quick_look(page)
    # the quick look: solved on the photo downsampled, its mesh in the photo's pixels
    assert quick["preview"] and quick["info"]["level"] >= 2
    assert quick["vertex_count"] > 1000 and quick["decodedInWorker"]
    mesh = page.evaluate("window.shadeform.mesh().positions")
    xs, ys = mesh[0::3], mesh[1::3]
    assert min(xs) >= 0 and max(xs) < 4000 and min(ys) > -3000 and max(ys) <= 0
    assert max(xs) - min(xs) > 1500  # the vase spans the photo, not the level
    # how soon it comes is the benchmark's (benchmarks/results/app-large.md): a loaded machine
    # took 4.8 s here, and a test must not fail on load
    # the full solve runs in the background: a progress bar with its stage and Cancel
    page.wait_for_function("window.shadeform.solveProgress().shown", timeout=30_000)
    shown = progress(page)
    assert shown["job"] and shown["cancellable"] and shown["text"].startswith("Full resolution")
    assert page.is_visible("#solve-bar") and page.is_visible("#solve-cancel")
    assert page.evaluate("window.shadeform.state().model") == "computing"
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "app-large-progress.png"))
    # Cancel: the job ends at once, the quick look stays, said to be one
    job = shown["job"]
    page.click("#solve-cancel")
    page.wait_for_function("!window.shadeform.solveProgress().cancellable", timeout=5000)
    status = page.evaluate(f"fetch('/api/solves/{job}').then((r) => r.json())")
    assert status["state"] == "cancelled", status
    assert page.evaluate("window.shadeform.lastResult().preview")
    assert page.is_visible("#solve-again") and "cancelled" in page.inner_text("#solve-progress")
    page.wait_for_function("window.shadeform.modelState().status === 'stale'", timeout=5000)
    assert "quick look" in page.evaluate("window.shadeform.modelState().message")
    page.screenshot(path=str(ARTIFACTS / "app-large-cancelled.png"))
    # the page is usable: a new setting gives a new quick look at once, and a new background solve
    applied = page.evaluate("window.shadeform.applied()")
    page.evaluate(
        "() => { const s = document.getElementById('refine'); s.value = '2'; s.dispatchEvent(new Event('change')); }"
    )
    wait_quick_look(page, applied)
    page.wait_for_function(
        f"window.shadeform.solveProgress().shown && window.shadeform.solveProgress().job !== '{job}'",
        timeout=30_000,
    )
    second = progress(page)["job"]
    page.click("#solve-cancel")
    page.wait_for_function("!window.shadeform.solveProgress().cancellable", timeout=5000)
    status = page.evaluate(f"fetch('/api/solves/{second}').then((r) => r.json())")
    assert status["state"] == "cancelled"
    # never a long task: uploading, the quick looks, the progress, the cancels
    assert longest_task(page) <= LONG_TASK_MS, page.evaluate("window.__longTasks")


def test_full_resolution_replaces_the_quick_look_without_long_tasks(page, photos):
    open_photo(page, photos["2.1mpx"])
    quick = wait_quick_look(page)
    assert quick["preview"] and quick["info"]["level"] >= 2
    page.wait_for_function(
        "window.shadeform.lastResult() && !window.shadeform.lastResult().preview", timeout=120_000
    )
    full = page.evaluate("window.shadeform.lastResult()")
    # the full result: the photo's own mask, a mesh sized for the screen (the server's budget)
    assert not full["preview"] and "level" not in full["info"] and full["decodedInWorker"]
    assert 100_000 < full["vertex_count"] <= 300_000
    assert full["vertex_count"] > 5 * quick["vertex_count"]
    # the photo's mask, read in the mask worker, shown on the image
    page.wait_for_function("window.shadeform.mask().pixels > 500000", timeout=10_000)
    assert page.evaluate("window.shadeform.state().model") == "current"
    assert not page.is_visible("#solve-progress")
    # drawn in the render worker, turned by the mouse on the page
    assert view_in_worker(page)
    front = page.evaluate("window.shadeform.cameraOffset()")
    orbit(page)
    assert page.evaluate("window.shadeform.cameraOffset()") != front
    assert longest_task(page) <= LONG_TASK_MS, page.evaluate("window.__longTasks")


def test_photo_over_the_limit_is_offered_a_downsample(page, photos):
    open_photo(page, photos["over"])
    page.wait_for_selector("#fit-offer:not([hidden])")
    text = page.inner_text("#fit-offer")
    # in the app's words: its size, the limit, the downsampled size, and the CLI's tiled path
    assert "4300x3300 = 14,190,000 pixels" in text and "13,000,000 (13.0 Mpx)" in text and "2150x1650" in text
    assert "shadeform reconstruct" in text and "--tiles auto" in text
    assert "max_pixels" not in text
    assert page.evaluate("window.shadeform.state().image") is None
    page.screenshot(path=str(ARTIFACTS / "app-large-fit-offer.png"))
    # it stays until acted on; one click opens the photo downsampled, and it is solved
    page.wait_for_timeout(300)
    assert page.is_visible("#fit-offer")
    page.click("#fit-accept")
    quick = wait_quick_look(page)
    image = page.evaluate("window.shadeform.state().image")
    assert (image["width"], image["height"]) == (2150, 1650)
    assert quick["preview"] and not page.is_visible("#fit-offer")
    page.wait_for_function("window.shadeform.solveProgress().shown", timeout=30_000)
    page.click("#solve-cancel")
    assert longest_task(page) <= LONG_TASK_MS, page.evaluate("window.__longTasks")


def test_view_drawn_on_the_page_without_offscreen_canvas(browser, server, tmp_path):
    """A browser that cannot hand a canvas to a worker gets the same renderer on the page, and
    says so once in the console; the model is drawn and turns."""
    context = browser.new_context(viewport={"width": 1440, "height": 860})
    context.add_init_script("delete HTMLCanvasElement.prototype.transferControlToOffscreen;")
    page = context.new_page()
    errors, warnings = [], []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.on("console", lambda message: message.type == "warning" and warnings.append(message.text))
    try:
        page.goto(server)
        page.evaluate("window.shadeform.ready")
        photo = tmp_path / "vase-300.png"
        phone_photo(photo, 300, 300)
        open_photo(page, photo)
        wait_quick_look(page)
        page.wait_for_function("window.shadeform.lastResult() && !window.shadeform.lastResult().preview")
        assert not view_in_worker(page)
        assert sum("cannot draw the 3D view in a worker" in text for text in warnings) == 1, warnings
        front = page.evaluate("window.shadeform.cameraOffset()")
        orbit(page)
        assert page.evaluate("window.shadeform.cameraOffset()") != front
        # the clay-coloured model, drawn: bright pixels in the view's middle (its background is dark)
        shot = np.asarray(Image.open(io.BytesIO(page.locator("#view-host").screenshot())).convert("L"))
        h, w = shot.shape
        assert (shot[h // 4 : 3 * h // 4, w // 4 : 3 * w // 4] > 120).mean() > 0.05
    finally:
        context.close()
    assert not errors, errors
