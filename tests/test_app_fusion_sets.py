"""Tests of the app's views that are photo sets (``FuseView.photo_set_id``, shadeform.app.fusion)
with FastAPI's TestClient.

Each view's photo set is written as a user has it (``helpers.photosets.write_photo_set``: 16-bit
photos under six lights and their light file) and uploaded as the photo-set mode uploads it.
The server's fused model must be the one ``shadeform fuse`` makes of the same folders, closed,
every outline kept; a set view is solved once by photometric stereo (the photo-set mode's cache)
and never again for settling; a set and a single photo fuse together; and a set the server
does not have, or concave regions drawn on one, end in a 4xx of one line.
"""

from __future__ import annotations

import base64
import io
import json
from functools import partial

import numpy as np
import pytest
import trimesh
from fastapi.testclient import TestClient
from PIL import Image

from helpers import app
from helpers.photosets import write_photo_set
from shadeform import synth

LOCAL = "http://127.0.0.1:8000"
NAME, SIZE, ANGLES = "waisted", 128, (0.0, 90.0)
RESOLUTION = 2.0


@pytest.fixture(scope="module")
def client():
    from shadeform.app.server import create_app

    with TestClient(create_app(), base_url=LOCAL) as test_client:
        yield test_client


@pytest.fixture(scope="module")
def rendered():
    """The object's views at ``ANGLES`` (``synth.render_views``)."""
    return synth.render_views(NAME, ANGLES, size=SIZE)


@pytest.fixture(scope="module")
def folders(rendered, tmp_path_factory):
    """Each view as a photo set's folder under six lights."""
    root = tmp_path_factory.mktemp("sets")
    out = []
    for view in rendered:
        out.append(root / f"view{int(view.angle):03d}")
        write_photo_set(out[-1], np.nan_to_num(view.normals), view.mask)
    return out


@pytest.fixture(scope="module")
def set_ids(client, folders) -> list[str]:
    """Each folder uploaded as the photo-set mode uploads it: its photos and light file."""
    ids = []
    for folder in folders:
        parts = [("photos", (p.name, p.read_bytes(), "image/png")) for p in sorted(folder.glob("*.png"))]
        lights = folder / "light_directions.txt"
        parts.append(("lights", (lights.name, lights.read_bytes(), "text/plain")))
        response = client.post("/api/photosets", files=parts)
        assert response.status_code == 201, response.text
        ids.append(response.json()["photoset_id"])
    return ids


def set_view(photoset_id: str, angle: float) -> dict:
    return {"photo_set_id": photoset_id, "angle": angle}


fuse = partial(app.fuse, resolution=RESOLUTION)
fused = partial(app.fused, resolution=RESOLUTION)


def vertices(mesh: dict) -> np.ndarray:
    return app.mesh_arrays(mesh)[0]


def faces(mesh: dict) -> np.ndarray:
    return app.mesh_arrays(mesh)[1]


def png(values: np.ndarray, bits: int = 8) -> bytes:
    buffer = io.BytesIO()
    top = 65535 if bits == 16 else 255
    data = np.rint(np.clip(values, 0, 1) * top).astype(np.uint16 if bits == 16 else np.uint8)
    Image.fromarray(data).save(buffer, format="PNG")
    return buffer.getvalue()


def one_line_error(response, status: int) -> str:
    assert response.status_code == status, response.text
    detail = response.json()["detail"]
    assert isinstance(detail, str) and "\n" not in detail and "Traceback" not in detail
    return detail


