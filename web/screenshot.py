"""Take the app's picture for the docs (``docs/app.png``) in headless Chromium.

Opens the synthetic bowl in a running ``shadeform app``, draws a concave region over it with the
mouse, turns the 3D view a little and saves the window. ``make web`` first, then::

    .venv/bin/shadeform app --no-browser --port 8765 &
    .venv/bin/python web/screenshot.py http://127.0.0.1:8765/ docs/app.png
"""

from __future__ import annotations

import math
import sys

from playwright.sync_api import sync_playwright


def main(url: str, out: str) -> None:
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path="/usr/bin/chromium", headless=True, args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1440, "height": 860}, device_scale_factor=1)
        page.goto(url)
        page.evaluate("window.shadeform.ready")
        page.click("#examples-menu > button")
        page.click('[data-example="synth:bowl"]')
        page.wait_for_function("window.shadeform.applied() >= 1 && !window.shadeform.state().busy", timeout=300_000)
        done = page.evaluate("window.shadeform.applied()")
        page.click('#tools [data-tool="polygon"]')
        for i in range(10):
            angle = 2 * math.pi * i / 10
            at = page.evaluate(f"window.shadeform.pagePoint({128 + 88 * math.cos(angle)}, {128 + 88 * math.sin(angle)})")
            page.mouse.click(at["x"], at["y"])
        page.keyboard.press("Enter")
        page.wait_for_function(f"window.shadeform.applied() > {done} && !window.shadeform.state().busy", timeout=120_000)
        page.click("#view-host canvas")
        for key in ("ArrowLeft", "ArrowLeft", "ArrowUp", "ArrowUp"):
            page.keyboard.press(key)
        page.click('#tools [data-tool="select"]')
        page.mouse.move(5, 300)  # no hover highlight in the picture
        page.wait_for_timeout(500)
        page.screenshot(path=out)
        browser.close()


if __name__ == "__main__":
    main(*sys.argv[1:3])
