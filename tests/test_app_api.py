"""Tests for the app's HTTP API (shadeform.app.server) with FastAPI's TestClient, no browser.

The server must be a thin shell: what it returns is compared with the library's own results for
the same input (meshes array for array, exported files byte for byte), and the synthetic bowl
must bulge toward the viewer without a concave region and sink away with one. Every bad input
must end in a 4xx whose body is exactly ``{"detail": "<one line>"}``, with no traceback in it.
"""

from __future__ import annotations

import asyncio
import base64
import dataclasses
import io
import json
import time
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image

import shadeform
from helpers.pngs import png_with_ihdr
from shadeform import metrics, synth
from shadeform.app import reconstruct as reconstruct_routes
from shadeform.app import schema, server
from shadeform.app.large import FIT_FACTOR, LARGE_PIXELS
from shadeform.app.server import AppLimits, create_app
from shadeform.app.store import LRU
from shadeform.examples import EXAMPLES, load_example
from shadeform.integration import available_integrators
from shadeform.io.exporters import available_formats
from shadeform.io.images import CHANNELS, srgb_encode
from shadeform.light import light_from_slant_tilt
from shadeform.preprocess import FILTER_KINDS, apply_filter
from shadeform.solvers import Problem, Solution, Solver, available_solvers

ROOT = Path(__file__).resolve().parents[1]
LOCAL = "http://127.0.0.1:8000"
SIZE = 64  # side of the synthetic examples used here: each solve takes a fraction of a second
SMALL = AppLimits(max_upload_bytes=20_000, max_pixels=64 * 64, max_json_bytes=50_000)


@pytest.fixture(scope="module")
def client():
    with TestClient(create_app(), base_url=LOCAL) as test_client:
        yield test_client


@pytest.fixture(scope="module")
def small():
    """A server with tiny limits, to hit them with tiny files."""
    with TestClient(create_app(limits=SMALL), base_url=LOCAL) as test_client:
        yield test_client


@pytest.fixture(scope="module")
def bowl(client):
    """The synthetic bowl example, SIZE x SIZE: its ImageInfo."""
    response = client.post(f"/api/examples/synth:bowl?size={SIZE}")
    assert response.status_code == 201, response.text
    return response.json()


def png_bytes(array) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(np.asarray(array)).save(buffer, format="PNG")
    return buffer.getvalue()


def disk_photo(size=48, colour=True) -> np.ndarray:
    """A lit sphere on black: 8-bit RGB (tinted) or gray."""
    scene = synth.scene("sphere", size=size)
    gray = np.rint(scene.image * 230).astype(np.uint8)
    if not colour:
        return gray
    return np.stack([gray, (gray * 0.8).astype(np.uint8), (gray * 0.5).astype(np.uint8)], axis=-1)


def upload(client, data: bytes, name="photo.png"):
    return client.post("/api/images", files={"file": (name, data, "application/octet-stream")})


def reconstruct(client, image_id, request_id=1, **params):
    return client.post(
        "/api/reconstruct", json={"image_id": image_id, "params": params, "request_id": request_id}
    )


def decode_mesh(mesh: dict) -> dict[str, np.ndarray]:
    def array(key, dtype, width):
        return np.frombuffer(base64.b64decode(mesh[key]), dtype=dtype).reshape(-1, width)

    return {
        "positions": array("positions", "<f4", 3),
        "normals": array("normals", "<f4", 3),
        "uvs": array("uvs", "<f4", 2),
        "indices": array("indices", "<u4", 3),
    }


def assert_error(response, status: int, *fragments: str) -> str:
    """``status`` with a body of exactly one key, ``detail``: one line, no traceback."""
    assert response.status_code == status, (response.status_code, response.text)
    assert response.headers["content-type"].startswith("application/json")
    body = response.json()
    assert set(body) == {"detail"} and isinstance(body["detail"], str), body
    detail = body["detail"]
    assert detail and "\n" not in detail and "Traceback" not in detail and 'File "' not in detail
    for fragment in fragments:
        assert fragment.lower() in detail.lower(), detail
    return detail


def library_result(name, size, *, step, **kwargs):
    """What the library makes of an example directly (the server must return the same)."""
    image, info = load_example(name, size=size)
    rec = shadeform.reconstruct(image, light=info["light"], mask=info["mask"], **kwargs)
    return rec, shadeform.to_mesh(rec, step=step)


def centre_minus_rim(positions: np.ndarray, size: int) -> float:
    """Mean height of the vertices near the image centre minus that of the outermost ones."""
    radius = np.hypot(positions[:, 0] - (size - 1) / 2, -positions[:, 1] - (size - 1) / 2)
    return float(positions[radius < 0.15 * size, 2].mean() - positions[radius > radius.max() - 3, 2].mean())


# --------------------------------------------------------------------------------- options


class TestOptions:
    def test_lists_the_library(self, client):
        options = client.get("/api/options").json()
        assert {m["name"]: m["description"] for m in options["solvers"]} == available_solvers()
        assert list(available_solvers())[0] == "auto"
        assert {i["name"]: i["description"] for i in options["integrators"]} == available_integrators()
        assert options["channels"] == list(CHANNELS)
        assert options["filters"] == list(FILTER_KINDS)
        assert {f["suffix"]: f["description"] for f in options["formats"]} == available_formats()
        assert [e["name"] for e in options["examples"]] == list(EXAMPLES)
        assert options["limits"] == {
            "max_upload_bytes": AppLimits().max_upload_bytes,
            "max_pixels": AppLimits().max_pixels,
            "large_pixels": LARGE_PIXELS,
            "fit_factor": FIT_FACTOR,
        }
        assert options["initial_image"] is None

    def test_defaults_are_the_library_defaults(self, client):
        defaults = schema.ReconstructParams(**client.get("/api/options").json()["defaults"])
        assert defaults.solver == "auto" and defaults.refine == 3 and defaults.light.mode == "z"
        assert defaults.integrator is None and defaults.references == [] and defaults.concave.regions == []

    def test_initial_example(self):
        with TestClient(create_app(initial_image="synth:sphere"), base_url=LOCAL) as test_client:
            initial = test_client.get("/api/options").json()["initial_image"]
            assert initial["name"] == "synth:sphere" and initial["width"] == 256
            assert test_client.get(f"/api/images/{initial['image_id']}/photo.png").status_code == 200

    def test_initial_file(self, tmp_path):
        path = tmp_path / "mine.png"
        path.write_bytes(png_bytes(disk_photo()))
        with TestClient(create_app(initial_image=path), base_url=LOCAL) as test_client:
            initial = test_client.get("/api/options").json()["initial_image"]
            assert (initial["name"], initial["width"], initial["channels"]) == ("mine.png", 48, 3)

    def test_initial_pinned(self):
        # the command line's image stays however many images are opened after it
        limits = AppLimits(max_images=2)
        with TestClient(
            create_app(initial_image="synth:sphere", limits=limits), base_url=LOCAL
        ) as test_client:
            initial = test_client.get("/api/options").json()["initial_image"]["image_id"]
            for _ in range(3):
                assert upload(test_client, png_bytes(disk_photo())).status_code == 201
            assert test_client.get(f"/api/images/{initial}/photo.png").status_code == 200

    def test_initial_errors(self, tmp_path):
        with pytest.raises(shadeform.InputError, match="unknown example 'synth:cube'"):
            create_app(initial_image="synth:cube")
        with pytest.raises(shadeform.InputError, match="file not found"):
            create_app(initial_image=tmp_path / "missing.png")


