"""Tests for the app's photo-set API (shadeform.app.stereo) with FastAPI's TestClient.

What the server returns is compared with the library's own photometric stereo on the same
photos (normals, albedo, mesh, exported file), the lights it reports with the true ones, and
every bad photo set must end in a 4xx whose body is one line, with no traceback.
"""

from __future__ import annotations

import base64
import io

import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image

import shadeform
from helpers.lights import angles, sphere_rig
from shadeform import synth
from shadeform.app.server import AppLimits, create_app
from shadeform.examples import load_photo_set_example
from shadeform.io.images import srgb_encode
from shadeform.light import light_from_slant_tilt
from shadeform.photometric import reconstruct_stereo
from shadeform.photoset import write_lights

LOCAL = "http://127.0.0.1:8000"


@pytest.fixture(scope="module")
def client():
    with TestClient(create_app(), base_url=LOCAL) as test_client:
        yield test_client


def png16(image) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(np.rint(np.clip(image, 0, 1) * 65535).astype(np.uint16)).save(buffer, format="PNG")
    return buffer.getvalue()


def decoded(text: str) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(text))), dtype=np.float64)


@pytest.fixture(scope="module")
def lit_sphere():
    """Eight 16-bit photos of a matte sphere (albedo 0.7) under known lights: (files, lights,
    scene)."""
    scene = synth.scene("sphere", size=64)
    lights = np.array([light_from_slant_tilt(s, t) for s, t in zip([20, 35, 50] * 3, range(0, 360, 40))])[:8]
    files = [
        (f"{i:02d}.png", png16(synth.render(scene.normals, scene.mask, light=light, albedo=0.7)))
        for i, light in enumerate(lights)
    ]
    return files, lights, scene


def post_set(client, files, *, lights=None, intensities=None, mask=None):
    parts = [("photos", (name, data, "image/png")) for name, data in files]
    for field, value in (("lights", lights), ("intensities", intensities), ("mask", mask)):
        if value is not None:
            parts.append((field, value))
    return client.post("/api/photosets", files=parts)


def light_text(lights) -> bytes:
    return "\n".join(" ".join(f"{v:.9f}" for v in row) for row in lights).encode()


def one_line_error(response, status):
    assert response.status_code == status, response.text
    detail = response.json()["detail"]
    assert isinstance(detail, str) and "\n" not in detail and "Traceback" not in detail
    return detail


@pytest.fixture(scope="module")
def solved(client):
    """The shipped photo set solved by the server, and by the library: (info, result, rec)."""
    info = client.post("/api/photosets/examples/stereo:vase")
    assert info.status_code == 201, info.text
    info = info.json()
    result = client.post("/api/stereo", json={"photoset_id": info["photoset_id"]})
    assert result.status_code == 200, result.text
    images, lights, mask = load_photo_set_example("stereo:vase")
    return info, result.json(), reconstruct_stereo(images, lights, mask)


class TestExampleSet:
    def test_info(self, solved):
        info, _, _ = solved
        assert (info["count"], info["width"], info["height"]) == (12, 256, 256)
        assert info["colour"] and info["lights_file"] and info["mask"] and not info["intensities_file"]
        assert info["suggested"]["lights"] == "file" and len(info["names"]) == 12

    def test_maps_are_the_librarys(self, solved):
        _, result, rec = solved
        mask = decoded(result["mask_png"]) > 127
        np.testing.assert_array_equal(mask, rec.mask)
        normals = decoded(result["normals_png"]) / 255 * 2 - 1
        assert np.abs(normals[mask] - rec.normals[mask]).max() <= 1.01 / 255 * 2
        # the albedo: sRGB-encoded, white = albedo_white; colour photos keep their colours
        assert rec.albedo.shape == mask.shape + (3,)
        white = result["albedo_white"]
        expected = np.rint(srgb_encode(np.clip(rec.albedo / white, 0, 1).astype(np.float32)) * 255)
        assert np.abs(decoded(result["albedo_png"])[mask] - expected[mask]).max() <= 1
        confidence = decoded(result["confidence_png"]) / 255
        assert np.abs(confidence[mask] - rec.confidence[mask]).max() <= 0.51 / 255

    def test_mesh_and_lights_are_the_librarys(self, solved):
        _, result, rec = solved
        mesh = shadeform.to_mesh(rec, step=2)
        positions = np.frombuffer(base64.b64decode(result["mesh"]["positions"]), "<f4").reshape(-1, 3)
        np.testing.assert_allclose(positions, mesh.vertices, atol=1e-3)
        _, lights, _ = load_photo_set_example("stereo:vase")
        np.testing.assert_allclose(result["lights"], lights, atol=1e-9)
        assert result["sphere"] is None and result["photos_dropped"] == []

    def test_photos_are_served(self, client, solved):
        info, _, _ = solved
        photo = client.get(f"/api/photosets/{info['photoset_id']}/photos/11.png")
        assert photo.status_code == 200 and photo.headers["content-type"] == "image/png"
        assert Image.open(io.BytesIO(photo.content)).size == (256, 256)
        one_line_error(client.get(f"/api/photosets/{info['photoset_id']}/photos/12.png"), 404)

    def test_step_only_remeshes_the_cached_solve(self, client, solved):
        info, result, _ = solved
        again = client.post("/api/stereo", json={"photoset_id": info["photoset_id"], "params": {"step": 4}})
        assert again.status_code == 200 and again.json()["info"]["cached"] is True
        assert again.json()["mesh"]["vertex_count"] < result["mesh"]["vertex_count"] / 3

    def test_export_is_the_librarys_file(self, client, solved, tmp_path):
        info, _, rec = solved
        body = {"photoset_id": info["photoset_id"], "params": {"step": 2}}
        response = client.post("/api/stereo/export?format=obj", json=body)
        assert response.status_code == 200, response.text
        assert 'filename="stereo_vase.obj"' in response.headers["content-disposition"]
        expected = shadeform.export(shadeform.to_mesh(rec, step=2), tmp_path / "model.obj").read_bytes()
        assert response.content == expected

    def test_unknown_lights_are_read_from_the_photos(self, client, solved):
        info, _, _ = solved
        body = {"photoset_id": info["photoset_id"], "params": {"lights": "unknown"}}
        result = client.post("/api/stereo", json=body)
        assert result.status_code == 200, result.text
        got = np.array(result.json()["lights"])
        np.testing.assert_allclose(np.linalg.norm(got, axis=1), 1.0, atol=1e-9)
        assert result.json()["info"]["lights"] == "read from the photos"


