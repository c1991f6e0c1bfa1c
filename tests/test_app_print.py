"""The app's print and texture-map endpoints (shadeform.app.printing) with FastAPI's TestClient.

A relief of the synthetic bowl must be a valid solid of the size asked for, its STL and 3MF
downloads must read back (trimesh) as that solid, and the reconstruction the model uses must be
reused, not solved again. The maps' previews are small PNGs; the zip holds the five maps at full
resolution with the bit depths of ``shadeform maps`` and a README.txt legend. Every bad print
option is a 4xx whose body is one line saying what was wrong.
"""

from __future__ import annotations

import base64
import io
import json
import zipfile

import numpy as np
import png
import pytest
from fastapi.testclient import TestClient

from helpers.app import mesh_arrays
from shadeform.app.printing import PREVIEW_SIDE
from shadeform.app.server import create_app
from shadeform.texture import LEGEND

trimesh = pytest.importorskip("trimesh")

LOCAL = "http://127.0.0.1:8000"
SIZE = 96  # the bowl's side: a solve takes a fraction of a second


@pytest.fixture(scope="module")
def client():
    with TestClient(create_app(), base_url=LOCAL) as test_client:
        yield test_client


@pytest.fixture(scope="module")
def bowl(client):
    response = client.post(f"/api/examples/synth:bowl?size={SIZE}")
    assert response.status_code == 201, response.text
    return response.json()


def body(bowl, **relief):
    return {"image_id": bowl["image_id"], "params": bowl["suggested"], "relief": relief}


def decoded(mesh: dict) -> trimesh.Trimesh:
    positions, faces = mesh_arrays(mesh)
    assert len(positions) == mesh["vertex_count"] and len(faces) == mesh["triangle_count"]
    return trimesh.Trimesh(positions, faces, process=False)


def assert_one_line(response, *statuses: int) -> str:
    assert response.status_code in statuses, (response.status_code, response.text)
    detail = response.json()["detail"]
    assert set(response.json()) == {"detail"} and detail and "\n" not in detail and "Traceback" not in detail
    return detail


class TestRelief:
    def test_a_valid_solid_of_the_size_asked(self, client, bowl):
        request = body(bowl, width_mm=80, height_mm=4, base_mm=2) | {"request_id": 7}
        response = client.post("/api/relief", json=request)
        assert response.status_code == 200, response.text
        result = response.json()
        assert result["request_id"] == 7
        width, depth, height = result["size_mm"]
        assert max(width, depth) == pytest.approx(80.0, abs=1e-6)
        assert height == pytest.approx(6.0, abs=1e-6)
        assert result["volume_mm3"] > 0 and result["triangle_count"] == result["mesh"]["triangle_count"]
        assert result["deviation_mm"] >= 0 and result["pixel_mm"] > 0
        assert result["mesh"]["uvs"] == ""
        solid = decoded(result["mesh"])
        assert solid.is_watertight and solid.is_winding_consistent
        assert solid.volume > 0 and solid.volume == pytest.approx(result["volume_mm3"], rel=1e-4)
        assert max(solid.extents[:2]) == pytest.approx(80.0, abs=1e-4)  # float32 on the wire

    def test_the_model_and_the_solid_are_reused(self, client, bowl):
        params = dict(bowl["suggested"], refine=2)  # settings no other test solved
        request = {"image_id": bowl["image_id"], "params": params}
        assert client.post("/api/reconstruct", json=request).status_code == 200
        first = client.post("/api/relief", json=request | {"relief": {"width_mm": 50}}).json()
        assert first["info"] == {"cached": True, "reused": False} and "reconstruct" not in first["timings"]
        # the mesh's step is no part of the solid
        again = client.post(
            "/api/relief", json=request | {"params": dict(params, step=5), "relief": {"width_mm": 50}}
        )
        assert again.json()["info"] == {"cached": True, "reused": True}
        assert again.json()["mesh"] == first["mesh"]

    @pytest.mark.parametrize(("suffix", "media"), [(".stl", "model/stl"), (".3mf", "model/3mf")])
    def test_downloads_read_back_as_the_solid(self, client, bowl, tmp_path, suffix, media):
        request = body(bowl, width_mm=80, height_mm=4, base_mm=2, compress=0.3, max_triangles=5000)
        shown = client.post("/api/relief", json=request).json()
        response = client.post(f"/api/relief/export?format={suffix}", json=request)
        assert response.status_code == 200, response.text
        assert response.headers["content-type"] == media
        assert response.headers["content-disposition"] == f'attachment; filename="synth_bowl-relief{suffix}"'
        path = tmp_path / f"relief{suffix}"
        path.write_bytes(response.content)
        solid = trimesh.load(path, file_type=suffix[1:], force="mesh")
        assert solid.is_watertight and solid.volume > 0
        assert len(solid.faces) == shown["triangle_count"] <= 5000
        assert solid.extents == pytest.approx(shown["size_mm"], abs=1e-3)
        assert max(solid.extents[:2]) == pytest.approx(80.0, abs=1e-3)

    def test_frame_and_invert(self, client, bowl):
        plaque = client.post("/api/relief", json=body(bowl, width_mm=40, outline="frame", invert=True)).json()
        # the frame is the whole image: a square plaque 40 mm on a side
        assert plaque["size_mm"][:2] == pytest.approx([40.0, 40.0], abs=1e-6)
        assert decoded(plaque["mesh"]).is_watertight

    @pytest.mark.parametrize(
        ("relief", "fragment"),
        [
            ({"width_mm": -1}, "the width must be > 0"),
            ({"width_mm": 0}, "the width must be > 0"),
            ({"height_mm": float("nan")}, "the relief height must be a finite number"),
            ({"base_mm": float("inf")}, "the base must be a finite number"),
            ({"base_mm": 0.3}, "thinner than the thinnest wall"),
            ({"min_wall_mm": 0}, "the thinnest wall must be > 0"),
            ({"max_triangles": 0}, "the triangle budget must be a whole number >= 12"),
            ({"max_triangles": 1.5}, "max_triangles"),
            ({"compress": 1.5}, "the compression must be in [0, 1]"),
            ({"border_mm": 50}, "less than half of the width"),
            ({"width_mm": 1e12}, "from 0.001 to 10000 mm"),
            ({"outline": "circle"}, "outline"),
            ({"colour": "red"}, "colour"),
        ],
        ids=repr,
    )
    @pytest.mark.parametrize("url", ["/api/relief", "/api/relief/export?format=.stl"])
    def test_bad_options_are_one_line(self, client, bowl, url, relief, fragment):
        text = json.dumps(body(bowl, **relief), allow_nan=True)
        response = client.post(url, content=text, headers={"content-type": "application/json"})
        assert fragment in assert_one_line(response, 422)

    def test_bad_requests(self, client, bowl):
        assert "unknown export format" in assert_one_line(
            client.post("/api/relief/export?format=.docx", json=body(bowl)), 422
        )
        unknown = {"image_id": "feedfacefeedface"}
        for url in ("/api/relief", "/api/relief/export?format=.3mf", "/api/maps", "/api/maps/zip"):
            assert "unknown image id" in assert_one_line(client.post(url, json=unknown), 404)


