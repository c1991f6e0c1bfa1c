"""Take the app's pictures for the docs (``docs/app.png``, ``docs/app-photo-set.png``,
``docs/app-views.png``) in headless Chromium.

Opens the coin photo in a running ``shadeform app`` (its light estimated from the photo, the
example's own settings), turns the 3D view a little and saves the window; or, given a folder of
photos (DiLiGenT's layout: the photos, ``light_directions.txt``, ``light_intensities.txt``,
``mask.png``), opens them as a photo set and drags the light to the upper left; or, given a
shipped view set (``views:lumpy``), opens it in the Views panel and turns the fused model to
show a side and its top, each view's partial model in its colour. ``make web`` first, then::

    .venv/bin/shadeform app --no-browser --port 8765 &
    .venv/bin/python web/screenshot.py http://127.0.0.1:8765/ docs/app.png
    .venv/bin/python web/screenshot.py http://127.0.0.1:8765/ docs/app-photo-set.png ../shared/data/real/diligent/cat
    .venv/bin/python web/screenshot.py http://127.0.0.1:8765/ docs/app-views.png views:lumpy
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from playwright.sync_api import Page, sync_playwright


@contextmanager
def app_page(url: str) -> Iterator[Page]:
    """The app open in a 1440 x 860 window, its last session restored."""
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(
            executable_path="/usr/bin/chromium", headless=True, args=["--no-sandbox"]
        )
        page = browser.new_page(viewport={"width": 1440, "height": 860}, device_scale_factor=1)
        page.goto(url)
        page.evaluate("window.shadeform.ready")
        yield page
        browser.close()


def turn_and_save(page: Page, out: str, keys: tuple[str, ...]) -> None:
    """Turn the 3D view by the keys given, move the mouse out of the way and save the window."""
    page.click("#view-host canvas")
    for key in keys:
        page.keyboard.press(key)
    page.mouse.move(5, 300)  # no hover highlight in the picture
    page.wait_for_timeout(500)
    page.screenshot(path=out)


def main(url: str, out: str) -> None:
    with app_page(url) as page:
        page.click("#examples-menu > button")
        page.click('[data-example="coin"]')
        page.wait_for_function(
            "window.shadeform.applied() >= 1 && !window.shadeform.state().busy", timeout=300_000
        )
        page.click('#tools [data-tool="select"]')
        turn_and_save(page, out, ("ArrowLeft", "ArrowUp", "ArrowUp"))


def photo_set(url: str, out: str, folder: str) -> None:
    files = sorted(
        str(p) for p in Path(folder).iterdir() if p.suffix in (".png", ".txt") and p.stem != "filenames"
    )
    with app_page(url) as page:
        page.set_input_files("#file-photos", files)
        page.wait_for_function(
            "window.shadeform.stereo.applied() >= 1 || window.shadeform.stereo.error() !== null",
            timeout=300_000,
        )
        assert page.evaluate("window.shadeform.stereo.error()") is None, page.evaluate(
            "window.shadeform.stereo.error()"
        )
        info = page.evaluate("window.shadeform.stereo.info()")
        start = page.evaluate(
            f"window.shadeform.stereo.pagePoint({info['height'] // 2}, {info['width'] // 2})"
        )
        end = page.evaluate(f"window.shadeform.stereo.pagePoint({info['height'] // 5}, {info['width'] // 4})")
        page.mouse.move(start["x"], start["y"])
        page.mouse.down()
        page.mouse.move(end["x"], end["y"], steps=8)
        page.mouse.up()
        turn_and_save(page, out, ("ArrowLeft", "ArrowUp"))


def view_set(url: str, out: str, name: str) -> None:
    with app_page(url) as page:
        page.click("#examples-menu > button")
        page.click(f'[data-view-set="{name}"]')
        page.wait_for_function(
            "window.shadeform.views.applied() >= 1 || window.shadeform.views.error() !== null",
            timeout=300_000,
        )
        assert page.evaluate("window.shadeform.views.error()") is None, page.evaluate(
            "window.shadeform.views.error()"
        )
        # a third of a turn between two views, tilted to show the top no view saw (closed by the hull)
        turn_and_save(page, out, ("ArrowLeft",) * 3 + ("ArrowUp",) * 5)


if __name__ == "__main__":
    if len(sys.argv) > 3 and sys.argv[3].startswith("views:"):
        view_set(*sys.argv[1:4])
    elif len(sys.argv) > 3:
        photo_set(*sys.argv[1:4])
    else:
        main(*sys.argv[1:3])
