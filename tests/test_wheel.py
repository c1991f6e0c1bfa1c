"""The wheel carries the built web client: installed into a fresh virtual environment, with no Node
on the PATH, ``shadeform app`` serves the page and its script."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import sysconfig
import time
import zipfile
from pathlib import Path

import httpx
import pytest

ROOT = Path(__file__).resolve().parents[1]
STATIC = ROOT / "src" / "shadeform" / "app" / "static"


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    if not (STATIC / "index.html").is_file():
        pytest.fail(f"the web client is not built ({STATIC} has no index.html): run `make web`")
    source = tmp_path_factory.mktemp("source")
    for name in ("pyproject.toml", "setup.py", "README.md", "MANIFEST.in"):
        shutil.copy(ROOT / name, source / name)
    shutil.copytree(ROOT / "src", source / "src", ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    out = tmp_path_factory.mktemp("wheel")
    done = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(source), "--no-deps", "-w", str(out), "-q"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    (path,) = out.glob("shadeform-*.whl")
    return path


def test_the_wheel_holds_the_client(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    assert "shadeform/app/static/index.html" in names
    assert any(re.fullmatch(r"shadeform/app/static/assets/index-[\w-]+\.js", name) for name in names)


def test_installed_without_node_the_app_serves_the_client(wheel, tmp_path):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    python = venv / "bin" / "python"
    subprocess.run(
        [python, "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)], check=True, timeout=300
    )
    # the dependencies come from this environment's site-packages, appended after the fresh
    # environment's own (a path a .pth adds does not run its own .pth files, so this
    # environment's editable shadeform stays out: the wheel's is the one imported)
    site = subprocess.run(
        [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    (Path(site) / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    env = {"PATH": str(venv / "bin"), "HOME": str(tmp_path), "LANG": "C.UTF-8"}  # no node, no npm
    assert shutil.which("node", path=env["PATH"]) is None and shutil.which("npm", path=env["PATH"]) is None
    where = subprocess.run(
        [python, "-c", "import shadeform.app.server as s; print(s.__file__)"],
        capture_output=True, text=True, env=env, check=True,
    ).stdout  # fmt: skip
    assert where.startswith(str(venv)), where
    app = subprocess.Popen(
        [venv / "bin" / "shadeform", "app", "--no-browser", "--port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        line = app.stdout.readline()  # "shadeform app at http://127.0.0.1:PORT/  (Ctrl+C stops it)"
        found = re.search(r"http://127\.0\.0\.1:\d+/", line)
        assert found, (line, app.stderr.read() if app.poll() is not None else "")
        url = found.group(0)
        deadline = time.monotonic() + 60
        while True:
            try:
                page = httpx.get(url, timeout=10)
                break
            except httpx.TransportError:
                assert time.monotonic() < deadline and app.poll() is None, "the app did not answer"
                time.sleep(0.2)
        assert page.status_code == 200 and "<html" in page.text.lower()
        script = re.search(r'src="\.?/(assets/index-[\w-]+\.js)"', page.text)
        assert script, page.text[:500]
        code = httpx.get(url + script.group(1), timeout=10)
        assert code.status_code == 200 and "javascript" in code.headers["content-type"]
        assert len(code.content) > 100_000  # the client with three.js, not a stub
        options = httpx.get(url + "api/options", timeout=10)
        assert options.status_code == 200 and "solvers" in options.json()
    finally:
        app.terminate()
        app.wait(timeout=30)
    assert os.path.exists(venv)