# ---------------------------------------------------------------------------------- images


class TestUpload:
    def test_colour(self, client):
        photo = disk_photo()
        response = upload(client, png_bytes(photo), name="sphere.png")
        assert response.status_code == 201, response.text
        info = response.json()
        assert (info["name"], info["width"], info["height"], info["channels"]) == ("sphere.png", 48, 48, 3)
        assert info["suggested"] is None
        back = Image.open(io.BytesIO(client.get(f"/api/images/{info['image_id']}/photo.png").content))
        np.testing.assert_array_equal(np.asarray(back), photo)  # 8 bits in, the same 8 bits out

    def test_gray_16_bit(self, client):
        values = (synth.scene("sphere", size=40).image * 65535).astype(np.uint16)
        buffer = io.BytesIO()
        Image.fromarray(values).save(buffer, format="TIFF")
        info = upload(client, buffer.getvalue(), name="deep.tif").json()
        assert info["channels"] == 1
        photo = np.asarray(
            Image.open(io.BytesIO(client.get(f"/api/images/{info['image_id']}/photo.png").content))
        )
        # 16 bits are linear: shown sRGB-encoded, as a viewer shows linear data, not as dark as
        # their numbers read as 8-bit sRGB (what is solved on stays linear)
        expected = np.rint(srgb_encode((values / 65535).astype(np.float32)) * 255).astype(np.uint8)
        np.testing.assert_allclose(photo, expected, atol=1)
        assert photo.max() > 250 and np.median(photo[values > 0]) > np.median(values[values > 0]) / 257 + 20

    def test_folders_dropped_from_the_name(self, client):
        info = upload(client, png_bytes(disk_photo()), name="../../secret/..\\My Photo (1).png").json()
        assert info["name"] == "My Photo (1).png"

    def test_ids_differ(self, client):
        data = png_bytes(disk_photo())
        assert upload(client, data).json()["image_id"] != upload(client, data).json()["image_id"]