def test_two_photo_set_views_fuse_as_the_cli_fuses_their_folders(client, set_ids, folders, cli, tmp_path):
    result = fused(client, [set_view(i, a) for i, a in zip(set_ids, ANGLES)])
    assert (
        result["watertight"]
        and trimesh.Trimesh(vertices(result["mesh"]), faces(result["mesh"])).is_watertight
    )
    outlines = [view["outline_iou"] for view in result["views"]]
    assert min(outlines) >= 0.95, outlines
    # nothing to settle in a set: its photometric stereo tells convex from concave
    assert [view["settled"] for view in result["views"]] == [[], []]
    assert [view["cached"] for view in result["views"]] == [False, False]
    # the very model `shadeform fuse` makes of the same folders
    model = tmp_path / "model.ply"
    out = cli("fuse", *folders, "--angles", "0,90", "--resolution", RESOLUTION, "-o", model, "--json")
    assert out.exit_code == 0, out.output
    report = json.loads(out.stdout)
    np.testing.assert_allclose(outlines, report["outline_iou"], atol=1e-9)
    mine = trimesh.load(model)
    assert result["mesh"]["vertex_count"] == len(mine.vertices)
    np.testing.assert_allclose(
        np.sort(vertices(result["mesh"]), axis=0), np.sort(mine.vertices, axis=0), atol=1e-3
    )
    assert result["volume"] == pytest.approx(report["mesh"]["volume"], rel=1e-6)
    # the photo-set mode's solve and cache: the stereo result of view 1 is the one fused
    stereo = client.post("/api/stereo", json={"photoset_id": set_ids[0]}).json()
    assert stereo["info"]["cached"] is True and result["views"][0]["mask_png"] == stereo["mask_png"]


def test_a_set_view_is_solved_once(client, set_ids, monkeypatch):
    import shadeform.photometric as photometric

    fused(client, [set_view(i, a) for i, a in zip(set_ids, ANGLES)])
    calls = []
    solve = photometric.reconstruct_stereo
    monkeypatch.setattr(photometric, "reconstruct_stereo", lambda *a, **k: calls.append(1) or solve(*a, **k))
    # another angle: fused anew, each set's stereo reused
    again = fused(client, [set_view(set_ids[0], 0.0), set_view(set_ids[1], 92.0)])
    assert again["info"]["cached"] is False and [v["cached"] for v in again["views"]] == [True, True]
    assert calls == []
    # another model: solved again (the set's own settings, as /api/stereo takes them)
    view = {**set_view(set_ids[1], 90.0), "stereo": {"model": "least_squares"}}
    changed = fused(client, [set_view(set_ids[0], 0.0), view])
    assert [v["cached"] for v in changed["views"]] == [True, False] and calls == [1]


def test_a_set_and_a_single_photo_fuse_together(client, set_ids, rendered):
    side = rendered[1]
    upload = client.post("/api/images", files={"file": ("side.png", png(side.image, 16), "image/png")})
    assert upload.status_code == 201, upload.text
    mask = base64.b64encode(png(side.mask.astype(float))).decode("ascii")
    photo = {
        "image_id": upload.json()["image_id"],
        "angle": 90.0,
        "params": {"mask": mask, "light": {"mode": "z"}},
    }
    result = fused(client, [set_view(set_ids[0], 0.0), photo])
    assert result["watertight"]
    assert min(view["outline_iou"] for view in result["views"]) >= 0.95
    assert len(result["parts"]) == 2 and all(part["vertex_count"] > 100 for part in result["parts"])
    # the photo's own light, the set's mean light
    assert result["views"][1]["light"] == [0.0, 0.0, 1.0]
    assert result["views"][0]["light"] != [0.0, 0.0, 1.0]


def test_bad_set_views_get_one_line(client, set_ids):
    good = set_view(set_ids[0], 0.0)
    detail = one_line_error(fuse(client, [good, set_view("nope", 90.0)]), 404)
    assert detail.startswith("view 2: unknown photo set 'nope'")
    both = {**set_view(set_ids[1], 90.0), "image_id": "x"}
    assert "exactly one of them" in one_line_error(fuse(client, [good, both]), 422)
    assert "exactly one of them" in one_line_error(fuse(client, [good, {"angle": 90.0}]), 422)
    # regions drawn on a set: refused, as the CLI refuses them
    regions = {"regions": [{"polygon": [[1, 1], [9, 1], [9, 9]], "axis": "x"}]}
    drawn = {**set_view(set_ids[1], 90.0), "params": {"concave": regions}}
    detail = one_line_error(fuse(client, [good, drawn]), 422)
    assert detail.startswith("view 2 (") and "photo set" in detail and "concave regions" in detail
    # the set's own settings the server refuses: said with the view's number
    wrong = {**set_view(set_ids[1], 90.0), "stereo": {"model": "nope"}}
    assert one_line_error(fuse(client, [good, wrong]), 422).startswith("view 2 (")
