"""Speed of the browser app: from a parameter change to the updated 3D view, in a real browser.

Starts ``shadeform app`` (the real command, ``--port 0``) on a 512x512 synthetic vase written as
an 8-bit PNG, drives Debian's Chromium (``/usr/bin/chromium``, headless) with Playwright, and
makes 20 changes of each kind of parameter at mesh step 2. Each change is timed inside the page,
from the control's change event to the end of the first frame drawn with the new mesh
(``window.shadeform.timeline()``): to the first model drawn (a new solve shows a quick look
solved at the mesh's grid first) and to the full-resolution one, split into where its time went:

- server: the server's own ``timings["total"]`` (solve, mesh, base64 encoding);
- wire: the rest of the request's round trip (HTTP on loopback, JSON text, ``response.json()``);
- decode: base64 to typed arrays;
- draw: building the three.js geometry and drawing the frame (headless Chromium renders WebGL
  in software, SwiftShader, on this machine's CPU cores: a GPU draws it far faster).

Run with ``make web`` first, then ``.venv/bin/python benchmarks/bench_app.py``. Prints a Markdown
table of medians and writes it to ``benchmarks/results/app.md``.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from PIL import Image

from shadeform import synth

CHROMIUM = "/usr/bin/chromium"
BUDGET_MS = 200

#: (what changes, JavaScript run once before, JavaScript that makes the i-th change through the
#: panel's controls); the rows run in this order, each from the state the one before left
CHANGES = [
    ("step 2 → 3 → 2 … (re-mesh, solve reused)", "", "setSlider('step', i % 2 ? 3 : 2)"),
    (
        "gaussian σ 0.5 … 10, light +z: auto = eikonal (new solve)",
        "setSelect('filter-kind', 'gaussian')",
        "setSlider('filter-size', 0.5 + 0.5 * i)",
    ),
    (
        "light tilt at slant 30°, propagation, refine 0: the 2002 field (new solve)",
        "setSelect('filter-kind', 'none'); setSelect('solver', 'propagation'); setSlider('refine', 0); "
        "document.querySelector('#light-mode [data-mode=slant_tilt]').click(); setSlider('slant', 30)",
        "setSlider('tilt', -60 + 3 * i)",
    ),
    (
        "light tilt at slant 30°, propagation, refine 3 (new solve)",
        "setSlider('refine', 3)",
        "setSlider('tilt', 3 * i)",
    ),
    (
        "light tilt at slant 30°, auto = oblique (new solve)",
        "setSelect('solver', 'auto')",
        "setSlider('tilt', 90 + 3 * i)",
    ),
]

# a release of the slider: the value is set and a 'change' event sent, as a mouse-up does
PAGE_HELPERS = """() => {
  window.setSlider = (id, value) => {
    const input = document.getElementById(id);
    input.value = String(value);
    input.dispatchEvent(new Event('change'));
  };
  window.setSelect = (id, value) => {
    const select = document.getElementById(id);
    select.value = value;
    select.dispatchEvent(new Event('change'));
  };
}"""


@contextmanager
def running_app(image: Path, *, stop_within: float = 20.0) -> Iterator[str]:
    """``shadeform app IMAGE`` in its own process for the ``with`` block: its URL. Stopped as the
    user stops it (Ctrl+C, SIGINT), killed if it has not ended within ``stop_within`` seconds."""
    command = [
        str(Path(sys.executable).with_name("shadeform")),
        "app",
        str(image),
        "--no-browser",
        "--port",
        "0",
    ]
    server = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 120
        seen = []
        url = None
        while url is None and time.monotonic() < deadline:
            line = server.stdout.readline()
            if not line and server.poll() is not None:
                break
            seen.append(line)
            found = re.search(r"http://127\.0\.0\.1:\d+/", line)
            url = found.group(0) if found else None
        if url is None:
            raise SystemExit("shadeform app did not start:\n" + "".join(seen))
        yield url
    finally:
        server.send_signal(signal.SIGINT)
        try:
            server.wait(timeout=stop_within)
        except subprocess.TimeoutExpired:
            server.kill()


def measure(page, script: str, runs: int) -> list[dict]:
    """Make ``runs`` changes one after another; the page's timeline of each."""
    timelines = []
    for i in range(runs):
        before = page.evaluate("window.shadeform.applied()")
        page.evaluate(f"(i) => {{ {script}; }}", i)
        # wait for the full-resolution model (a quick look may be drawn before it)
        page.wait_for_function(
            f"window.shadeform.applied() > {before} && !window.shadeform.state().busy", timeout=120_000
        )
        timeline = page.evaluate("window.shadeform.timeline()")
        timeline["cached"] = bool(page.evaluate("window.shadeform.lastResult().info.cached"))
        timelines.append(timeline)
    return timelines