def test_uploaded_photos_with_a_light_file_or_an_lp_file(client, lit_sphere, tmp_path):
    files, lights, scene = lit_sphere
    response = post_set(client, files, lights=("lights.txt", light_text(lights), "text/plain"))
    assert response.status_code == 201, response.text
    info = response.json()
    assert info["count"] == 8 and not info["colour"] and info["names"][0] == "00.png"
    result = client.post("/api/stereo", json={"photoset_id": info["photoset_id"]}).json()
    normals = decoded(result["normals_png"]) / 255 * 2 - 1
    inner = scene.mask & (scene.normals[..., 2] > 0.3)
    normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    assert angles(normals[inner], scene.normals[inner]).mean() < 1.0
    # an .lp file names the photos: its lines may come in any order
    order = [3, 0, 7, 5, 1, 6, 2, 4]
    write_lights(tmp_path / "rig.lp", lights[order], names=[files[i][0] for i in order])
    response = post_set(client, files, lights=("rig.lp", (tmp_path / "rig.lp").read_bytes(), "text/plain"))
    assert response.status_code == 201, response.text
    again = client.post("/api/stereo", json={"photoset_id": response.json()["photoset_id"]}).json()
    np.testing.assert_allclose(again["lights"], lights, atol=1e-6)


def test_lights_from_a_sphere_in_the_photos(client, scene_with_sphere):
    folder, lights, obj = scene_with_sphere
    files = [(path.name, path.read_bytes()) for path in sorted(folder.glob("*.png"))]
    response = post_set(client, files)
    assert response.status_code == 201, response.text
    info = response.json()
    assert not info["lights_file"] and info["suggested"]["lights"] == "unknown"
    body = {"photoset_id": info["photoset_id"], "params": {"lights": "sphere"}}
    result = client.post("/api/stereo", json=body)
    assert result.status_code == 200, result.text
    result = result.json()
    np.testing.assert_allclose(result["sphere"], [200, 55, 50], atol=1.0)
    assert angles(np.array(result["lights"]), lights).max() < 1.0
    # the sphere is not the object
    assert decoded(result["mask_png"])[55, 200] == 0 and decoded(result["mask_png"])[190, 70] == 255
    # its circle given: the same lights
    body["params"]["sphere"] = result["sphere"]
    given = client.post("/api/stereo", json=body).json()
    np.testing.assert_allclose(given["lights"], result["lights"], atol=1e-6)


@pytest.fixture(scope="module")
def scene_with_sphere(tmp_path_factory):
    return sphere_rig(tmp_path_factory.mktemp("rig"))