class TestUploadErrors:
    def test_too_many_bytes(self, small):
        data = png_bytes(np.random.default_rng(1).integers(0, 256, (100, 100, 3), dtype=np.uint8))
        assert 20_000 < len(data) < 64 * 1024  # past the file limit, inside the form allowance
        assert_error(upload(small, data), 413, "larger than")

    def test_body_too_large_refused_before_parsing(self, small):
        assert_error(upload(small, b"\0" * 200_000), 413, "larger than")

    def test_too_many_pixels_declared(self, small):
        assert_error(upload(small, png_with_ihdr(100, 100)), 413, "too large", "10,000")

    def test_too_many_pixels(self, small):
        assert_error(upload(small, png_bytes(disk_photo(size=80, colour=False))), 413, "too large")

    def test_not_an_image(self, client):
        # named as the user's file, not as the bytes the server read
        assert_error(upload(client, b"#!/bin/sh\nrm -rf /\n", name="run.sh"), 415, "not an image: 'run.sh'")

    def test_damaged(self, client):
        data = png_bytes(disk_photo())
        assert_error(upload(client, data[: len(data) // 2], name="cut.png"), 415, "damaged", "'cut.png'")

    def test_too_small(self, client):
        assert_error(upload(client, png_bytes(np.ones((2, 2), np.uint8))), 415, "too small: 'photo.png'")

    def test_empty(self, client):
        assert_error(upload(client, b""), 400, "empty")

    def test_no_file(self, client):
        assert_error(client.post("/api/images", data={"other": "x"}), 422, "field 'file'")
        assert_error(client.post("/api/images"), 422, "field 'file'")

    def test_json_instead_of_a_form(self, client):
        assert_error(client.post("/api/images", json={"file": "/etc/passwd"}), 422, "field 'file'")


class TestExamples:
    def test_every_example(self, client):
        for name in EXAMPLES:
            size = "" if name == "coin" else "?size=32"
            response = client.post(f"/api/examples/{name}{size}")
            assert response.status_code == 201, response.text
            info = response.json()
            image, settings = load_example(name, size=None if name == "coin" else 32)
            assert (info["height"], info["width"], info["channels"]) == (*image.shape, 1)
            suggested = info["suggested"]
            assert suggested["step"] == settings["step"]
            assert suggested["concave"] == {"regions": []}  # the user draws those

    def test_coin_settings(self, client):
        suggested = client.post("/api/examples/coin").json()["suggested"]
        assert suggested["filter"] == {"kind": "gaussian", "size": 1.0}
        assert suggested["light"]["mode"] == "estimate"  # nobody measured this photo's light

    def test_same_example_same_id(self, client):
        first = client.post("/api/examples/synth:vase?size=32").json()["image_id"]
        assert client.post("/api/examples/synth:vase?size=32").json()["image_id"] == first

    def test_unknown(self, client):
        assert_error(client.post("/api/examples/synth:cube"), 404, "unknown example", "synth:bowl")
        assert_error(client.post("/api/examples/..%2F..%2Fetc%2Fpasswd"), 404)
        assert_error(client.post("/api/examples/%2Fetc%2Fpasswd"), 404)

    def test_bad_size(self, client, small):
        assert_error(client.post("/api/examples/synth:bowl?size=4"), 422, "size")
        assert_error(client.post("/api/examples/synth:bowl?size=big"), 422, "size")
        assert_error(client.post("/api/examples/coin?size=64"), 422, "fixed size")
        assert_error(small.post("/api/examples/synth:bowl?size=100"), 413, "smaller size")


class TestPreviews:
    def test_channel(self, client):
        photo = disk_photo()
        image_id = upload(client, png_bytes(photo)).json()["image_id"]
        for index, channel in enumerate("rgb"):
            response = client.get(f"/api/images/{image_id}/channel.png?channel={channel}")
            assert response.status_code == 200 and response.headers["content-type"] == "image/png"
            np.testing.assert_array_equal(
                np.asarray(Image.open(io.BytesIO(response.content))), photo[:, :, index]
            )

    def test_filter_matches_the_library(self, client, bowl):
        response = client.get(f"/api/images/{bowl['image_id']}/channel.png?filter=median:2")
        shown = np.asarray(Image.open(io.BytesIO(response.content))).astype(int)
        image, info = load_example("synth:bowl", size=SIZE)
        expected = np.rint(np.clip(apply_filter(image, info["mask"], "median:2"), 0, 1) * 255)
        np.testing.assert_array_equal(shown, expected)
        before = client.get(f"/api/images/{bowl['image_id']}/channel.png").content
        assert before != response.content

    def test_errors(self, client, bowl):
        base = f"/api/images/{bowl['image_id']}/channel.png"
        assert_error(client.get(base + "?channel=green"), 422, "unknown channel 'green'")
        assert_error(client.get(base + "?filter=blur:3"), 422, "bad filter")
        assert_error(client.get(base + "?filter=median:1.5"), 422, "whole-number")
        assert_error(client.get(base + "?filter=gaussian:-1"), 422, ">= 0")

    def test_unknown_image(self, client):
        for path in ("photo.png", "channel.png"):
            assert_error(client.get(f"/api/images/0123456789abcdef/{path}"), 404, "open the image again")
        assert_error(client.get("/api/images/..%2F..%2F..%2Fetc%2Fpasswd/photo.png"), 404)


# ----------------------------------------------------------------------------- reconstruct


class TestReconstruct:
    def test_a_doubtful_automatic_mask_is_said_with_the_result(self, client, monkeypatch):
        # as the CLI says it (info["mask_warning"]): the server finds the mask itself, so it adds it
        import shadeform.masks as masks

        found = masks.find_object

        def doubtful(image, **options):
            result = found(image, **options)
            return dataclasses.replace(result, confidence=masks.LOW_CONFIDENCE / 2)

        monkeypatch.setattr(masks, "find_object", doubtful)
        info = upload(client, png_bytes(disk_photo(40, colour=False)), name="doubtful.png").json()
        result = reconstruct(client, info["image_id"], solver="propagation").json()
        assert "doubtful" in result["info"]["mask_warning"]
        monkeypatch.undo()
        clear = upload(client, png_bytes(disk_photo(44, colour=False)), name="clear.png").json()
        assert (
            "mask_warning" not in reconstruct(client, clear["image_id"], solver="propagation").json()["info"]
        )

    def test_same_as_the_library(self, client, bowl):
        result = reconstruct(client, bowl["image_id"], request_id=7, step=2).json()
        rec, mesh = library_result("synth:bowl", SIZE, step=2)
        got = decode_mesh(result["mesh"])
        assert result["request_id"] == 7
        assert (result["mesh"]["vertex_count"], result["mesh"]["triangle_count"]) == (
            mesh.n_vertices,
            mesh.n_faces,
        )
        np.testing.assert_array_equal(got["positions"], mesh.vertices.astype(np.float32))
        np.testing.assert_array_equal(got["normals"], mesh.normals.astype(np.float32))
        np.testing.assert_array_equal(got["uvs"], mesh.uv.astype(np.float32))
        np.testing.assert_array_equal(got["indices"], mesh.faces)
        mask = np.asarray(Image.open(io.BytesIO(base64.b64decode(result["mask_png"])))) > 0
        np.testing.assert_array_equal(mask, rec.mask)
        assert result["references"] == [list(ref) for ref in rec.info["references"]]
        assert result["depth_range"] == [float(np.nanmin(rec.depth)), float(np.nanmax(rec.depth))]
        assert result["light"] == [0.0, 0.0, 1.0]
        assert (
            result["info"]["solver"] == rec.info["solver"] == "eikonal" and result["info"]["cached"] is False
        )
        assert {"normals", "mesh", "encode", "total"} <= set(result["timings"])

    def test_mesh_convention(self, client, bowl):
        got = decode_mesh(reconstruct(client, bowl["image_id"], step=3).json()["mesh"])
        positions, uvs = got["positions"], got["uvs"]
        cols, rows = positions[:, 0], -positions[:, 1]
        assert (cols % 3 == 0).all() and (rows % 3 == 0).all()  # grid points every step pixels
        np.testing.assert_allclose(uvs[:, 0], (cols + 0.5) / SIZE, rtol=1e-6)
        np.testing.assert_allclose(uvs[:, 1], 1 - (rows + 0.5) / SIZE, rtol=1e-6)
        np.testing.assert_allclose(np.linalg.norm(got["normals"], axis=1), 1, atol=1e-6)
        corners = positions[got["indices"]]
        facing = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])[:, 2]
        assert (facing > 0).all()  # counter-clockwise seen from +z

    def test_bowl_flips_with_a_concave_region(self, client, bowl):
        scene = synth.scene("bowl", size=SIZE)
        plain = reconstruct(client, bowl["image_id"], step=1).json()
        assert centre_minus_rim(decode_mesh(plain["mesh"])["positions"], SIZE) > 5  # convex guess: bulges
        regions = synth.concave_regions("bowl", size=SIZE)
        marked = reconstruct(client, bowl["image_id"], step=1, concave=regions).json()
        positions = decode_mesh(marked["mesh"])["positions"]
        true_positions = scene.depth[(-positions[:, 1]).astype(int), positions[:, 0].astype(int)]
        assert centre_minus_rim(positions, SIZE) < -5  # sinks away from the viewer, as the truth
        assert centre_minus_rim(np.column_stack([positions[:, :2], true_positions]), SIZE) < -5
        rec, _ = library_result("synth:bowl", SIZE, step=1, concave=regions)
        assert metrics.depth_error(rec.depth, scene.depth, fit="offset") < 1  # measured 0.04 %

    def test_step_only_reuses_the_solve(self, client, bowl):
        params = {"refine": 2, "filter": {"kind": "gaussian", "size": 1.0}}
        first = reconstruct(client, bowl["image_id"], step=1, **params).json()
        second = reconstruct(client, bowl["image_id"], step=4, **params).json()
        assert first["info"]["cached"] is False and second["info"]["cached"] is True
        assert "normals" not in second["timings"] and "mesh" in second["timings"]
        assert second["mesh"]["vertex_count"] < first["mesh"]["vertex_count"] / 10
        changed = reconstruct(client, bowl["image_id"], step=4, **{**params, "refine": 1}).json()
        assert changed["info"]["cached"] is False

    def test_preview_then_full(self, client, bowl):
        params = {"step": 2, "filter": {"kind": "gaussian", "size": 2.0}}
        body = {"image_id": bowl["image_id"], "params": params, "request_id": 7}
        quick = client.post("/api/reconstruct", json={**body, "preview": True}).json()
        assert quick["preview"] is True and quick["info"]["preview_step"] == 2 and quick["request_id"] == 7
        full = client.post("/api/reconstruct", json=body).json()
        assert (
            full["preview"] is False
            and "preview_step" not in full["info"]
            and full["info"]["cached"] is False
        )
        # the quick look has the full mesh's vertices and triangles, at nearly the same depth
        quick_mesh, full_mesh = decode_mesh(quick["mesh"]), decode_mesh(full["mesh"])
        np.testing.assert_array_equal(quick_mesh["indices"], full_mesh["indices"])
        np.testing.assert_array_equal(quick_mesh["positions"][:, :2], full_mesh["positions"][:, :2])
        depth_gap = quick_mesh["positions"][:, 2] - full_mesh["positions"][:, 2]
        assert np.std(depth_gap) < 0.02 * np.ptp(full_mesh["positions"][:, 2])
        assert quick["mask_png"] == full["mask_png"]
        # once the full result is known, a preview request gets it
        again = client.post("/api/reconstruct", json={**body, "preview": True}).json()
        assert again["preview"] is False and again["info"]["cached"] is True
        # at step 1 there is no quick look
        single = client.post(
            "/api/reconstruct", json={**body, "params": {**params, "step": 1, "refine": 1}, "preview": True}
        ).json()
        assert single["preview"] is False

    def test_light_modes(self, client):
        image_id = client.post("/api/examples/synth:sphere?size=48").json()["image_id"]
        tilted = reconstruct(client, image_id, light={"mode": "slant_tilt", "slant": 20, "tilt": 30}).json()
        np.testing.assert_allclose(tilted["light"], light_from_slant_tilt(20, 30), atol=1e-12)
        estimated = reconstruct(client, image_id, light={"mode": "estimate"}).json()
        assert "light_estimate" in estimated["info"]
        assert np.degrees(np.arccos(estimated["light"][2])) < 5  # the sphere was lit from +z

    def test_user_reference_comes_first(self, client, bowl):
        result = reconstruct(client, bowl["image_id"], references=[[20, 30]]).json()
        assert result["references"][0] == [20, 30]

    def test_every_method_and_integrator(self, client, bowl):
        for method in available_solvers():
            for integrator in (None, *available_integrators()):
                response = reconstruct(client, bowl["image_id"], step=4, solver=method, integrator=integrator)
                assert response.status_code == 200, (method, integrator, response.text)

    def test_colour_channels(self, client):
        image_id = upload(client, png_bytes(disk_photo())).json()["image_id"]
        for channel in CHANNELS:
            assert reconstruct(client, image_id, channel=channel).status_code == 200


class TestReconstructErrors:
    @pytest.mark.parametrize(
        ("params", "fragments"),
        [
            ({"step": 0}, ["params.step", "greater than or equal to 1"]),
            ({"step": 2.5}, ["params.step"]),
            ({"step": SIZE}, ["step must be at least 1 and below"]),
            ({"refine": -1}, ["params.refine"]),
            ({"solver": "magic"}, ["unknown solver 'magic'", "propagation"]),
            ({"integrator": "guess"}, ["unknown integrator 'guess'"]),
            ({"channel": "green"}, ["params.channel", "'luma'"]),
            ({"filter": {"kind": "blur", "size": 1}}, ["params.filter.kind"]),
            ({"filter": {"kind": "median", "size": 1.5}}, ["whole-number window radius"]),
            ({"filter": {"kind": "gaussian", "size": -2}}, ["params.filter.size"]),
            ({"light": {"mode": "slant_tilt", "slant": 95, "tilt": 0}}, ["slant must be in [0, 90)"]),
            ({"light": {"mode": "sun"}}, ["params.light.mode"]),
            ({"references": [[0, 0]]}, ["not on the object"]),
            ({"references": [[1, 2, 3]]}, ["params.references.0"]),
            ({"concave": {"regions": [{"polygon": [[0, 0], [5, 5]], "axis": "x"}]}}, ["at least 3 points"]),
            ({"concave": {"regions": [{"polygon": [[0, 0], [5, 5], [0, 5]], "axis": "z"}]}}, ["axis"]),
            ({"concave": [{"polygon": [], "axis": "x"}]}, ["params.concave"]),
            ({"colour": "red"}, ["params.colour", "unknown field"]),
            ({"solver": "eikonal", "light": {"mode": "slant_tilt", "slant": 30, "tilt": 0}}, ["(0, 0, 1)"]),
        ],
    )
    def test_bad_params(self, client, bowl, params, fragments):
        assert_error(reconstruct(client, bowl["image_id"], **params), 422, *fragments)

    def test_unknown_image(self, client):
        assert_error(reconstruct(client, "feedfacefeedface"), 404, "unknown image id", "reload the page")
        assert_error(reconstruct(client, "../../etc/passwd"), 404, "unknown image id")

    def test_malformed_json(self, client):
        headers = {"content-type": "application/json"}
        assert_error(
            client.post("/api/reconstruct", content=b'{"image_id": ', headers=headers), 422, "not valid JSON"
        )
        assert_error(client.post("/api/reconstruct", content=b"\xff\xfe", headers=headers), 422)
        assert_error(client.post("/api/reconstruct", json=[1, 2]), 422, "body")
        assert_error(client.post("/api/reconstruct", json={"params": {}}), 422, "image_id", "missing")
        assert_error(client.post("/api/reconstruct", json={"image_id": 5}), 422, "image_id")
        assert_error(client.post("/api/reconstruct"), 422, "missing")

    def test_body_too_large(self, small):
        points = [[float(i), float(i % 7)] for i in range(5000)]
        body = {"image_id": "x", "params": {"concave": {"regions": [{"polygon": points, "axis": "x"}]}}}
        assert_error(small.post("/api/reconstruct", json=body), 413, "larger than")

    def test_many_problems_one_line(self, client, bowl):
        detail = assert_error(reconstruct(client, bowl["image_id"], step=0, refine=-1, channel="q"), 422)
        assert "2 more problems" in detail

    def test_internal_error_is_one_line(self, monkeypatch, bowl):
        def broken(*args, **kwargs):
            raise RuntimeError("secret internals\nline two")

        monkeypatch.setattr(shadeform.pipeline, "reconstruct", broken)
        monkeypatch.setattr(shadeform, "reconstruct", broken, raising=False)
        with TestClient(create_app(), base_url=LOCAL, raise_server_exceptions=False) as test_client:
            image_id = test_client.post(f"/api/examples/synth:bowl?size={SIZE}").json()["image_id"]
            detail = assert_error(reconstruct(test_client, image_id), 500, "internal error", "report")
        assert "secret" not in detail


class TestSuperseded:
    def test_no_solve_for_a_client_that_left(self, monkeypatch):
        """A request whose client disconnected (the app aborts superseded requests) is not solved."""
        calls = []
        monkeypatch.setattr(reconstruct_routes, "reconstruct_result", lambda *args: calls.append(args))
        app = create_app()
        with TestClient(app, base_url=LOCAL) as test_client:
            image_id = test_client.post(f"/api/examples/synth:bowl?size={SIZE}").json()["image_id"]
        body = json.dumps({"image_id": image_id}).encode()
        incoming = [{"type": "http.request", "body": body, "more_body": False}, {"type": "http.disconnect"}]
        sent = []

        async def receive():
            return incoming.pop(0) if incoming else {"type": "http.disconnect"}

        async def send(message):
            sent.append(message)

        scope = {
            "type": "http",
            "asgi": {"version": "3.0"},
            "http_version": "1.1",
            "method": "POST",
            "scheme": "http",
            "path": "/api/reconstruct",
            "raw_path": b"/api/reconstruct",
            "query_string": b"",
            "root_path": "",
            "server": ("127.0.0.1", 8000),
            "client": ("127.0.0.1", 5),
            "headers": [
                (b"host", b"127.0.0.1:8000"),
                (b"content-type", b"application/json"),
                (b"content-length", str(len(body)).encode()),
            ],
        }
        asyncio.run(app(scope, receive, send))
        assert calls == []
        assert sent[0]["status"] == 204


# ---------------------------------------------------------------------------------- export


class TestExport:
    def test_every_format_is_the_library_file(self, client, bowl, tmp_path):
        _, mesh = library_result("synth:bowl", SIZE, step=2)
        request = {"image_id": bowl["image_id"], "params": {"step": 2}}
        for suffix in available_formats():
            response = client.post(f"/api/export?format={suffix}", json=request)
            assert response.status_code == 200, response.text
            assert response.headers["content-disposition"] == f'attachment; filename="synth_bowl{suffix}"'
            expected = shadeform.export(mesh, tmp_path / f"expected{suffix}").read_bytes()
            assert response.content == expected, suffix

    def test_a_closed_model_is_the_librarys_and_says_its_back_is_guessed(self, client, tmp_path):
        """``closed=true``: the library's :func:`shadeform.close` of the same solve (its back the
        front mirrored), watertight, named as closed."""
        import trimesh

        image_id = client.post("/api/examples/synth:ellipsoid?size=96").json()["image_id"]
        request = {"image_id": image_id, "params": {"step": 2}}
        response = client.post("/api/export?format=.stl&closed=true", json=request)
        assert response.status_code == 200, response.text
        assert response.headers["content-disposition"] == 'attachment; filename="synth_ellipsoid_closed.stl"'
        rec, _ = library_result("synth:ellipsoid", 96, step=2)
        expected = shadeform.export(shadeform.close(rec, resolution=2), tmp_path / "closed.stl").read_bytes()
        assert response.content == expected
        (tmp_path / "got.stl").write_bytes(response.content)
        assert trimesh.load(tmp_path / "got.stl").is_watertight
        assert_error(client.post("/api/export?format=.stl&closed=maybe", json=request), 422, "closed")

    def test_suffix_without_dot_and_case(self, client, bowl):
        request = {"image_id": bowl["image_id"]}
        wrl = client.post("/api/export?format=.wrl", json=request).content
        assert client.post("/api/export?format=WRL", json=request).content == wrl

    def test_upload_name_sanitised(self, client):
        image_id = upload(client, png_bytes(disk_photo()), name="..\\..\\x/; rm -rf ~ ü.png").json()[
            "image_id"
        ]
        response = client.post("/api/export?format=.iv", json={"image_id": image_id})
        assert response.status_code == 200
        assert response.headers["content-disposition"] == 'attachment; filename="rm_-rf.iv"'

    def test_bad_formats(self, client, bowl):
        request = {"image_id": bowl["image_id"]}
        for bad in ("xyz", ".exe", "../../etc/passwd", ".wrl/../../x", "..%2F..%2Fx", ".wrl%00.sh", ""):
            assert_error(client.post(f"/api/export?format={bad}", json=request), 422, "format")
        assert_error(client.post("/api/export", json=request), 422, "format", "missing")

    def test_bad_requests(self, client, bowl):
        assert_error(
            client.post("/api/export?format=.wrl", json={"image_id": "nope"}), 404, "unknown image id"
        )
        assert_error(
            client.post(
                "/api/export?format=.wrl", json={"image_id": bowl["image_id"], "params": {"solver": "x"}}
            ),
            422,
            "unknown solver",
        )


# ----------------------------------------------------------------------------------- masks


def mask_text(mask) -> str:
    """A mask as ReconstructParams.mask: base64 of a PNG, 255 on the object."""
    return base64.b64encode(png_bytes(np.where(mask, 255, 0).astype(np.uint8))).decode()


def decoded_mask(text: str) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(text)))) > 0