def summarise(timelines: list[dict]) -> dict[str, float]:
    def median(values):
        return statistics.median(values)

    first = [t["firstRendered"] - t["changed"] for t in timelines]
    total = [t["rendered"] - t["changed"] for t in timelines]
    server = [1000 * t["serverTimings"].get("total", 0.0) for t in timelines]
    trip = [t["received"] - t["sent"] for t in timelines]
    return {
        "first": median(first),
        "first_p90": float(np.percentile(first, 90)),
        "total": median(total),
        "p90": float(np.percentile(total, 90)),
        "server": median(server),
        "wire": median([r - s for r, s in zip(trip, server)]),
        "decode": median([t["decoded"] - t["received"] for t in timelines]),
        "draw": median([t["rendered"] - t["decoded"] for t in timelines]),
        "cached": sum(t["cached"] for t in timelines),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "app.md")
    args = parser.parse_args(argv)
    if not Path(CHROMIUM).is_file():
        raise SystemExit(f"{CHROMIUM} is not installed (Debian package chromium); it runs the benchmark")
    from playwright.sync_api import sync_playwright

    folder = Path(tempfile.mkdtemp())
    image = folder / f"vase{args.size}.png"
    scene = synth.scene("vase", size=args.size)
    Image.fromarray(np.round(scene.image * 255).astype(np.uint8)).save(image)
    load_before = os.getloadavg()[0]  # other work on the machine slows both sides: say so
    rows = []
    with running_app(image, stop_within=10) as url, sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True, args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1440, "height": 860})
        page.goto(url)
        page.evaluate("window.shadeform.ready")
        page.evaluate(PAGE_HELPERS)
        page.wait_for_function("window.shadeform.applied() >= 1", timeout=300_000)
        page.evaluate("setSlider('step', 2)")
        page.wait_for_function("!window.shadeform.state().busy", timeout=120_000)
        measure(
            page, "setSlider('step', i % 2 ? 2 : 3)", 2
        )  # warm-up (ends at step 2): first geometry uploads
        result = page.evaluate("window.shadeform.lastResult()")
        stages: dict[str, list[float]] = {}
        for name, setup, script in CHANGES:
            if setup:
                page.evaluate(f"() => {{ {setup}; }}")
                page.wait_for_timeout(200)
                page.wait_for_function("!window.shadeform.state().busy", timeout=120_000)
            timelines = measure(page, script, args.runs)
            summary = summarise(timelines)
            for timeline in timelines:
                if not timeline["cached"] and "eikonal" in name:
                    for stage, seconds in timeline["serverTimings"].items():
                        stages.setdefault(stage, []).append(1000 * seconds)
            rows.append(
                f"| {name} | **{summary['first']:.0f}** | {summary['first_p90']:.0f} | "
                f"{summary['total']:.0f} | {summary['p90']:.0f} | {summary['server']:.0f} | "
                f"{summary['wire']:.0f} | {summary['decode']:.1f} | {summary['draw']:.0f} | "
                f"{summary['cached']}/{args.runs} |"
            )
            print(rows[-1], file=sys.stderr)
        chromium_version = browser.version
        browser.close()

    load_after = os.getloadavg()[0]
    header = (
        f"`shadeform app` on a synthetic vase {args.size}x{args.size} (8-bit PNG upload, automatic mask), "
        f"step 2: {result['vertex_count']:,} vertices / "
        f"{result['triangle_count']:,} triangles on screen. Median of {args.runs} changes each, timed in the "
        f"page from the control's change event to the end of the first frame drawn with the new mesh: the "
        f"quick look solved at the mesh's grid (`reconstruct_preview`) that a new solve shows first, and the "
        f"full-resolution model that replaces it (server, wire, decode and draw columns are the full one's). "
        f"Headless Chromium {chromium_version} (WebGL in software: SwiftShader), server and browser on the same "
        f"{os.cpu_count()} cores (1-minute load average {load_before:.1f} before the run, {load_after:.1f} after: "
        f"other work on the machine counts in); Python "
        f"{platform.python_version()}. Budget: {BUDGET_MS} ms.\n\n"
        "| change | median ms, change → view updated | p90 ms | median ms, → full-resolution view | p90 ms | "
        "server ms | wire ms | decode ms | draw ms | solve reused |\n"
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    )
    breakdown = (
        "\n\nWhere a new full-resolution solve's server time goes with the default method at +z (median ms "
        "over the eikonal changes that solved anew; "
        "`total` is the server's whole handling):\n\n"
        "| " + " | ".join(stages) + " |\n|" + "---:|" * len(stages) + "\n"
        "| " + " | ".join(f"{statistics.median(values):.0f}" for values in stages.values()) + " |"
    )
    table = header + "\n" + "\n".join(rows) + breakdown + "\n"
    print(table)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
