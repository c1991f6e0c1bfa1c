"""shadeform.tiled: huge images in overlapping tiles, checked against the analytic relief and the
same image solved whole, on small images (192 x 192 in tiles of 64); objects on a background
(a 256-pixel sphere in tiles of 128); hostile TIFFs, interruptions and what is left behind."""

from __future__ import annotations

import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import tifffile

import shadeform
from shadeform import synth, tiled
from shadeform.errors import InputError
from shadeform.tiled import reading, tasks
from shadeform.tiled.join import Tiling, _band, _disagreement, _offsets
from shadeform.tiled.output import _mesh_step

SIDE, SPACING, TILE, OVERLAP = 192, 48.0, 64, 32
TILES = (SIDE // TILE) ** 2
# GeoTIFF tags of a small north-up raster: pixel scale, one tie point, a GeoKey directory
GEO = [
    (33550, "d", 3, (0.5, 0.5, 0.0), True),
    (33922, "d", 6, (0.0, 0.0, 0.0, 431000.0, 5207000.0, 0.0), True),
    (34735, "H", 8, (1, 1, 0, 1, 3072, 3, 1, 32632), True),
]


def rms(depth, truth, region=np.s_[:, :]):
    """Root-mean-square depth error after the best offset."""
    diff = (np.asarray(depth, dtype=np.float64) - truth)[region]
    return float(np.sqrt(np.mean((diff - diff.mean()) ** 2)))


@pytest.fixture(scope="module")
def scene():
    return synth.bump_relief((SIDE, SIDE), spacing=SPACING)


@pytest.fixture(scope="module")
def whole(scene):
    return shadeform.reconstruct(scene.image, mask=scene.mask)


@pytest.fixture(scope="module")
def result(scene):
    return tiled.reconstruct(scene.image, tile=TILE, overlap=OVERLAP, scheduler="synchronous", mask="whole")


@pytest.fixture
def geotiff(scene, tmp_path):
    path = tmp_path / "relief.tif"
    tifffile.imwrite(path, np.rint(scene.image * 65535).astype(np.uint16), tile=(64, 64), extratags=GEO)
    return path


def test_bump_relief_windows_agree_with_the_whole():
    full = synth.bump_relief((200, 300), spacing=40)
    part = synth.bump_relief((200, 300), window=(37, 101, 90, 150), spacing=40)
    np.testing.assert_array_equal(part.depth, full.depth[37:127, 101:251])
    np.testing.assert_array_equal(part.image, full.image[37:127, 101:251])
    # the image is n_z of the analytic normals, whose slopes are the depth's (finite differences)
    slope = np.gradient(full.depth, axis=1)[50:150, 50:250]
    assert np.abs(slope - (-full.normals[..., 0] / full.normals[..., 2])[50:150, 50:250]).max() < 0.05


def test_tiled_error_within_a_fifth_of_the_whole_solve(scene, whole, result):
    assert result.tiles == TILES and result.solved == TILES and result.skipped == 0
    assert result.depth.shape == (SIDE, SIDE) and np.isfinite(result.depth).all()
    error_whole = rms(whole.depth, scene.depth)
    error_tiled = rms(result.depth, scene.depth)
    assert error_tiled <= 1.2 * error_whole, (error_tiled, error_whole)
    assert error_tiled < 0.05 * np.ptp(scene.depth)


def test_no_seams(scene, whole, result):
    """Across tile borders the height steps are as right as inside the tiles and as in the whole
    solve; the tiles' disagreement where they are blended is below the whole solve's own error."""
    whole_error = np.abs(whole.depth - scene.depth - np.mean(whole.depth - scene.depth))
    assert result.seam < whole_error.max()
    for axis in (0, 1):
        step = np.abs(np.diff(result.depth - scene.depth, axis=axis))
        crossing = (np.arange(SIDE - 1) + 1) % TILE == 0
        border = np.take(step, np.flatnonzero(crossing), axis=axis)
        inside = np.take(step, np.flatnonzero(~crossing), axis=axis)
        whole_step = np.abs(np.diff(whole.depth - scene.depth, axis=axis))
        assert border.max() <= inside.max(), (border.max(), inside.max())
        assert border.max() <= whole_step.max()


def test_the_join_finds_each_tiles_offset_and_blends_without_seams(scene, tmp_path):
    """Tiles of the true depth, each shifted by its own offset (a tile's z = 0 is at its own
    reference pixel) and slightly noisy: the join recovers the offsets and the blend the depth."""
    grid = Tiling(SIDE, SIDE, TILE, OVERLAP)
    rng = np.random.default_rng(1)
    names, shifts = {}, {}
    for i in range(grid.rows):
        for j in range(grid.cols):
            window = grid.window(i, j)
            shifts[i, j] = rng.uniform(-20, 20)
            names[i, j] = tmp_path / f"{i}_{j}.npy"
            noisy = scene.depth[window] + shifts[i, j] + rng.normal(0, 0.01, scene.depth[window].shape)
            np.save(names[i, j], noisy.astype(np.float32))
    offsets = _offsets(grid, names)
    recovered = np.array([offsets[k] + shifts[k] for k in names])
    assert np.ptp(recovered) < 0.01  # every tile shifted back to one common level
    seam, _ = _disagreement(grid, names, offsets)
    assert seam < 0.1  # what is left is the noise
    blended = np.concatenate([_band(grid, names, offsets, i) for i in range(grid.rows)])
    assert rms(blended, scene.depth) < 0.01
    butted = np.zeros((SIDE, SIDE))  # the tiles' cores side by side, without the join
    for (i, j), path in names.items():
        k0, k1, e0, _ = grid.span(i, SIDE)
        c0, c1, f0, _ = grid.span(j, SIDE)
        butted[k0:k1, c0:c1] = np.load(path)[k0 - e0 : k1 - e0, c0 - f0 : c1 - f0]
    assert rms(butted, scene.depth) > 100 * rms(blended, scene.depth)


def test_geotiff_in_bigtiff_out_with_its_tags_and_a_mesh(scene, result, geotiff, tmp_path):
    import trimesh

    out, mesh = tmp_path / "depth.tif", tmp_path / "relief.ply"
    made = tiled.reconstruct(
        geotiff,
        tile=TILE,
        overlap=OVERLAP,
        scheduler="synchronous",
        out=out,
        mesh=mesh,
        max_triangles=5000,
        mask="whole",
    )
    assert made.depth is None and made.path == out
    assert not (tmp_path / "depth.tif.tiles").exists()  # the work folder goes after success
    with tifffile.TiffFile(out) as tif:
        page = tif.pages.first
        assert tif.is_bigtiff and page.is_tiled and page.dtype == np.float32
        for code, _, _, value, _ in GEO:
            assert tuple(np.atleast_1d(page.tags[code].value)) == pytest.approx(value)
        depth = page.asarray()
    # read from a 16-bit file it is the same relief: as right as the float image's result
    assert rms(depth, scene.depth) <= 1.1 * rms(result.depth, scene.depth) + 1e-3
    # the mesh: the depth on a grid, decimated to the budget, in pixels of the input
    loaded = trimesh.load(mesh, process=False)
    step = _mesh_step(Tiling(SIDE, SIDE, TILE, OVERLAP), 5000)
    assert 0.8 * 5000 <= len(loaded.faces) <= 5000 < 2 * (SIDE // step - 1) ** 2
    assert np.ptp(loaded.vertices[:, 0]) == pytest.approx(SIDE - step, abs=step)
    assert np.ptp(loaded.vertices[:, 2]) == pytest.approx(np.ptp(depth[::step, ::step]), rel=0.02)


def test_a_rerun_skips_the_finished_tiles(scene, result, tmp_path, monkeypatch):
    work = tmp_path / "work"
    solve = tasks.tile_depth
    calls = []

    def failing(image, mask, options):
        if len(calls) == 5:
            raise RuntimeError("interrupted")
        calls.append(1)
        return solve(image, mask, options)

    monkeypatch.setattr(tasks, "tile_depth", failing)
    run = {"tile": TILE, "overlap": OVERLAP, "scheduler": "synchronous", "work": work, "mask": "whole"}
    with pytest.raises(RuntimeError, match="interrupted"):
        tiled.reconstruct(scene.image, keep_work=True, **run)
    assert len(list(work.glob("*.npy"))) == 5

    def counting(image, mask, options):
        calls.append(1)
        return solve(image, mask, options)

    calls.clear()
    monkeypatch.setattr(tasks, "tile_depth", counting)
    again = tiled.reconstruct(scene.image, keep_work=True, **run)
    assert (again.solved, again.skipped, len(calls)) == (TILES - 5, 5, TILES - 5)
    np.testing.assert_allclose(again.depth, result.depth, atol=1e-5)
    # another tile size is another run: its tiles are not mixed with these
    with pytest.raises(InputError, match="another run"):
        tiled.reconstruct(scene.image, **{**run, "tile": 2 * TILE})


def test_on_a_cluster_of_worker_processes(result, geotiff, tmp_path):
    distributed = pytest.importorskip("distributed")
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=50
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        made = tiled.reconstruct(
            geotiff, tile=TILE, overlap=OVERLAP, scheduler=client, out=tmp_path / "d.tif", mask="whole"
        )
        workers = {w["id"] for w in client.scheduler_info()["workers"].values()}
    assert made.solved == TILES and len(workers) == 2
    local = tiled.reconstruct(geotiff, tile=TILE, overlap=OVERLAP, scheduler="synchronous", mask="whole")
    np.testing.assert_allclose(tifffile.imread(tmp_path / "d.tif"), local.depth, atol=1e-5)


@pytest.mark.parametrize(
    ("options", "fragment"),
    [
        ({"tile": 60}, "multiple of 16"),
        ({"overlap": 7}, "even"),
        ({"overlap": 200}, "overlap"),
        ({"out": "depth.png"}, "BigTIFF"),
        ({"light": "estimate"}, "direction"),
        ({"mask": np.ones((8, 8), bool)}, "shape"),
        ({"mask": np.zeros((64, 64), bool)}, "empty"),
        ({"scheduler": "fastest"}, "scheduler"),
        ({"solver": "magic"}, "solver"),
    ],
)
def test_bad_options_are_one_line_input_errors(options, fragment):
    image = synth.bump_relief((64, 64), spacing=32).image
    with pytest.raises(InputError, match=fragment) as caught:
        tiled.reconstruct(image, **{"tile": 32, "overlap": 8, "mask": "whole", **options})
    assert "\n" not in str(caught.value)


def test_without_dask_the_message_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "dask", None)
    with pytest.raises(InputError, match=r"shadeform\[dask\]"):
        tiled.reconstruct(np.ones((64, 64)), tile=32, overlap=8)


def test_cli_tiles_end_to_end(geotiff, tmp_path):
    from typer.testing import CliRunner

    from shadeform.cli import app

    runner = CliRunner(env={"COLUMNS": "200"})
    out = tmp_path / "out"
    out.mkdir()
    done = runner.invoke(
        app,
        [
            "reconstruct",
            str(geotiff),
            "-o",
            str(out / "r.glb"),
            "--tiles",
            "64",
            "--scheduler",
            "synchronous",
            "--mask",
            "whole",
        ],
    )
    assert done.exit_code == 0, done.output
    assert sorted(p.name for p in out.iterdir()) == ["r.glb", "r_depth.tif"]
    assert f"{TILES} tiles" in done.stdout
    with tifffile.TiffFile(out / "r_depth.tif") as tif:
        assert 33922 in tif.pages.first.tags  # georeferenced like the input
    # auto: tiled only over the pixel limit
    auto = runner.invoke(
        app,
        [
            "reconstruct",
            str(geotiff),
            "-o",
            str(out / "a.ply"),
            "--max-pixels",
            "10000",
            "--scheduler",
            "synchronous",
        ],
    )
    assert auto.exit_code == 0, auto.output
    assert "tiles of 512" in auto.stdout
    empty = tmp_path / "empty"
    empty.mkdir()
    for args in (
        ["--tiles", "huge"],
        ["--tiles", "64", "--reference", "1,1"],
        ["--tiles", "24"],
        ["--tiles", "64", "--scheduler", "evil"],  # refused before the work folder is made
        ["--tiles", "64", "--mask", str(tmp_path / "none.png")],
    ):
        bad = runner.invoke(app, ["reconstruct", str(geotiff), "-o", str(empty / "r.glb"), *args])
        assert bad.exit_code == 2, bad.output
        lines = bad.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in bad.output
    assert list(empty.iterdir()) == []


# --- objects on a background ---------------------------------------------------------------------

OBJECT_SIDE, OBJECT_TILE = 256, 128


@pytest.fixture(scope="module")
def sphere():
    """A sphere on black: the object fills the middle, the frame is background."""
    return synth.scene("sphere", size=OBJECT_SIDE)


@pytest.fixture(scope="module")
def sphere_whole(sphere):
    return shadeform.reconstruct(sphere.image)


def offset_rms(depth, reference, mask):
    """RMS difference of two depth maps over ``mask`` after the best offset."""
    diff = (np.asarray(depth, dtype=np.float64) - reference)[mask]
    return float(np.sqrt(np.mean((diff - diff.mean()) ** 2)))


def check_matches_whole(made, scene, whole):
    """The bar: the object alone has depth (NaN on the background, as solved whole), and the
    tiled depth differs from the whole solve's, after the offset, by less than the whole
    solve's own error against the true depth."""
    assert np.isfinite(made.depth[scene.mask]).all()
    assert np.isnan(made.depth[~scene.mask]).all()
    own_error = offset_rms(whole.depth, scene.depth, scene.mask)
    assert offset_rms(made.depth, whole.depth, scene.mask) <= own_error
    assert made.info["seam_warning"] is None


def test_an_object_photo_tiled_matches_the_whole_solve(sphere, sphere_whole):
    made = tiled.reconstruct(sphere.image, tile=OBJECT_TILE, scheduler="synchronous")
    check_matches_whole(made, sphere, sphere_whole)
    assert "bright object" in made.info["mask"]


def test_an_object_photo_on_a_local_dask_cluster(sphere, sphere_whole, tmp_path):
    distributed = pytest.importorskip("distributed")
    path = tmp_path / "sphere.tif"
    tifffile.imwrite(path, np.rint(sphere.image * 65535).astype(np.uint16), tile=(64, 64))
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None, silence_logs=50
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        made = tiled.reconstruct(path, tile=OBJECT_TILE, scheduler=client)
    assert made.info["scheduler"].startswith("distributed")
    check_matches_whole(made, sphere, sphere_whole)


def test_a_given_mask_is_the_object(sphere, tmp_path):
    """A mask given (an array, or an image file) is used at full resolution: depth on it only."""
    mask = sphere.mask.copy()
    mask[:, : OBJECT_SIDE // 2] = False  # the right half of the sphere only
    made = tiled.reconstruct(sphere.image, tile=OBJECT_TILE, scheduler="synchronous", mask=mask)
    assert np.array_equal(np.isfinite(made.depth), mask)
    path = tmp_path / "mask.tif"
    tifffile.imwrite(path, mask.astype(np.uint8) * 255, tile=(64, 64))
    from_file = tiled.reconstruct(sphere.image, tile=OBJECT_TILE, scheduler="synchronous", mask=path)
    np.testing.assert_array_equal(from_file.depth, made.depth)


def test_a_seam_above_the_solvers_error_is_a_warning_in_words(sphere, tmp_path):
    """Tiles of 64 on a 256-pixel sphere: the rim's tiles never see its top and disagree."""
    made = tiled.reconstruct(sphere.image, tile=64, scheduler="synchronous")
    warning = made.info["seam_warning"]
    assert made.seam > tiled.SEAM_FRACTION * made.info["depth_range"]
    assert warning and "\n" not in warning and f"{made.seam:.3g} px" in warning
    from typer.testing import CliRunner

    from shadeform.cli import app

    image = tmp_path / "sphere.tif"
    tifffile.imwrite(image, np.rint(sphere.image * 65535).astype(np.uint16))
    done = CliRunner().invoke(
        app,
        ["reconstruct", str(image), "-o", str(tmp_path / "s.ply"), "--tiles", "64", "--scheduler", "threads"],
    )
    assert done.exit_code == 0, done.output
    warnings = [line for line in done.stderr.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "tiles disagree" in warnings[0], done.stderr


def test_cli_takes_a_mask_with_tiles(sphere, tmp_path):
    from PIL import Image
    from typer.testing import CliRunner

    from shadeform.cli import app

    image, mask = tmp_path / "sphere.tif", tmp_path / "mask.png"
    tifffile.imwrite(image, np.rint(sphere.image * 65535).astype(np.uint16))
    Image.fromarray(sphere.mask.astype(np.uint8) * 255).save(mask)
    depth = tmp_path / "d.tif"
    done = CliRunner().invoke(
        app,
        ["reconstruct", str(image), "-o", str(tmp_path / "s.ply"), "--tiles", "128", "--mask", str(mask),
         "--depth", str(depth), "--scheduler", "synchronous"],
    )  # fmt: skip
    assert done.exit_code == 0, done.output
    assert np.array_equal(np.isfinite(tifffile.imread(depth)), sphere.mask)
    assert "the mask mask.png" in done.stdout


# --- hostile files, interruptions, leftovers -----------------------------------------------------


def tiff_bytes(width, height, *, width_tag=None, bits=8, data=b"\x80" * 100):
    """A classic TIFF of one strip, written byte by byte: it may declare what it cannot hold."""

    def long(v):
        return struct.pack("<I", v)

    def short(v):
        return struct.pack("<HH", v, 0)

    start = 8 + 2 + 12 * 9 + 4
    entries = [
        width_tag or (256, 4, 1, long(width)),
        (257, 4, 1, long(height)),
        (258, 3, 1, short(bits)),
        (259, 3, 1, short(1)),
        (262, 3, 1, short(1)),
        (273, 4, 1, long(start)),
        (277, 3, 1, short(1)),
        (278, 4, 1, long(height)),
        (279, 4, 1, long(min(width * height * bits // 8, 2**32 - 1))),
    ]
    ifd = struct.pack("<H", len(entries))
    for tag, kind, count, value in sorted(entries):
        ifd += struct.pack("<HHI", tag, kind, count) + value
    return b"II*\x00" + struct.pack("<I", 8) + ifd + struct.pack("<I", 0) + data


HOSTILE = {
    "width as text": tiff_bytes(64, 64, width_tag=(256, 2, 4, b"abc\x00"), data=b"\x80" * 4096),
    "1e10 pixels in 222 bytes": tiff_bytes(100_000, 100_000),
    "one row of 4e9": tiff_bytes(4_000_000_000, 1),
    "(2^32-1) squared": tiff_bytes(2**32 - 1, 2**32 - 1),
    "width 0": tiff_bytes(0, 64),
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_hostile_tiffs_are_refused_in_one_line_before_any_work(name, tmp_path):
    path = tmp_path / "x.tif"
    path.write_bytes(HOSTILE[name])
    with pytest.raises(InputError) as caught:
        tiled.reconstruct(path, tile=64, out=tmp_path / "x_depth.tif")
    assert "\n" not in str(caught.value)
    from typer.testing import CliRunner

    from shadeform.cli import app

    for tiles in ("auto", "64"):
        done = CliRunner().invoke(
            app, ["reconstruct", str(path), "-o", str(tmp_path / "x.ply"), "--tiles", tiles]
        )
        assert done.exit_code == 2, (tiles, done.output)
        assert len(done.stderr.strip().splitlines()) == 1 and done.stderr.startswith("error: ")
        assert sorted(p.name for p in tmp_path.iterdir()) == ["x.tif"]


def test_strips_too_large_to_read_by_windows_are_refused(tmp_path, monkeypatch):
    path = tmp_path / "strip.tif"
    tifffile.imwrite(path, np.full((64, 64), 200, np.uint8), compression="zlib", rowsperstrip=64)
    monkeypatch.setattr(reading, "MAX_SEGMENT_BYTES", 1024)
    with pytest.raises(InputError, match="strips or tiles"):
        tiled.TiffWindows(path)


def test_a_black_image_is_refused_before_the_tiles(tmp_path):
    path = tmp_path / "black.tif"
    tifffile.imwrite(path, np.zeros((300, 300), np.uint16))
    with pytest.raises(InputError, match="no object"):
        tiled.reconstruct(path, tile=64, out=tmp_path / "d.tif", scheduler="synchronous")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["black.tif"]


def test_an_interrupted_run_removes_its_work_unless_kept(sphere, tmp_path, monkeypatch):
    solve = tasks.tile_depth
    calls = []

    def interrupted(image, mask, options):
        if len(calls) == 2:
            raise KeyboardInterrupt
        calls.append(1)
        return solve(image, mask, options)

    monkeypatch.setattr(tasks, "tile_depth", interrupted)
    out = tmp_path / "d.tif"
    with pytest.raises(KeyboardInterrupt):
        tiled.reconstruct(sphere.image, tile=64, out=out, scheduler="synchronous")
    assert list(tmp_path.iterdir()) == []
    calls.clear()
    with pytest.raises(KeyboardInterrupt):
        tiled.reconstruct(sphere.image, tile=64, out=out, scheduler="synchronous", keep_work=True)
    kept = tmp_path / "d.tif.tiles"
    assert (kept / "manifest.json").exists() and len(list(kept.glob("*.npy"))) == 2


def test_sigterm_stops_a_tiled_run_and_its_workers_and_leaves_nothing(tmp_path):
    """The command line, tiles in 2 worker processes: SIGTERM once the tiles are being solved."""
    scene = synth.scene("sphere", size=512)
    image = tmp_path / "sphere.tif"
    tifffile.imwrite(image, np.rint(scene.image * 65535).astype(np.uint16), tile=(64, 64))
    out = tmp_path / "out"
    out.mkdir()
    env = {**os.environ, "PYTHONPATH": str(Path(shadeform.__file__).parents[1]), "OPENBLAS_NUM_THREADS": "1"}
    command = [sys.executable, "-c", "from shadeform.cli import main; main()", "reconstruct", str(image),
               "-o", str(out / "s.ply"), "--tiles", "32", "--scheduler", "processes"]  # fmt: skip
    run = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    work = out / "s_depth.tif.tiles"
    deadline = time.monotonic() + 120
    while not list(work.glob("*.npy")) and run.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert run.poll() is None, run.communicate()
    children = subprocess.run(["pgrep", "-P", str(run.pid)], capture_output=True, text=True).stdout.split()
    run.send_signal(signal.SIGTERM)
    run.wait(timeout=60)  # a guard against a hang, not a timing
    assert run.returncode != 0
    assert list(out.iterdir()) == []  # no work folder, no manifest, no partial file
    for pid in children:
        for _ in range(100):
            if not Path(f"/proc/{pid}").exists():
                break
            time.sleep(0.05)
        assert not Path(f"/proc/{pid}").exists(), f"worker {pid} outlived the run"