def half_bowl():
    """The bowl's true mask with its left half taken off: a mask the automatic one is not."""
    _, info = load_example("synth:bowl", size=SIZE)
    mask = info["mask"].copy()
    mask[:, : SIZE // 2] = False
    return mask


class TestMasks:
    def test_auto_is_what_a_solve_uses(self, client, bowl):
        result = client.post(f"/api/images/{bowl['image_id']}/mask/auto", json={}).json()
        solved = reconstruct(client, bowl["image_id"]).json()
        np.testing.assert_array_equal(decoded_mask(result["mask_png"]), decoded_mask(solved["mask_png"]))
        assert result["note"] == "the example's true mask"
        np.testing.assert_array_equal(
            decoded_mask(result["mask_png"]), load_example("synth:bowl", size=SIZE)[1]["mask"]
        )

    def test_auto_photo_is_the_library_mask(self, client):
        from shadeform.masks import find_object

        image_id = client.post("/api/examples/coin").json()["image_id"]
        result = client.post(f"/api/images/{image_id}/mask/auto", json={"channel": "luma"}).json()
        found = find_object(load_example("coin")[0])
        np.testing.assert_array_equal(decoded_mask(result["mask_png"]), found.mask)
        assert result["pixels"] == found.mask.sum() and result["dark"] is False
        assert result["threshold"] == pytest.approx(found.threshold) and result["note"] == found.note

    def test_threshold(self, client):
        from shadeform.masks import threshold_object

        image, _ = load_example("coin")
        image_id = client.post("/api/examples/coin").json()["image_id"]
        for dark in (False, True):
            result = client.post(
                f"/api/images/{image_id}/mask/auto", json={"threshold": 0.3, "dark": dark}
            ).json()
            np.testing.assert_array_equal(
                decoded_mask(result["mask_png"]), threshold_object(image, 0.3, dark=dark)
            )
            assert result["threshold"] == 0.3 and result["dark"] is dark

    def test_seeds(self, client):
        from shadeform.masks import segment_from_seeds

        gray = np.zeros((40, 80), dtype=np.uint8)
        gray[5:35, 5:30] = 200
        gray[5:35, 45:75] = 120
        image_id = upload(client, png_bytes(gray)).json()["image_id"]
        result = client.post(
            f"/api/images/{image_id}/mask/seeds", json={"inside": [[20, 60]], "outside": [[2, 40]]}
        ).json()
        mask = decoded_mask(result["mask_png"])
        assert mask[5:35, 45:75].all() and mask.sum() == 30 * 30
        image = gray / 255.0  # the same object whether the upload was made linear or not
        np.testing.assert_array_equal(mask, segment_from_seeds(image, [(20, 60)], [(2, 40)]))
        assert result["note"] == "grown from 1 click on the object and 1 on the background"

    def test_file_is_checked_and_made_a_grey_png(self, client, bowl):
        mask = half_bowl()
        rgba = np.zeros((SIZE, SIZE, 4), dtype=np.uint8)
        rgba[mask] = (255, 255, 255, 255)
        rgba[~mask, 3] = 255
        data = base64.b64encode(png_bytes(rgba)).decode()
        result = client.post(f"/api/images/{bowl['image_id']}/mask/file", json={"data": data}).json()
        png = Image.open(io.BytesIO(base64.b64decode(result["mask_png"])))
        assert png.mode == "L" and set(np.unique(np.asarray(png))) == {0, 255}
        np.testing.assert_array_equal(np.asarray(png) > 0, mask)
        assert result["pixels"] == mask.sum()

    def test_reconstruct_and_preview_use_the_mask(self, client, bowl):
        mask = half_bowl()
        params = {"step": 2, "mask": mask_text(mask)}
        image, info = load_example("synth:bowl", size=SIZE)
        rec = shadeform.reconstruct(image, light=info["light"], mask=mask)
        expected = shadeform.to_mesh(rec, step=2)
        for preview in (True, False):
            body = {"image_id": bowl["image_id"], "params": params, "preview": preview}
            result = client.post("/api/reconstruct", json=body).json()
            np.testing.assert_array_equal(decoded_mask(result["mask_png"]), mask)
            positions = decode_mesh(result["mesh"])["positions"]
            assert positions[:, 0].min() >= SIZE // 2  # nothing left of the mask's edge
        np.testing.assert_array_equal(positions, expected.vertices.astype(np.float32))
        plain = reconstruct(client, bowl["image_id"], step=2).json()
        assert plain["mesh"]["vertex_count"] > 1.8 * result["mesh"]["vertex_count"]

    def test_export_uses_the_mask(self, client, bowl, tmp_path):
        mask = half_bowl()
        image, info = load_example("synth:bowl", size=SIZE)
        expected = shadeform.to_mesh(shadeform.reconstruct(image, light=info["light"], mask=mask), step=2)
        request = {"image_id": bowl["image_id"], "params": {"step": 2, "mask": mask_text(mask)}}
        response = client.post("/api/export?format=.obj", json=request)
        assert response.status_code == 200, response.text
        assert response.content == shadeform.export(expected, tmp_path / "expected.obj").read_bytes()

    @pytest.mark.parametrize(
        ("make", "fragments"),
        [
            (lambda: mask_text(np.ones((10, 12), dtype=bool)), ["mask is 12x10 but the image is 64x64"]),
            (lambda: mask_text(np.zeros((SIZE, SIZE), dtype=bool)), ["mask is empty"]),
            (lambda: base64.b64encode(b"not a picture").decode(), ["mask:", "not an image"]),
            (lambda: "%%% not base64 %%%", ["not base64"]),
            (lambda: "", ["empty file"]),
        ],
    )
    def test_bad_masks(self, client, bowl, make, fragments):
        text = make()
        assert_error(reconstruct(client, bowl["image_id"], mask=text), 422, *fragments)
        assert_error(
            client.post(
                "/api/export?format=.wrl", json={"image_id": bowl["image_id"], "params": {"mask": text}}
            ),
            422,
            *fragments,
        )
        assert_error(
            client.post(f"/api/images/{bowl['image_id']}/mask/file", json={"data": text}), 422, *fragments
        )

    def test_bad_requests(self, client, bowl):
        route = f"/api/images/{bowl['image_id']}/mask"
        assert_error(
            client.post(f"{route}/auto", json={"threshold": 2.0}), 422, "no pixel is above threshold 2"
        )
        assert_error(client.post(f"{route}/auto", json={"channel": "pink"}), 422, "channel")
        assert_error(client.post(f"{route}/seeds", json={"inside": []}), 422, "inside")
        assert_error(
            client.post(f"{route}/seeds", json={"inside": [[99, 0]]}), 422, "not a pixel of the 64x64 image"
        )
        assert_error(
            client.post(f"{route}/seeds", json={"inside": [[0, 0]]}), 422, "look like the background"
        )
        assert_error(client.post(f"{route}/seeds", json={"inside": [[9, 9]], "radius": 500}), 422, "radius")
        assert_error(client.post(f"{route}/file", json={}), 422, "data", "missing")
        assert_error(client.post("/api/images/feedfacefeedface/mask/auto", json={}), 404, "unknown image id")
        assert_error(client.get(f"{route}/auto"), 405, "not allowed")


# ------------------------------------------------------------------- guard, routes, static


class TestGuard:
    def test_other_hosts_refused(self, client):
        response = client.get("/api/options", headers={"host": "attacker.example"})
        assert_error(response, 403, "only answers requests addressed to")
        assert_error(client.get("/api/options", headers={"host": "attacker.example:8000"}), 403)

    def test_loopback_hosts(self, client):
        # the server is bound to port 8000 (the test client's base URL): any loopback name at it
        for host in ("127.0.0.1:8000", "localhost:8000", "LOCALHOST:8000", "[::1]:8000", "localhost:08000"):
            assert client.get("/api/options", headers={"host": host}).status_code == 200, host

    @pytest.mark.parametrize(
        "host", ["localhost", "127.0.0.1:80", "LOCALHOST:1", "[::1]:8001", "127.0.0.1:18000", "localhost:"]
    )
    def test_other_ports_refused(self, client, host):
        # a loopback name at another port: something forwarded it (the browser took the app for
        # that other address's origin); the refusal names the addresses that are answered
        for response in (
            client.get("/api/options", headers={"host": host}),
            client.get("/", headers={"host": host}),
        ):
            detail = assert_error(response, 403, "only answers requests addressed to", "127.0.0.1:8000")
            assert repr(host) in detail

    def test_the_bound_port_is_the_servers(self):
        app = create_app(allowed_hosts=["localhost"])
        with TestClient(app, base_url="http://localhost:8765") as client:
            assert client.get("/api/options").status_code == 200
            assert client.get("/api/options", headers={"host": "localhost:8000"}).status_code == 403
        with TestClient(app, base_url="http://localhost") as client:  # port 80: Host may leave it out
            assert client.get("/api/options", headers={"host": "localhost"}).status_code == 200
            assert client.get("/api/options", headers={"host": "localhost:80"}).status_code == 200
            assert client.get("/api/options", headers={"host": "localhost:8765"}).status_code == 403
        # a forwarder the user runs, named with its port, is answered as it is
        with TestClient(create_app(allowed_hosts=["localhost", "127.0.0.1:9000"]), base_url=LOCAL) as client:
            assert client.get("/api/options", headers={"host": "127.0.0.1:9000"}).status_code == 200
            assert client.get("/api/options", headers={"host": "127.0.0.1:9001"}).status_code == 403

    def test_other_origins_refused(self, client, bowl):
        evil = {"origin": "http://attacker.example"}
        assert_error(upload_with(client, evil), 403, "other sites")
        assert_error(client.post("/api/reconstruct", json={"image_id": bowl["image_id"]}, headers=evil), 403)

    @pytest.mark.parametrize(
        "origin",
        [
            "null",  # a sandboxed page, a local file
            "NULL",
            "http://localhost:5173",  # another server on this machine: another origin
            "http://127.0.0.1:8001",
            "http://127.0.0.1",  # port 80
            "https://127.0.0.1:8000",  # another scheme
            "http://localhost:8000",  # another host name for the same machine
            "http://127.0.0.1:8000.attacker.example",
            "http://attacker.example#127.0.0.1:8000",
            "http://127.0.0.1:8000/",  # not an origin
            "http://user@127.0.0.1:8000",
            "file://",
            "chrome-extension://abcdef",
            "127.0.0.1:8000",
            "",
        ],
    )
    def test_only_the_apps_own_origin(self, client, bowl, origin):
        headers = {"origin": origin}
        for response in (
            client.get("/api/options", headers=headers),
            client.post("/api/reconstruct", json={"image_id": bowl["image_id"]}, headers=headers),
            upload_with(client, headers),
            client.get("/", headers=headers),
        ):
            detail = assert_error(response, 403, "refused", "open the app at the address it printed")
        assert ("null" in detail.lower()) == (origin.lower() == "null")

    def test_own_origin_served(self, client, bowl):
        for origin in ("http://127.0.0.1:8000", "HTTP://127.0.0.1:8000"):
            assert client.get("/api/options", headers={"origin": origin}).status_code == 200
        response = upload_with(client, {"origin": LOCAL})
        assert response.status_code == 201, response.text
        # another address of this machine, asked for by the page itself (Host and Origin agree),
        # and the Vite dev server's (npm run dev), which forwards its page's Host and Origin
        for host, origin in (
            ("localhost:5173", "http://localhost:5173"),
            ("[::1]:8000", "http://[::1]:8000"),
        ):
            response = client.get("/api/options", headers={"host": host, "origin": origin})
            assert response.status_code == 200, (host, response.text)

    def test_cross_site_fetch_refused(self, client, bowl):
        # browsers say where a request comes from even where they send no Origin
        for site in ("cross-site", "same-site"):
            for mode in ("cors", "no-cors", "navigate"):
                headers = {"sec-fetch-site": site, "sec-fetch-mode": mode}
                assert_error(upload_with(client, headers), 403, "refused", site)
            headers = {"sec-fetch-site": site, "sec-fetch-mode": "no-cors"}
            # an <img> of another site showing the user's photo
            assert_error(client.get(f"/api/images/{bowl['image_id']}/photo.png", headers=headers), 403)
            # a link to the app from another site still opens it
            link = {"sec-fetch-site": site, "sec-fetch-mode": "navigate"}
            assert client.get("/", headers=link).status_code == 200
        for site in ("same-origin", "none"):
            headers = {"sec-fetch-site": site, "sec-fetch-mode": "cors", "origin": LOCAL}
            assert upload_with(client, headers).status_code == 201

    def test_one_host_header(self):
        # a Host header sent twice is ambiguous: refused before any check reads either
        scope = {
            "type": "http",
            "method": "GET",
            "path": "/api/options",
            "scheme": "http",
            "headers": [(b"host", b"127.0.0.1:8000"), (b"host", b"attacker.example")],
        }
        sent = []

        async def send(message):
            sent.append(message)

        async def receive():
            return {"type": "http.request", "body": b""}

        asyncio.run(create_app()(scope, receive, send))
        assert sent[0]["status"] == 400

    def test_any_host_when_allowed(self):
        with TestClient(create_app(allowed_hosts=None), base_url="http://192.168.1.20:8000") as test_client:
            assert test_client.get("/api/options").status_code == 200
            origin = {"origin": "http://192.168.1.20:8000"}
            assert test_client.get("/api/options", headers=origin).status_code == 200
            # any host, but still only the app's own pages
            for origin in ("http://attacker.example", "null", "http://192.168.1.20:8001"):
                assert_error(test_client.get("/api/options", headers={"origin": origin}), 403, "refused")


def upload_with(client, headers):
    return client.post("/api/images", files={"file": ("a.png", png_bytes(disk_photo()))}, headers=headers)


class TestRoutes:
    def test_unknown_api_path(self, client):
        assert_error(client.get("/api/nothing"), 404, "no such API endpoint")
        assert_error(client.post("/api/images/abc/photo.png"), 405, "not allowed")
        assert_error(client.post("/api/nothing/else"), 404, "no such API endpoint")

    def test_wrong_method(self, client):
        assert_error(client.get("/api/reconstruct"), 405, "not allowed")
        assert_error(client.post("/"), 405)
        assert_error(client.delete("/api/options"), 405, "not allowed")


class TestStatic:
    def test_no_client_built(self, tmp_path):
        with TestClient(create_app(static_dir=tmp_path / "missing"), base_url=LOCAL) as test_client:
            page = test_client.get("/")
            assert page.status_code == 200 and "make web" in page.text
            assert_error(test_client.get("/assets/app.js"), 404)

    def test_built_client(self, tmp_path):
        static = tmp_path / "static"
        (static / "assets").mkdir(parents=True)
        (static / "index.html").write_text("<!doctype html><title>app</title>")
        (static / "assets" / "app.js").write_text("console.log(1)")
        (tmp_path / "secret.txt").write_text("do not serve")
        with TestClient(create_app(static_dir=static), base_url=LOCAL) as test_client:
            assert test_client.get("/").text == "<!doctype html><title>app</title>"
            assert test_client.get("/assets/app.js").text == "console.log(1)"
            for sneaky in (
                "/../secret.txt",
                "/%2e%2e/secret.txt",
                "/assets/..%2F..%2Fsecret.txt",
                "/..%5Csecret.txt",
                "/assets/%2e%2e/%2e%2e/secret.txt",
            ):
                response = test_client.get(sneaky)
                assert "do not serve" not in response.text, sneaky
                assert response.status_code == 404, sneaky


# ------------------------------------------------------------------------ schema, store, cli


def test_the_schema_s_limits_are_the_library_s():
    """The schema stays free of the library's imports, so its bounds repeat the library's: the
    same numbers, or the app would accept what the solve then refuses (or the reverse)."""
    from shadeform.pipeline import MAX_REFINE

    refine = schema.ReconstructParams.model_fields["refine"].metadata
    assert [rule.le for rule in refine if hasattr(rule, "le")] == [MAX_REFINE]


class TestGeneratedTypes:
    def test_committed_file_is_current(self):
        committed = (ROOT / "web" / "src" / "api.gen.ts").read_text(encoding="utf-8")
        assert committed == schema.typescript(), (
            "web/src/api.gen.ts is stale: run `python -m shadeform.app.schema > web/src/api.gen.ts`"
        )

    def test_every_model_and_alias(self):
        text = schema.typescript()
        for name in (
            "ReconstructParams",
            "ReconstructRequest",
            "ReconstructResult",
            "ImageInfo",
            "Options",
            "MeshData",
            "ErrorBody",
        ):
            assert f"export interface {name} {{" in text
        assert 'export type Channel = "luma" | "r" | "g" | "b" | "max";' in text
        assert "  light: [number, number, number];" in text
        assert "  integrator: string | null;" in text
        assert "  references: [number, number][];" in text


class TestLRU:
    def test_count(self):
        lru = LRU(max_items=2, max_bytes=100)
        for key in "abc":
            lru.put(key, key.upper(), 1)
        assert lru.get("a") is None and lru.get("b") == "B" and lru.get("c") == "C"

    def test_bytes_and_recency(self):
        lru = LRU(max_items=10, max_bytes=10)
        lru.put("a", 1, 4)
        lru.put("b", 2, 4)
        assert lru.get("a") == 1  # now b is the least recently used
        lru.put("c", 3, 4)
        assert lru.get("b") is None and lru.get("a") == 1 and lru.nbytes == 8

    def test_pinned_and_oversize(self):
        lru = LRU(max_items=2, max_bytes=10)
        lru.put("pin", 0, 5, pinned=True)
        lru.put("big", 1, 50)  # alone over the limit: kept, it is the newest
        assert lru.get("big") == 1 and lru.get("pin") == 0
        lru.put("next", 2, 1)
        assert lru.get("big") is None and lru.get("pin") == 0 and len(lru) == 2


class TestAppCommand:
    @pytest.fixture
    def served(self, monkeypatch):
        """Record what would be served, and that no browser or warm-up really starts."""
        import webbrowser

        import uvicorn

        calls = {}
        monkeypatch.setattr(
            uvicorn.Server, "run", lambda self, sockets: calls.update(app=self.config.app, sockets=sockets)
        )
        monkeypatch.setattr(webbrowser, "open", lambda url: calls.update(browser=url))
        monkeypatch.setattr(server, "warm_up", lambda: calls.update(warmed=True))
        monkeypatch.delenv("DISPLAY", raising=False)
        monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
        yield calls
        for sock in calls.get("sockets", ()):
            sock.close()

    def test_serves_on_loopback(self, served, cli):
        result = cli("app", "synth:sphere", "--port", 0, "--no-browser")
        assert result.exit_code == 0, result.output
        port = served["sockets"][0].getsockname()[1]
        assert f"http://127.0.0.1:{port}/" in result.stdout
        assert served["sockets"][0].getsockname()[0] == "127.0.0.1"
        assert "browser" not in served
        with TestClient(served["app"], base_url=f"http://127.0.0.1:{port}") as test_client:
            assert test_client.get("/api/options").json()["initial_image"]["name"] == "synth:sphere"
        for _ in range(100):  # start-up began compiling the kernels in a background thread
            if "warmed" in served:
                break
            time.sleep(0.02)
        assert served.get("warmed") is True

    def test_image_file(self, served, cli, tmp_path):
        path = tmp_path / "photo.png"
        path.write_bytes(png_bytes(disk_photo()))
        assert cli("app", path, "--port", 0).exit_code == 0
        with TestClient(served["app"], base_url=LOCAL) as test_client:
            assert test_client.get("/api/options").json()["initial_image"]["name"] == "photo.png"

    def test_remote_needs_the_flag(self, served, cli):
        result = cli("app", "--host", "0.0.0.0", "--port", 0)
        assert result.exit_code == 2 and "sockets" not in served
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and "--allow-remote" in lines[0]

    def test_remote_warns(self, served, cli):
        result = cli("app", "--host", "0.0.0.0", "--port", 0, "--allow-remote", "--no-browser")
        assert result.exit_code == 0, result.output
        assert "warning" in result.stderr and "not loopback" in result.stderr
        with TestClient(served["app"], base_url="http://10.1.2.3:8000") as test_client:
            assert test_client.get("/api/options").status_code == 200  # any Host: remote users

    def test_bad_image(self, served, cli, tmp_path):
        for bad, fragment in (
            (tmp_path / "missing.png", "no such image file or example"),
            (tmp_path, "no such image file or example"),
        ):
            result = cli("app", bad, "--port", 0)
            assert result.exit_code == 2, result.output
            assert fragment in result.stderr and "Traceback" not in result.output
        (tmp_path / "text.png").write_text("not a picture")
        result = cli("app", tmp_path / "text.png", "--port", 0)
        assert result.exit_code == 2 and "not an image" in result.stderr

    def test_port_in_use(self, served, cli):
        import socket

        with socket.socket() as taken:
            taken.bind(("127.0.0.1", 0))
            taken.listen()
            result = cli("app", "--port", taken.getsockname()[1], "--no-browser")
        assert result.exit_code == 2 and "choose another --port" in result.stderr


def facing_the_viewer(problem: Problem) -> Solution:
    """A solver registered by the warm-up test: every normal toward the viewer, depth by the
    integrator."""
    normals = np.zeros((*problem.mask.shape, 3))
    normals[..., 2] = 1.0
    return Solution(normals, problem.integrate(normals), {})


def test_warm_up_runs_every_method(registries, monkeypatch):
    """The warm-up solves with every method the app lists (one registered just now included), with
    each integrator it lists and the solver's own, on float32 and float64 images, and meshes each
    result: so the first request of each kind finds its kernels compiled."""
    registries[0].register(
        Solver("facing", facing_the_viewer, integrator="poisson", description="flat (a test solver)")
    )
    solved, meshed = [], []
    real_reconstruct, real_to_mesh = shadeform.reconstruct, shadeform.to_mesh

    def reconstruct(image, **options):
        result = real_reconstruct(image, **options)  # a method that fails raises here
        solved.append((options.get("solver", "auto"), options.get("integrator"), image.dtype))
        return result

    def to_mesh(result, **options):
        meshed.append(result)
        return real_to_mesh(result, **options)

    # warm_up imports them from the package when it runs
    monkeypatch.setattr(shadeform, "reconstruct", reconstruct)
    monkeypatch.setattr(shadeform, "to_mesh", to_mesh)
    server.warm_up()

    with TestClient(create_app(), base_url=LOCAL) as fresh:  # an app's options are read when it is made
        options = fresh.get("/api/options").json()
    methods = [m["name"] for m in options["solvers"]]
    integrators = [None, *(i["name"] for i in options["integrators"])]
    assert "facing" in methods and len(integrators) > 2
    offered = {
        (method, integrator, np.dtype(dtype))
        for method in methods
        for integrator in integrators
        for dtype in (np.float32, np.float64)
    }
    assert offered <= set(solved), sorted(map(str, offered - set(solved)))
    # each pair once per dtype, each of them meshed, plus the one solve of the confidence's outlines
    assert len(solved) == len(offered) + 1 and len(meshed) == len(offered)
