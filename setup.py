"""Package build hook: build the browser client into the package when it is not built yet.

All the metadata is in ``pyproject.toml``; this file only adds one step to ``build_py``. The
client (TypeScript + three.js in ``web/``) is built by Vite into ``src/shadeform/app/static/``,
which ``shadeform app`` serves and which ships as package data, so a user never runs npm by
hand. ``make web`` does the same during development (and rebuilds when a source changes).
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
WEB = ROOT / "web"
STATIC = ROOT / "src" / "shadeform" / "app" / "static"


class BuildPyWithClient(build_py):
    """``build_py`` that first builds the web client if ``static/`` has none and npm is here."""

    def run(self):
        # before super().run(): the package data (static/**) is listed when first asked for;
        # an editable install (`make venv`) serves src/ as it is, where `make web` builds
        if not (STATIC / "index.html").is_file() and not getattr(self, "editable_mode", False):
            npm = shutil.which("npm")
            if npm is None or not (WEB / "package.json").is_file():
                self.warn(
                    "the web client is not built and npm (or web/) is missing: the package will "
                    "work, but `shadeform app` will ask for the client to be built (`make web`)"
                )
            else:
                subprocess.run([npm, "ci", "--no-audit", "--no-fund"], cwd=WEB, check=True)
                subprocess.run([npm, "run", "build"], cwd=WEB, check=True)
        super().run()


setup(cmdclass={"build_py": BuildPyWithClient})