def test_bad_photo_sets_get_one_line(client, lit_sphere):
    files, lights, _ = lit_sphere
    text = ("lights.txt", light_text(lights), "text/plain")
    assert "3 to" in one_line_error(post_set(client, files[:2]), 422)
    small = png16(np.zeros((40, 40)))
    detail = one_line_error(post_set(client, [*files[:7], ("odd.png", small)], lights=text), 422)
    assert "odd.png" in detail and "40x40" in detail
    detail = one_line_error(post_set(client, [*files[:7], ("notes.png", b"not an image")], lights=text), 422)
    assert "notes.png" in detail
    assert "empty" in one_line_error(post_set(client, [*files[:7], ("e.png", b"")], lights=text), 400)
    short = ("lights.txt", light_text(lights[:5]), "text/plain")
    assert "8 rows" in one_line_error(post_set(client, files, lights=short), 422)
    binary = ("lights.txt", b"\xff\xfe\x00", "text/plain")
    assert "not text" in one_line_error(post_set(client, files, lights=binary), 422)
    mask = ("mask.png", png16(np.ones((10, 10))), "image/png")
    one_line_error(post_set(client, files, lights=text, mask=mask), 422)
    # a set without a light file asked to use one; an unknown set; an unknown model
    bare = post_set(client, files).json()["photoset_id"]
    detail = one_line_error(client.post("/api/stereo", json={"photoset_id": bare}), 422)
    assert "without a light file" in detail
    one_line_error(client.post("/api/stereo", json={"photoset_id": "nope"}), 404)
    body = {"photoset_id": bare, "params": {"lights": "unknown", "model": "magic"}}
    detail = one_line_error(client.post("/api/stereo", json=body), 422)
    assert "unknown photometric stereo model 'magic'" in detail and "bivariate" in detail
    body = {"photoset_id": bare, "params": {"lights": "bogus"}}
    one_line_error(client.post("/api/stereo", json=body), 422)
    one_line_error(client.post("/api/photosets/examples/stereo:nope"), 404)
    # a photo set id is not an image id, and the other way round
    one_line_error(client.post("/api/reconstruct", json={"image_id": bare}), 404)


def test_the_whole_set_is_limited():
    limits = AppLimits(max_upload_bytes=30_000, max_image_bytes=200_000)
    with TestClient(create_app(limits=limits), base_url=LOCAL) as client:
        photo = png16(np.full((64, 64), 0.5))  # about 100 bytes each: many fit the body limit
        detail = one_line_error(post_set(client, [(f"{i}.png", photo) for i in range(8)]), 413)
        assert "need" in detail and "fewer or smaller" in detail
        noisy = png16(np.random.default_rng(0).random((128, 128)))  # about 32 KB each
        detail = one_line_error(post_set(client, [(f"{i}.png", noisy) for i in range(4)]), 413)
        assert "photos together" in detail


class TestNamesAndLooks:
    """What a user sees of an uploaded set: its exports named after the photos they gave, its
    16-bit (linear) photos shown sRGB-encoded as a viewer shows linear data (issue 34)."""

    @pytest.mark.parametrize(
        ("names", "stem"),
        [
            ([f"{i:03d}.png" for i in range(1, 9)], "001"),  # DiLiGenT: the first photo's
            ([f"cat_{i:03d}.png" for i in range(1, 9)], "cat"),  # what they share, numbers left out
            ([f"light{i:02d}_frog.png" for i in range(1, 9)], "light_frog"),
            ([f"catPNG/{i:03d}.png" for i in range(1, 9)], "catPNG"),  # the folder, where sent
            ([f"My Set (2)/{i:03d}.png" for i in range(1, 9)], "My_Set_2"),  # sanitised
        ],
    )
    def test_an_export_is_named_after_the_photos(self, client, lit_sphere, names, stem):
        files, lights, _ = lit_sphere
        info = post_set(client, list(zip(names, (data for _, data in files))), lights=light_text(lights))
        assert info.status_code == 201, info.text
        body = {"photoset_id": info.json()["photoset_id"], "params": {"step": 4}}
        response = client.post("/api/stereo/export?format=glb", json=body)
        assert response.status_code == 200, response.text
        assert response.headers["content-disposition"] == f'attachment; filename="{stem}.glb"'

    def test_a_16_bit_photo_is_shown_srgb_encoded(self, client, lit_sphere):
        files, lights, _ = lit_sphere
        info = post_set(client, files, lights=light_text(lights)).json()
        shown = np.asarray(
            Image.open(io.BytesIO(client.get(f"/api/photosets/{info['photoset_id']}/photos/0.png").content)),
            dtype=np.float64,
        )
        assert shown.ndim == 3 and (shown == shown[..., :1]).all()  # a grey photo, as RGB
        shown = shown[..., 0]
        linear = np.asarray(Image.open(io.BytesIO(files[0][1])), dtype=np.float64) / 65535
        expected = np.rint(srgb_encode(linear.astype(np.float32)) * 255)
        assert np.abs(shown - expected).max() <= 1
        # mid-grey light, 0.2 linear, shows as 124 of 255 (not 51: as dark as raw numbers read as sRGB)
        lit = (linear > 0.15) & (linear < 0.25)
        assert lit.any() and np.all(shown[lit] > 105)


def test_a_model_registered_after_the_server_started_is_taken(client, lit_sphere):
    from shadeform.photometric import STEREO_MODELS, StereoModel, register

    files, lights, scene = lit_sphere
    photoset = post_set(client, files, lights=("lights.txt", light_text(lights), "text/plain"))
    assert photoset.status_code == 201, photoset.text
    body = {"photoset_id": photoset.json()["photoset_id"], "params": {"model": "woodham"}}
    assert "bivariate" in one_line_error(client.post("/api/stereo", json=body), 422)
    with STEREO_MODELS.restored():
        register(StereoModel("woodham", "shadeform.photometric.lambertian:least_squares", "a copy"))
        result = client.post("/api/stereo", json=body)
    assert result.status_code == 200, result.text
