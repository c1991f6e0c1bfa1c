"""The app's real server and Chromium, for the browser tests (``tests/test_app_browser*.py``).

The server is :func:`shadeform.app.server.create_app` under uvicorn, in a thread, on a free
loopback port, serving the client built into ``src/shadeform/app/static/`` (``make web``);
Playwright drives Debian's Chromium (``/usr/bin/chromium``) as a person would. Without Chromium
the tests skip, saying so; when ``CI`` is set they fail instead. A test module takes the fixtures
by naming them at its top (``server, browser, page = ui.server, ui.browser, ui.page``, with
``from helpers import browser as ui``); one whose server is :class:`RestartableServer` (the
``app_server`` fixture of ``tests/conftest.py``) defines its own ``server`` fixture.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from helpers.readers import require

CHROMIUM = Path("/usr/bin/chromium")
ARTIFACTS = Path(__file__).resolve().parents[1] / "artifacts"
# a cold start compiles the numba kernels (up to a minute on 2 cores); warm solves take < 1 s
FIRST_RESULT_MS = 180_000
RESULT_MS = 60_000

# the synthetic bowl at its default size (256 px)
BOWL = "synth:bowl"


# ---------------------------------------------------------------------------- fixtures


def require_built_client() -> None:
    """Fail, saying what to run, where the web client is not built."""
    from shadeform.app.server import STATIC_DIR

    if not (STATIC_DIR / "index.html").is_file():
        pytest.fail(f"the web client is not built ({STATIC_DIR} has no index.html): run `make web`")


@contextmanager
def serving(app) -> Iterator[str]:
    """``app`` under uvicorn, in a thread, on a free loopback port; yields its address."""
    import uvicorn

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    uvicorn_server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=uvicorn_server.run, name="app-under-test", daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not uvicorn_server.started:
        assert thread.is_alive() and time.monotonic() < deadline, "the app server did not start"
        time.sleep(0.05)
    yield f"http://127.0.0.1:{port}/"
    uvicorn_server.should_exit = True
    thread.join(timeout=10)


@pytest.fixture(scope="module")
def server():
    """The app's real server on a free loopback port; yields its address."""
    from shadeform.app.server import create_app

    require_built_client()
    with serving(create_app(warm=True)) as url:
        yield url


@pytest.fixture(scope="module")
def browser():
    """Debian's Chromium, headless, driven by Playwright (skips, or fails on CI, without it)."""
    require(
        CHROMIUM.is_file(),
        f"{CHROMIUM} not installed (Debian package chromium): cannot run the browser tests",
    )
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(
            executable_path=str(CHROMIUM), headless=True, args=["--no-sandbox"]
        )
        yield chromium
        chromium.close()


@pytest.fixture
def page(browser, server):
    """A fresh browser profile (empty storage) on the app's page, ready to use."""
    with opened(browser, server, accept_downloads=True) as fresh:
        yield fresh


@contextmanager
def opened(browser, url: str, *, init_script: str | None = None, **options) -> Iterator:
    """A fresh browser profile (empty storage, ``options`` for its context) on the app's page at
    ``url``, ready to use (``init_script`` run before the page's own); an uncaught error in the
    page fails the test when it is closed."""
    context = browser.new_context(viewport={"width": 1440, "height": 860}, **options)
    if init_script is not None:
        context.add_init_script(init_script)
    page = context.new_page()
    errors = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.goto(url)
    page.evaluate("window.shadeform.ready")
    yield page
    context.close()
    assert not errors, f"uncaught errors in the page: {errors}"


class RestartableServer:
    """The app's real server on one fixed loopback port, which can be stopped and started again."""

    def __init__(self) -> None:
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            self.port = probe.getsockname()[1]
        self.url = f"http://127.0.0.1:{self.port}/"
        self._server = None
        self._thread: threading.Thread | None = None

    def start(self, make_app: Callable) -> None:
        import uvicorn

        config = uvicorn.Config(make_app(), host="127.0.0.1", port=self.port, log_level="warning")
        self._server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self._server.run, name="app-under-test", daemon=True)
        self._thread.start()
        deadline = time.monotonic() + 30
        while not self._server.started:
            assert self._thread.is_alive(), f"the app server did not start on port {self.port}"
            assert time.monotonic() < deadline, "the app server did not start within 30 s"
            time.sleep(0.05)

    def stop(self) -> None:
        if self._server is None:
            return
        self._server.should_exit = True
        self._thread.join(timeout=15)
        assert not self._thread.is_alive(), "the app server did not stop"
        self._server = None
        # nothing answers on the port any more: a request now fails at the network level
        with socket.socket() as probe, pytest.raises(ConnectionRefusedError):
            probe.connect(("127.0.0.1", self.port))


# ----------------------------------------------------------------------------- helpers


def applied(page) -> int:
    return page.evaluate("window.shadeform.applied()")


def wait_for_result(page, after: int, timeout=RESULT_MS) -> None:
    """Wait until a result newer than the ``after``-th is on screen and nothing is pending."""
    page.wait_for_function(
        f"window.shadeform.applied() > {after} && !window.shadeform.state().busy", timeout=timeout
    )
    # nothing pending means the full-resolution model, not the quick look, is on screen
    assert page.evaluate("window.shadeform.lastResult().preview") is False


def open_example(page, name: str) -> None:
    before = applied(page)
    page.click("#examples-menu > button")
    page.click(f'#examples-menu [data-example="{name}"]')
    wait_for_result(page, before, timeout=FIRST_RESULT_MS)
    assert page.evaluate("window.shadeform.state().image.name") == name
    # the mask the result was solved with is decoded in the mask worker, beside the model's frame
    page.wait_for_function("window.shadeform.mask().pixels > 0", timeout=RESULT_MS)


def click_image(page, x: float, y: float) -> None:
    """Click image pixel (x = column, y = row) on the image pane's canvas."""
    at = page.evaluate(f"window.shadeform.pagePoint({x}, {y})")
    page.mouse.click(at["x"], at["y"])


def download(page, selector: str, menu: str, folder: Path) -> Path:
    """Open ``menu``, click ``selector`` in it and save the download it starts under ``folder``."""
    page.click(f"{menu} > button")
    with page.expect_download(timeout=RESULT_MS) as started:
        page.click(selector)
    done = started.value
    assert done.failure() is None, done.failure()
    target = folder / done.suggested_filename
    done.save_as(target)
    return target


def toast_texts(page, kind: str) -> list[str]:
    return [t["text"] for t in page.evaluate("window.shadeform.toasts()") if t["kind"] == kind]


def record_requests(page) -> list[tuple[str, str]]:
    """(method, path) of every request the page makes from now on, sent or refused."""
    log: list[tuple[str, str]] = []
    page.on("request", lambda request: log.append((request.method, request.url.split("/", 3)[-1])))
    return log
