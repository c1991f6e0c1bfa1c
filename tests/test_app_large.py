"""Large photos in the app's API: the quick look on a pyramid level, background solves with progress
and cancel, meshes sized for the screen, and photos over the limit downsampled on request.

Checked against ground truth: the quick look's depth against the synthetic sphere's true depth, the
background solve's mesh against the library's own reconstruction of the same image, a downsampled
upload against block means computed here by a loop. One solve of a large photo at most (it is
cancelled); the background solves that finish are of small images.
"""

from __future__ import annotations

import base64
import io
import time

import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image

from helpers.app import mesh_arrays
from shadeform import reconstruct, synth, to_mesh
from shadeform.app.guard import AppLimits
from shadeform.app.large import (
    FIT_FACTOR,
    LARGE_PIXELS,
    VIEW_VERTICES,
    downsample,
    fit_factor,
    level_factor,
    scale_mesh,
    view_step,
)
from shadeform.app.server import create_app
from shadeform.io.images import read_photo, srgb_encode

LOCAL = "http://127.0.0.1:8000"
#: A sphere just over LARGE_PIXELS: the quick look goes through the pyramid.
SIDE = 1500


def png_bytes(image: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(np.rint(np.clip(image, 0, 1) * 65535).astype(np.uint16)).save(buffer, format="PNG")
    return buffer.getvalue()


@pytest.fixture(scope="module")
def client():
    with TestClient(create_app(), base_url=LOCAL) as test_client:
        yield test_client


@pytest.fixture(scope="module")
def ball():
    assert SIDE * SIDE > LARGE_PIXELS
    return synth.scene("sphere", size=SIDE)


@pytest.fixture(scope="module")
def large(client, ball):
    """The sphere uploaded as a 16-bit PNG (linear): its ImageInfo."""
    response = client.post("/api/images", files={"file": ("ball.png", png_bytes(ball.image), "image/png")})
    assert response.status_code == 201, response.text
    return response.json()


def wait(client, job_id: str, timeout: float = 60) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        job = client.get(f"/api/solves/{job_id}").json()
        if job["state"] != "running" or time.monotonic() > deadline:
            return job
        time.sleep(0.05)


# --- the helpers -------------------------------------------------------------------------------


def test_downsample_is_the_block_mean_with_edge_padding():
    rng = np.random.default_rng(0)
    values = rng.random((7, 10, 3)).astype(np.float32)
    got = downsample(values, 3)
    assert got.shape == (3, 4, 3) and got.dtype == np.float32
    padded = np.pad(values, ((0, 2), (0, 2), (0, 0)), mode="edge")
    for i in range(3):
        for j in range(4):
            expected = padded[3 * i : 3 * i + 3, 3 * j : 3 * j + 3].mean(axis=(0, 1))
            np.testing.assert_allclose(got[i, j], expected, rtol=1e-6)
    assert downsample(values, 1) is values


def test_levels_fits_and_view_steps():
    assert level_factor((1000, 1000)) == 1
    factor = level_factor((3000, 4000))
    assert 3000 * 4000 / factor**2 <= 2**20 < 3000 * 4000 / (factor - 1) ** 2
    assert fit_factor(100, 100, 100 * 100) == 1
    assert fit_factor(8193, 8193, 8192 * 8192) == 2
    assert fit_factor(100, 100, 100 * 100 // FIT_FACTOR - 1) is None
    assert view_step(1000, 2) == 2
    step = view_step(12_000_000, 2)
    assert 12_000_000 / step**2 <= VIEW_VERTICES < 12_000_000 / (step - 1) ** 2


def test_a_level_mesh_is_scaled_to_the_photo_pixels(sphere64):
    rec = reconstruct(sphere64.image[::4, ::4], mask=sphere64.mask[::4, ::4])
    small = to_mesh(rec, step=1)
    big = scale_mesh(small, 4)
    # a level pixel (r, c) is the centre of block rows 4r..4r+3, cols 4c..4c+3; depth scaled alike
    np.testing.assert_allclose(big.vertices[:, 0], small.vertices[:, 0] * 4 + 1.5)
    np.testing.assert_allclose(big.vertices[:, 1], small.vertices[:, 1] * 4 - 1.5)
    np.testing.assert_allclose(big.vertices[:, 2], small.vertices[:, 2] * 4)
    np.testing.assert_array_equal(big.faces, small.faces)


# --- the quick look of a large photo -----------------------------------------------------------


def test_large_quick_look_is_solved_on_a_level_in_the_photos_pixels(client, large, ball):
    started = time.perf_counter()
    response = client.post("/api/reconstruct", json={"image_id": large["image_id"], "preview": True})
    seconds = time.perf_counter() - started
    assert response.status_code == 200, response.text
    result = response.json()
    factor = result["info"]["level"]
    assert result["preview"] and factor == level_factor((SIDE, SIDE)) and result["mask_png"] == ""
    positions, _ = mesh_arrays(result["mesh"])
    cols, rows = np.rint(positions[:, 0]).astype(int), np.rint(-positions[:, 1]).astype(int)
    # every vertex lies on the sphere, and they span it (not the level's smaller frame)
    assert ball.mask[rows, cols].mean() > 0.97
    object_rows, object_cols = np.nonzero(ball.mask)
    assert cols.max() - cols.min() > 0.9 * (object_cols.max() - object_cols.min())
    assert rows.max() - rows.min() > 0.9 * (object_rows.max() - object_rows.min())
    # the depth is the sphere's, in the photo's pixels (up to the offset integration leaves)
    truth = ball.depth[rows, cols]
    on = np.isfinite(truth)  # the level's mask is the blocks half on the object: its rim may be off it
    truth = truth[on]
    error = positions[on, 2] - truth
    error -= np.median(error)
    assert np.sqrt(np.mean(error**2)) < 0.05 * np.ptp(truth), (np.sqrt(np.mean(error**2)), np.ptp(truth))
    low, high = result["depth_range"]
    assert abs((high - low) - np.ptp(positions[:, 2])) < 1e-3 * np.ptp(truth)
    # its references are the photo's pixels, on the object
    for row, col in result["references"]:
        assert ball.mask[row, col]
    assert seconds < 10  # a guard; its time is measured in benchmarks/bench_app_large.py


# --- background solves -------------------------------------------------------------------------


def test_background_solve_reports_progress_and_matches_the_library(client):
    scene = synth.scene("bowl", size=96)
    upload = client.post(
        "/api/images", files={"file": ("bowl.png", png_bytes(scene.image), "image/png")}
    ).json()
    body = {"image_id": upload["image_id"], "request_id": 7, "params": {"step": 1}}
    job = client.post("/api/solves", json=body)
    assert job.status_code == 202, job.text
    job = job.json()
    assert job["state"] == "running" and job["request_id"] == 7
    seen = [job]
    while seen[-1]["state"] == "running":
        time.sleep(0.01)
        seen.append(client.get(f"/api/solves/{job['job_id']}").json())
    done = seen[-1]
    assert done["state"] == "done" and done["fraction"] == 1.0 and done["stage_text"] == "Done"
    fractions = [s["fraction"] for s in seen]
    assert fractions == sorted(fractions)
    result = client.get(f"/api/solves/{job['job_id']}/result").json()
    assert result["request_id"] == 7 and not result["preview"] and result["mask_png"]
    # the same mesh as the library's reconstruction of the same image, and the server keeps it
    photo = read_photo(png_bytes(scene.image))
    expected = to_mesh(reconstruct(photo.image), step=1)
    positions, indices = mesh_arrays(result["mesh"])
    np.testing.assert_allclose(positions, expected.vertices, rtol=1e-5, atol=1e-4)
    np.testing.assert_array_equal(indices, expected.faces)
    again = client.post("/api/reconstruct", json=body).json()
    assert again["info"]["cached"] and again["mesh"]["positions"] == result["mesh"]["positions"]
    # a finished solve asked for again is done at once
    known = client.post("/api/solves", json=body).json()
    assert known["state"] == "done"


def test_cancel_stops_the_worker_at_once_and_the_next_solve_runs(client, large):
    job = client.post("/api/solves", json={"image_id": large["image_id"], "params": {"refine": 1}}).json()
    # wait until the worker is solving (past its first stage), then cancel
    deadline = time.monotonic() + 60
    while client.get(f"/api/solves/{job['job_id']}").json()["stage"] == "queued":
        assert time.monotonic() < deadline
        time.sleep(0.05)
    started = time.perf_counter()
    cancelled = client.delete(f"/api/solves/{job['job_id']}")
    assert time.perf_counter() - started < 2.0
    assert cancelled.status_code == 200 and cancelled.json()["state"] == "cancelled"
    result = client.get(f"/api/solves/{job['job_id']}/result")
    assert result.status_code == 409 and "cancelled" in result.json()["detail"]
    # its worker was terminated: the next solve gets a fresh one
    scene = synth.scene("sphere", size=48)
    upload = client.post("/api/images", files={"file": ("s.png", png_bytes(scene.image), "image/png")}).json()
    second = client.post("/api/solves", json={"image_id": upload["image_id"]}).json()
    assert wait(client, second["job_id"])["state"] == "done"
    # an unknown job is one line, 404
    missing = client.get("/api/solves/nope")
    assert missing.status_code == 404 and "unknown solve" in missing.json()["detail"]


def test_a_newer_solve_supersedes_the_running_one(client, large):
    first = client.post("/api/solves", json={"image_id": large["image_id"], "params": {"refine": 2}}).json()
    scene = synth.scene("sphere", size=40)
    upload = client.post("/api/images", files={"file": ("s.png", png_bytes(scene.image), "image/png")}).json()
    second = client.post("/api/solves", json={"image_id": upload["image_id"]}).json()
    old = client.get(f"/api/solves/{first['job_id']}").json()
    assert old["state"] == "cancelled" and "superseded" in old["detail"]
    assert wait(client, second["job_id"])["state"] == "done"


# --- photos over the limit ---------------------------------------------------------------------


def test_over_the_limit_is_offered_a_downsample_that_opens(tmp_path):
    limits = AppLimits(max_pixels=60 * 60)
    rng = np.random.default_rng(1)
    image = rng.random((100, 90))
    data = png_bytes(image)
    with TestClient(create_app(limits=limits, sessions=tmp_path / "s.sqlite3"), base_url=LOCAL) as client:
        refused = client.post("/api/images", files={"file": ("big.png", data, "image/png")})
        assert refused.status_code == 413
        detail = refused.json()["detail"]
        assert refused.headers["X-Shadeform-Fit"] == "2" and refused.headers["X-Shadeform-Size"] == "90x100"
        assert "big.png is too large for the app: 90x100 = 9,000 pixels" in detail and "45x50" in detail
        assert "shadeform reconstruct big.png --tiles auto" in detail and "max_pixels" not in detail
        taken = client.post("/api/images?fit=true", files={"file": ("big.png", data, "image/png")})
        assert taken.status_code == 201, taken.text
        info = taken.json()
        assert (info["width"], info["height"]) == (45, 50)
        # the block means of the photo, computed here by a loop
        pixels = read_photo(data).pixels[:, :, 0]
        expected = np.array(
            [[pixels[2 * i : 2 * i + 2, 2 * j : 2 * j + 2].mean() for j in range(45)] for i in range(50)]
        )
        shown = client.get(f"/api/images/{info['image_id']}/photo.png")
        got = np.asarray(Image.open(io.BytesIO(shown.content)), dtype=np.float64) / 255
        # a 16-bit file is linear: shown sRGB-encoded, as a viewer shows linear data
        expected = srgb_encode(expected)
        assert np.abs(got - expected).max() <= 0.5 / 255 + 1e-6
        # beyond FIT_FACTOR times the limit only the CLI is offered
        huge = client.post(
            "/api/images", files={"file": ("h.png", png_bytes(rng.random((130, 130))), "image/png")}
        )
        assert huge.status_code == 413 and huge.headers["X-Shadeform-Fit"] == "none"
        assert "--tiles auto" in huge.json()["detail"]
    # after a restart, the session store makes it again, downsampled the same way
    with TestClient(create_app(limits=limits, sessions=tmp_path / "s.sqlite3"), base_url=LOCAL) as client:
        again = client.get(f"/api/images/{info['image_id']}/photo.png")
        assert again.status_code == 200 and again.content == shown.content


def test_the_background_solver_gives_way_to_what_the_user_looks_at():
    # its process runs at a background priority, so that a page and its renderer on the same
    # cores are not held up by a long solve (their tasks stretched past 50 ms: app-large.md)
    import os

    from shadeform.app.jobs import BACKGROUND_NICENESS, SolveJobs

    jobs = SolveJobs()
    try:
        jobs.warm()
        pid = jobs._process.pid
        wanted = min(19, os.getpriority(os.PRIO_PROCESS, 0) + BACKGROUND_NICENESS)
        deadline = time.monotonic() + 60
        while os.getpriority(os.PRIO_PROCESS, pid) != wanted and time.monotonic() < deadline:
            time.sleep(0.05)  # the spawned process starts its interpreter first
        assert os.getpriority(os.PRIO_PROCESS, pid) == wanted
    finally:
        jobs.close()


def test_the_object_is_found_on_the_photos_colours(client):
    # a painted body on wood grain (benchmarks/composites.py), as a JPEG: the luma alone takes a
    # sixth of the object; the background solve's worker and the quick look find it on the colours
    from helpers.masks import body, composites, iou

    picture, truth = composites.composite(body(seed=3), "wood", 3, shadow=True)
    buffer = io.BytesIO()
    Image.fromarray(np.round(srgb_encode(picture) * 255).astype(np.uint8)).save(buffer, "JPEG", quality=90)
    upload = client.post("/api/images", files={"file": ("wood.jpg", buffer.getvalue(), "image/jpeg")}).json()
    body_ = {"image_id": upload["image_id"], "request_id": 3, "params": {"solver": "propagation"}}
    job = wait(client, client.post("/api/solves", json=body_).json()["job_id"])
    assert job["state"] == "done", job
    result = client.get(f"/api/solves/{job['job_id']}/result").json()
    mask = np.asarray(Image.open(io.BytesIO(base64.b64decode(result["mask_png"])))) > 0
    mask = mask[..., 0] if mask.ndim == 3 else mask
    assert iou(mask, truth) >= 0.9
    auto = client.post(f"/api/images/{upload['image_id']}/mask/auto", json={}).json()
    found = np.asarray(Image.open(io.BytesIO(base64.b64decode(auto["mask_png"])))) > 0
    assert iou(found[..., 0] if found.ndim == 3 else found, truth) >= 0.9
