"""The independent readers the exported meshes are checked with: Open Inventor's own
``ivinfo``/``ivcat`` for ``.iv``, three.js's ``VRMLLoader`` under Node (``tests/js/check_vrml.mjs``)
for ``.wrl``. Where one is missing a test skips, saying so, or fails when ``CI`` is set."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

JS = Path(__file__).resolve().parents[1] / "js"
IVINFO_MISSING = "ivinfo/ivcat not installed (Debian package inventor-clients)"
ON_CI = os.environ.get("CI", "").lower() not in ("", "0", "false")


def require(available: bool, reason: str) -> None:
    """Skip with ``reason`` locally; fail on CI, where every reader must be installed."""
    if available:
        return
    if ON_CI:
        pytest.fail(f"{reason} (required when CI is set)")
    pytest.skip(reason)


# ---------------------------------------------------------------- Open Inventor (ivinfo, ivcat)


def run_tool(*args):
    return subprocess.run(args, capture_output=True, text=True, timeout=60)


def inventor_numbers(text, node, field):
    """Numbers of ``node { field [ ... ] }`` in ivcat's normalised output."""
    found = re.search(rf"\b{node}\s*\{{[^}}]*?\b{field}\s*\[([^\]]*)\]", text)
    assert found, f"ivcat output has no {node} {field}"
    return np.array(found.group(1).replace(",", " ").split(), dtype=float)


def check_inventor(path, mesh):
    require(shutil.which("ivinfo") is not None, IVINFO_MISSING)
    info = run_tool("ivinfo", str(path))
    assert info.returncode == 0, info.stdout + info.stderr
    # Separator, ShapeHints, Material, Coordinate3, Normal, NormalBinding,
    # [TextureCoordinate2, TextureCoordinateBinding,] IndexedFaceSet
    nodes = 9 if mesh.uv is not None else 7
    assert f"number of nodes under root is {nodes}" in info.stdout

    cat = run_tool("ivcat", str(path))
    assert cat.returncode == 0 and cat.stdout.startswith("#Inventor V2.1 ascii"), cat.stderr
    text = cat.stdout
    assert re.search(r"vertexOrdering\s+COUNTERCLOCKWISE", text)
    assert re.search(r"NormalBinding\s*\{\s*value\s+PER_VERTEX_INDEXED", text)
    points = inventor_numbers(text, "Coordinate3", "point").reshape(-1, 3)
    vectors = inventor_numbers(text, "Normal", "vector").reshape(-1, 3)
    index = inventor_numbers(text, "IndexedFaceSet", "coordIndex").astype(int).reshape(-1, 4)
    normal_index = re.search(r"normalIndex\s*\[([^\]]*)\]", text).group(1)
    assert len(points) == mesh.n_vertices and len(vectors) == mesh.n_vertices
    assert len(index) == mesh.n_faces
    assert (index[:, 3] == -1).all()
    np.testing.assert_array_equal(index[:, :3], mesh.faces)
    assert normal_index.replace(",", " ").split() == [str(i) for i in index.ravel()]
    np.testing.assert_allclose(points, mesh.vertices, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(vectors, mesh.normals, atol=1e-5)
    if mesh.uv is not None:
        uv = inventor_numbers(text, "TextureCoordinate2", "point").reshape(-1, 2)
        np.testing.assert_allclose(uv, mesh.uv, atol=1e-6)


# --------------------------------------------------------------------- VRML (three.js, Node)


def run_vrml_loader(path):
    node = shutil.which("node")
    require(node is not None, "node not installed: cannot run three.js's VRMLLoader")
    require(
        (JS / "node_modules" / "three").is_dir(),
        "three.js not installed: run `npm ci --prefix tests/js`",
    )
    return subprocess.run(
        [node, str(JS / "check_vrml.mjs"), str(path)], capture_output=True, text=True, timeout=60
    )


def check_vrml(path, mesh):
    done = run_vrml_loader(path)
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout)
    assert found["meshes"] == 1
    assert found["faces"] == mesh.n_faces
    assert found["vertices"] == mesh.n_vertices
    assert found["normals"] is True
    assert found["uv"] is (mesh.uv is not None)
    assert found["frontFacing"] == mesh.n_faces  # counter-clockwise seen from +z
    np.testing.assert_allclose(found["min"], mesh.vertices.min(axis=0), atol=1e-4)
    np.testing.assert_allclose(found["max"], mesh.vertices.max(axis=0), atol=1e-4)