class TestMaps:
    def test_previews(self, client, bowl):
        response = client.post("/api/maps", json={"image_id": bowl["image_id"], "params": bowl["suggested"]})
        assert response.status_code == 200, response.text
        result = response.json()
        assert (result["width"], result["height"]) == (SIZE, SIZE)
        assert [m["name"] for m in result["maps"]] == list(LEGEND)
        for preview in result["maps"]:
            bits, text = LEGEND[preview["name"]]
            assert preview["bits"] == bits and preview["legend"].startswith(text.split("{")[0])
            width, height, _, _ = png.Reader(bytes=base64.b64decode(preview["png"])).read()
            assert (width, height) == (SIZE, SIZE)
        assert "px of relief" in next(m["legend"] for m in result["maps"] if m["name"] == "height")

    def test_zip_of_full_resolution_pngs(self, client, bowl):
        request = {"image_id": bowl["image_id"], "params": bowl["suggested"]}
        response = client.post("/api/maps/zip", json=request)
        assert response.status_code == 200, response.text
        assert response.headers["content-type"] == "application/zip"
        assert response.headers["content-disposition"] == 'attachment; filename="synth_bowl-maps.zip"'
        archive = zipfile.ZipFile(io.BytesIO(response.content))
        names = archive.namelist()
        assert sorted(names) == sorted([*(f"synth_bowl_{name}.png" for name in LEGEND), "README.txt"])
        readme = archive.read("README.txt").decode()
        planes = {}
        for name, (bits, _) in LEGEND.items():
            width, height, rows, meta = png.Reader(bytes=archive.read(f"synth_bowl_{name}.png")).read()
            assert (width, height, meta["bitdepth"]) == (SIZE, SIZE, bits), name
            planes[name] = np.array(list(rows)).reshape(height, width, -1)
            assert f"synth_bowl_{name}.png  ({bits}-bit PNG)" in readme
        # DirectX's green is OpenGL's flipped; red and blue the same
        opengl, directx = planes["normal_opengl"], planes["normal_directx"]
        assert np.array_equal(opengl[..., [0, 2]], directx[..., [0, 2]])
        assert np.abs(opengl[..., 1].astype(int) + directx[..., 1] - 65535).max() <= 1  # no uint16 wrap
        # made once: the preview and the zip of the same settings share the maps
        again = client.post("/api/maps", json=request).json()
        assert again["info"]["reused"] is True

    def test_previews_are_small(self, client):
        """A photo over :data:`PREVIEW_SIDE` on a side: each map's preview is the mean of the
        full-resolution map's 2 x 2 blocks (the map the zip holds), so fine detail shows as its
        average."""
        side = PREVIEW_SIDE + 44  # 300: two pixels a side per preview pixel
        made = client.post(f"/api/examples/synth:bowl?size={side}")
        assert made.status_code == 201, made.text
        request = {"image_id": made.json()["image_id"], "params": made.json()["suggested"]}
        previews = client.post("/api/maps", json=request).json()["maps"]
        archive = zipfile.ZipFile(io.BytesIO(client.post("/api/maps/zip", json=request).content))
        for preview in previews:
            width, height, rows, meta = png.Reader(bytes=base64.b64decode(preview["png"])).read()
            assert (width, height) == (side // 2, side // 2), preview["name"]
            small = np.array(list(rows)).reshape(height, width, -1) / (2 ** meta["bitdepth"] - 1)
            width, height, rows, meta = png.Reader(
                bytes=archive.read(f"synth_bowl_{preview['name']}.png")
            ).read()
            full = np.array(list(rows)).reshape(height, width, -1) / (2 ** meta["bitdepth"] - 1)
            blocks = full.reshape(side // 2, 2, side // 2, 2, -1).mean(axis=(1, 3))
            # each rounded to its PNG's levels (the preview's 8 bits at most)
            np.testing.assert_allclose(small, blocks, atol=1.5 / 255, err_msg=preview["name"])
