"""Fixtures shared by the test modules."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from helpers import ROOT, SHARED_DATA
from shadeform import integration, solvers, synth


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data``: the real photos and normals with ground truth."""
    return SHARED_DATA


@pytest.fixture(scope="session")
def real_data():
    """``benchmarks/real_data.py`` (the real photos of ``../shared/data/real`` as cases); skips,
    saying why, where that folder is absent."""
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location("real_data", ROOT / "benchmarks" / "real_data.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("real_data", module)  # its dataclass looks itself up there
    spec.loader.exec_module(module)
    if not module.available():
        pytest.skip(f"no real photographs at {module.DATA}")
    return module


@pytest.fixture
def cli():
    """Run the ``shadeform`` command in-process: ``cli("reconstruct", path, "-o", out)``.

    A wide console, whatever the terminal running the tests, so tables are not wrapped."""
    from shadeform.cli import app

    def invoke(*args):
        return CliRunner(env={"COLUMNS": "200"}).invoke(app, [str(arg) for arg in args])

    return invoke


@pytest.fixture
def out(tmp_path) -> Path:
    """An empty output folder."""
    folder = tmp_path / "out"
    folder.mkdir()
    return folder


@pytest.fixture
def registries():
    """The solver and integrator registries, restored after the test: register freely in it."""
    with solvers.SOLVERS.restored(), integration.INTEGRATORS.restored():
        yield solvers, integration


@pytest.fixture(scope="session")
def sphere64():
    """The synthetic sphere, 64 x 64, light +z: image, mask, normals, depth."""
    return synth.scene("sphere", size=64)


@pytest.fixture
def app_server(tmp_path):
    """The app's real server with a session store, on a port it can be stopped and started on
    again (``helpers.browser.RestartableServer``)."""
    from helpers.browser import RestartableServer, require_built_client
    from shadeform.app.server import create_app

    require_built_client()
    controlled = RestartableServer()
    controlled.start(lambda: create_app(sessions=tmp_path / "s.sqlite3", warm=True))
    yield controlled
    controlled.stop()
