"""Tests for the app's views API (shadeform.app.fusion) with FastAPI's TestClient.

The fused model the server returns is compared with the library's own ``shadeform.fuse`` on the
same reconstructions (vertices, volume, the exported file), each placed partial model must lie
on the fused surface, editing one view's mask must change the model and solve only that view
again, what one photo leaves open must be settled by the others (the waisted object's waist),
and every bad request must end in a 4xx whose body is one line, with no traceback.
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
from scipy.spatial import cKDTree

import shadeform
from helpers import app
from shadeform import synth
from shadeform.examples import VIEW_SET_EXAMPLES, load_view_set_example

LOCAL = "http://127.0.0.1:8000"
SET = "views:lumpy"
# voxels of 3 px: each fusion of the 256-pixel views takes well under a second
RESOLUTION = 3.0


@pytest.fixture(scope="module")
def client():
    from shadeform.app.server import create_app

    with TestClient(create_app(), base_url=LOCAL) as test_client:
        yield test_client


@pytest.fixture(scope="module")
def view_set(client) -> dict:
    response = client.post(f"/api/viewsets/examples/{SET}")
    assert response.status_code == 201, response.text
    return response.json()


@pytest.fixture(scope="module")
def library():
    """The example's views reconstructed as the server does (its suggested settings: light from
    the camera, the true masks, the automatic method) and fused by the library: (recs, mesh)."""
    images, masks, angles, _ = load_view_set_example(SET)
    recs = [
        shadeform.reconstruct(image, mask=mask, light=(0.0, 0.0, 1.0)) for image, mask in zip(images, masks)
    ]
    return recs, shadeform.fuse(list(zip(recs, angles)), resolution=RESOLUTION)


def views_of(view_set: dict) -> list[dict]:
    return [
        {"image_id": image["image_id"], "angle": angle, "params": image["suggested"]}
        for image, angle in zip(view_set["images"], view_set["angles"])
    ]


fuse = partial(app.fuse, resolution=RESOLUTION)
fused = partial(app.fused, resolution=RESOLUTION)


def vertices(mesh: dict) -> np.ndarray:
    return app.mesh_arrays(mesh)[0]


def faces(mesh: dict) -> np.ndarray:
    return app.mesh_arrays(mesh)[1]


def png_base64(mask: np.ndarray) -> str:
    buffer = io.BytesIO()
    Image.fromarray(np.where(mask, 255, 0).astype(np.uint8)).save(buffer, format="PNG")
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def one_line_error(response, status: int) -> str:
    assert response.status_code == status, response.text
    detail = response.json()["detail"]
    assert isinstance(detail, str) and "\n" not in detail and "Traceback" not in detail
    return detail


class TestExampleSet:
    def test_info(self, client, view_set):
        assert view_set["name"] == SET and view_set["angles"] == [0.0, 90.0, 180.0, 270.0]
        images = view_set["images"]
        assert [(i["width"], i["height"], i["channels"]) for i in images] == [(256, 256, 1)] * 4
        assert images[1]["name"] == "lumpy 90°" and images[0]["suggested"]["light"]["mode"] == "z"
        # opened again: the same stored images
        again = client.post(f"/api/viewsets/examples/{SET}").json()
        assert [i["image_id"] for i in again["images"]] == [i["image_id"] for i in images]
        options = client.get("/api/options").json()
        assert [e["name"] for e in options["view_set_examples"]] == list(VIEW_SET_EXAMPLES)

    def test_fused_mesh_is_the_librarys(self, client, view_set, library):
        _, mesh = library
        result = fused(client, views_of(view_set))
        assert result["mesh"]["vertex_count"] == mesh.n_vertices
        assert result["mesh"]["triangle_count"] == mesh.n_faces
        np.testing.assert_allclose(vertices(result["mesh"]), mesh.vertices, atol=1e-3)
        np.testing.assert_array_equal(faces(result["mesh"]), mesh.faces)
        solid = trimesh.Trimesh(mesh.vertices, mesh.faces)
        assert result["volume"] == pytest.approx(solid.volume, rel=1e-9)
        assert result["watertight"] is True and solid.is_watertight
        assert result["mesh"]["uvs"] == ""  # a fused model has no texture coordinates
        assert result["info"]["resolution"] == RESOLUTION and result["axis"] == pytest.approx(127.5, abs=2)
        assert [view["light"] for view in result["views"]] == [[0.0, 0.0, 1.0]] * 4
        assert min(view["outline_iou"] for view in result["views"]) >= 0.95  # every outline kept

    def test_each_partial_model_lies_on_the_fused_surface(self, client, view_set, library):
        recs, _ = library
        result = fused(client, views_of(view_set))
        # the fused surface, sampled about every half pixel (its vertices are a voxel apart)
        surface = trimesh.Trimesh(vertices(result["mesh"]), faces(result["mesh"]))
        samples = cKDTree(trimesh.sample.sample_surface(surface, 400_000, seed=0)[0])
        for part, view, rec in zip(result["parts"], result["views"], recs):
            # light: a coarser grid than the view's own (step 2 -> 4 on 256 px)
            assert part["vertex_count"] == shadeform.to_mesh(rec, step=4).n_vertices
            points = vertices(part)
            distance, _ = samples.query(points)
            assert np.median(distance) < 1.0 and np.percentile(distance, 95) < RESOLUTION
            # the transform given is the one that placed it
            transform = np.array(view["transform"])
            own = shadeform.to_mesh(rec, step=4).vertices
            np.testing.assert_allclose(own @ transform[:3, :3].T + transform[:3, 3], points, atol=1e-3)

    def test_the_same_request_is_fused_once(self, client, view_set):
        first = fused(client, views_of(view_set))
        again = fused(client, views_of(view_set), request_id=7)
        assert again["request_id"] == 7 and again["info"]["cached"] is True
        assert [view["cached"] for view in again["views"]] == [True] * 4
        assert "place" not in again["timings"] and again["mesh"]["positions"] == first["mesh"]["positions"]

    def test_refine_poses_and_its_old_name_refine(self, client, view_set):
        kept = fused(client, views_of(view_set), refine_poses=False)
        assert kept["info"]["refine_poses"] is False and "refine" not in kept["info"]
        # "refine", the old name, is still read (saved projects): the same request, fused once
        old = fused(client, views_of(view_set), refine=False)
        assert old["info"]["refine_poses"] is False and old["info"]["cached"] is True
        assert old["mesh"]["positions"] == kept["mesh"]["positions"]
        both = fuse(client, views_of(view_set), refine_poses=False, refine=True)
        assert both.status_code == 422  # one name or the other, not both

    def test_export_is_the_librarys_file(self, client, view_set, library, tmp_path):
        _, mesh = library
        body = {"views": views_of(view_set), "resolution": RESOLUTION}
        response = client.post("/api/fuse/export?format=obj", json=body)
        assert response.status_code == 200, response.text
        assert response.headers["content-disposition"] == 'attachment; filename="lumpy_0-fused.obj"'
        assert response.content == shadeform.export(mesh, tmp_path / "model.obj").read_bytes()
        glb = client.post("/api/fuse/export?format=.GLB", json=body)
        assert glb.status_code == 200 and glb.content[:4] == b"glTF"


def test_a_rival_placement_is_sent_with_the_model(client, view_set, monkeypatch):
    import dataclasses

    import shadeform.fusion as fusion

    assert fused(client, views_of(view_set))["rivals"] == []  # exact angles: the photos decide
    placed = fusion.place  # the server imports it when it fuses
    rival = fusion.Rival((0.0, 16.5, 0.0, 16.4), 1.06)
    monkeypatch.setattr(
        fusion, "place", lambda *a, **k: dataclasses.replace(placed(*a, **k), rivals=(rival,))
    )
    views = views_of(view_set)
    views[1]["angle"] = 91.0  # another request: not the cached fusion
    assert fused(client, views)["rivals"] == [[0.0, 16.5, 0.0, 16.4]]


def test_editing_one_views_mask_changes_the_model_and_solves_only_that_view(client, view_set):
    views = views_of(view_set)
    before = fused(client, views)
    # view 2 (90 degrees) loses the object's top: every row above 110 is carved off the model
    _, masks, _, _ = load_view_set_example(SET)
    rows = np.arange(256)[:, None]
    views[1]["params"] = {**views[1]["params"], "mask": png_base64(masks[1] & (rows >= 110))}
    after = fused(client, views)
    assert [view["cached"] for view in after["views"]] == [True, False, True, True]
    assert after["info"]["cached"] is False
    assert after["volume"] < 0.8 * before["volume"] and after["watertight"]
    # the other views still show the top the model lost: their outlines are not kept, and it is said
    assert min(view["outline_iou"] for view in after["views"]) < 0.95
    # row 110 is y = -(110 - 127.5) in the object frame
    assert vertices(after["mesh"])[:, 1].max() < 17.5 + RESOLUTION
    assert vertices(before["mesh"])[:, 1].max() > 17.5 + 40
    mask = np.asarray(Image.open(io.BytesIO(base64.b64decode(after["views"][1]["mask_png"])))) > 127
    np.testing.assert_array_equal(mask, masks[1] & (rows >= 110))


def test_bad_requests_get_one_line(client, view_set):
    views = views_of(view_set)
    assert "at least 2" in one_line_error(fuse(client, views[:1]), 422)
    assert "at most 24" in one_line_error(fuse(client, views * 7), 422)
    detail = one_line_error(fuse(client, [views[0], {**views[1], "image_id": "nope"}]), 404)
    assert detail.startswith("view 2: unknown image id")
    small = client.post("/api/examples/synth:sphere?size=64").json()["image_id"]
    detail = one_line_error(fuse(client, [views[0], {"image_id": small, "angle": 90}]), 422)
    assert "view 2 is 64x64 but view 1 is 256x256" in detail
    for angle in ("NaN", "Infinity"):
        text = json.dumps({"views": views}).replace('"angle": 90.0', f'"angle": {angle}')
        response = client.post("/api/fuse", content=text, headers={"content-type": "application/json"})
        assert "views.1.angle" in one_line_error(response, 422)
    assert "resolution" in one_line_error(fuse(client, views, resolution=0), 422)
    # two views that share no volume: the top of one and the bottom of the other
    _, masks, _, _ = load_view_set_example(SET)
    rows = np.arange(256)[:, None]
    top = {**views[0], "params": {**views[0]["params"], "mask": png_base64(masks[0] & (rows < 80))}}
    bottom = {**views[1], "params": {**views[1]["params"], "mask": png_base64(masks[1] & (rows > 170))}}
    assert "share no volume" in one_line_error(fuse(client, [top, bottom]), 422)
    # a view's own settings the library refuses: said with the view's number
    wrong = {**views[0], "params": {**views[0]["params"], "mask": png_base64(np.ones((10, 10), bool))}}
    assert one_line_error(fuse(client, [wrong, views[1]]), 422).startswith("view 1 (lumpy 0°): ")
    assert "unknown export format" in one_line_error(
        client.post("/api/fuse/export?format=.xyz", json={"views": views}), 422
    )
    assert "lumpy" in one_line_error(client.post("/api/viewsets/examples/views:cube"), 404)


def test_the_other_views_settle_what_a_photo_leaves_open(client):
    """The waisted object: the front and back photos read the waist as a hill top (an unsure
    area); the side views' silhouettes show it concave, and the model's volume comes right."""
    views = views_of(client.post("/api/viewsets/examples/views:waisted").json())
    truth = synth.closed_object("waisted", size=256).volume
    alone = fused(client, views, settle=False, resolution=2)
    settled = fused(client, views, resolution=2)
    assert [len(view["settled"]) for view in alone["views"]] == [0, 0, 0, 0]
    assert [len(view["settled"]) > 0 for view in settled["views"]] == [True, False, True, False]
    assert abs(settled["volume"] / truth - 1) < min(0.05, abs(alone["volume"] / truth - 1))
    # kept as the view's own regions: the very reading (solved once already), the same model
    regions = settled["views"][0]["settled"]
    views[0]["params"] = {**views[0]["params"], "concave": {"regions": regions}}
    kept = fused(client, views, resolution=2)
    assert kept["views"][0]["cached"] and kept["views"][0]["settled"] == []
    assert kept["volume"] == pytest.approx(settled["volume"], rel=1e-9)
