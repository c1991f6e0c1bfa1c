"""The app's viewing modes for photo sets (``web/src/relightModes.ts``: diffuse gain, specular
enhancement, normal unsharp masking, several lights), checked under Node against slow per-pixel
references and the properties each mode must have (``tests/js/check_relight_modes.mjs``).

The TypeScript module is compiled to plain JavaScript with the web client's own esbuild (Vite's,
in ``web/node_modules``: ``make web`` installs it). Where Node or esbuild is missing the checks
skip, saying so, or fail when ``CI`` is set."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from helpers.readers import JS, require

ROOT = Path(__file__).resolve().parents[1]
ESBUILD = ROOT / "web" / "node_modules" / ".bin" / "esbuild"
CHECKS = [
    "each mode matches the reference",
    "the masked blur matches the reference at every radius",
    "unsharp masking of a flat normal field is the identity",
    "unsharp masking with no amount is the identity, and more amount bends the ripples further",
    "specular enhancement peaks where the reflected light meets the viewer",
    "specular enhancement is grey, whatever the albedo",
    "two equal lights at the same place give twice one light, in every mode",
    "diffuse gain of 1 is the default shading, and more gain darkens only where the light leaves the normal",
    "nothing is drawn off the object, and no mode makes NaN",
    "saved settings are read back clamped, and junk falls back to the defaults",
]


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    node = shutil.which("node")
    require(node is not None, "node not installed: cannot run the viewing modes' checks")
    require(ESBUILD.exists(), "esbuild not installed: run `npm ci --prefix web` (make web)")
    compiled = tmp_path_factory.mktemp("relight") / "relightModes.mjs"
    build = subprocess.run(
        [
            str(ESBUILD),
            str(ROOT / "web" / "src" / "relightModes.ts"),
            "--format=esm",
            f"--outfile={compiled}",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert build.returncode == 0, build.stderr
    done = subprocess.run(
        [node, str(JS / "check_relight_modes.mjs"), str(compiled)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_every_check_ran(results):
    assert sorted(results) == sorted(CHECKS)


@pytest.mark.parametrize("check", CHECKS)
def test_viewing_mode(results, check):
    assert results[check] is None, results[check]
