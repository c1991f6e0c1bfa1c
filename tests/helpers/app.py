"""The app's answers as a test reads them: its meshes decoded, its views fused."""

from __future__ import annotations

import base64

import numpy as np


def mesh_arrays(mesh: dict) -> tuple[np.ndarray, np.ndarray]:
    """A mesh of the app's JSON (base64 little-endian ``positions`` float32, ``indices``
    uint32): its vertices (N, 3) float64 and faces (M, 3)."""
    positions = np.frombuffer(base64.b64decode(mesh["positions"]), "<f4").reshape(-1, 3)
    indices = np.frombuffer(base64.b64decode(mesh["indices"]), "<u4").reshape(-1, 3)
    return positions.astype(np.float64), indices


def fuse(client, views: list[dict], **body):
    """POST ``/api/fuse`` with ``views`` and the rest of the request ``body``: the response."""
    return client.post("/api/fuse", json={"views": views, **body})


def fused(client, views: list[dict], **body) -> dict:
    """The fused result of :func:`fuse`, which must succeed."""
    response = fuse(client, views, **body)
    assert response.status_code == 200, response.text
    return response.json()
