"""Take the app's picture for the docs (``docs/app.png``) in headless Chromium.

Opens the coin photo in a running ``shadeform app`` (its light estimated from the photo, the
example's own settings), turns the 3D view a little and saves the window. ``make web`` first, then::

    .venv/bin/shadeform app --no-browser --port 8765 &
    .venv/bin/python web/screenshot.py http://127.0.0.1:8765/ docs/app.png
"""

from __future__ import annotations

import sys

from playwright.sync_api import sync_playwright


def main(url: str, out: str) -> None:
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(
            executable_path="/usr/bin/chromium", headless=True, args=["--no-sandbox"]
        )
        page = browser.new_page(viewport={"width": 1440, "height": 860}, device_scale_factor=1)
        page.goto(url)
        page.evaluate("window.shadeform.ready")
        page.click("#examples-menu > button")
        page.click('[data-example="coin"]')
        page.wait_for_function(
            "window.shadeform.applied() >= 1 && !window.shadeform.state().busy", timeout=300_000
        )
        page.click("#view-host canvas")
        for key in ("ArrowLeft", "ArrowUp", "ArrowUp"):
            page.keyboard.press(key)
        page.click('#tools [data-tool="select"]')
        page.mouse.move(5, 300)  # no hover highlight in the picture
        page.wait_for_timeout(500)
        page.screenshot(path=out)
        browser.close()


if __name__ == "__main__":
    main(*sys.argv[1:3])
