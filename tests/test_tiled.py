"""shadeform.tiled: huge images in overlapping tiles, checked against the analytic relief and the
same image solved whole, on small images (192 x 192 in tiles of 64)."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import tifffile

import shadeform
from shadeform import synth, tiled
from shadeform.errors import InputError

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
    return tiled.reconstruct(scene.image, tile=TILE, overlap=OVERLAP, scheduler="synchronous")


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
    grid = tiled._Grid(SIDE, SIDE, TILE, OVERLAP)
    rng = np.random.default_rng(1)
    names, shifts = {}, {}
    for i in range(grid.rows):
        for j in range(grid.cols):
            window = grid.window(i, j)
            shifts[i, j] = rng.uniform(-20, 20)
            names[i, j] = tmp_path / f"{i}_{j}.npy"
            noisy = scene.depth[window] + shifts[i, j] + rng.normal(0, 0.01, scene.depth[window].shape)
            np.save(names[i, j], noisy.astype(np.float32))
    offsets = tiled._offsets(grid, names)
    recovered = np.array([offsets[k] + shifts[k] for k in names])
    assert np.ptp(recovered) < 0.01  # every tile shifted back to one common level
    seam, _ = tiled._disagreement(grid, names, offsets)
    assert seam < 0.1  # what is left is the noise
    blended = np.concatenate([tiled._band(grid, names, offsets, i) for i in range(grid.rows)])
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
        geotiff, tile=TILE, overlap=OVERLAP, scheduler="synchronous", out=out, mesh=mesh, max_triangles=5000
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
    step = tiled._mesh_step(tiled._Grid(SIDE, SIDE, TILE, OVERLAP), 5000)
    assert 0.8 * 5000 <= len(loaded.faces) <= 5000 < 2 * (SIDE // step - 1) ** 2
    assert np.ptp(loaded.vertices[:, 0]) == pytest.approx(SIDE - step, abs=step)
    assert np.ptp(loaded.vertices[:, 2]) == pytest.approx(np.ptp(depth[::step, ::step]), rel=0.02)


def test_a_rerun_skips_the_finished_tiles(scene, result, tmp_path, monkeypatch):
    work = tmp_path / "work"
    solve = tiled._tile_depth
    calls = []

    def failing(image, options):
        if len(calls) == 5:
            raise RuntimeError("interrupted")
        calls.append(1)
        return solve(image, options)

    monkeypatch.setattr(tiled, "_tile_depth", failing)
    with pytest.raises(RuntimeError, match="interrupted"):
        tiled.reconstruct(scene.image, tile=TILE, overlap=OVERLAP, scheduler="synchronous", work=work)
    assert len(list(work.glob("*.npy"))) == 5

    def counting(image, options):
        calls.append(1)
        return solve(image, options)

    calls.clear()
    monkeypatch.setattr(tiled, "_tile_depth", counting)
    again = tiled.reconstruct(
        scene.image, tile=TILE, overlap=OVERLAP, scheduler="synchronous", work=work, keep_work=True
    )
    assert (again.solved, again.skipped, len(calls)) == (TILES - 5, 5, TILES - 5)
    np.testing.assert_allclose(again.depth, result.depth, atol=1e-5)
    # another tile size is another run: its tiles are not mixed with these
    with pytest.raises(InputError, match="another run"):
        tiled.reconstruct(scene.image, tile=2 * TILE, overlap=OVERLAP, scheduler="synchronous", work=work)


def test_on_a_cluster_of_worker_processes(result, geotiff, tmp_path):
    distributed = pytest.importorskip("distributed")
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=50
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        made = tiled.reconstruct(
            geotiff, tile=TILE, overlap=OVERLAP, scheduler=client, out=tmp_path / "d.tif"
        )
        workers = {w["id"] for w in client.scheduler_info()["workers"].values()}
    assert made.solved == TILES and len(workers) == 2
    local = tiled.reconstruct(geotiff, tile=TILE, overlap=OVERLAP, scheduler="synchronous")
    np.testing.assert_allclose(tifffile.imread(tmp_path / "d.tif"), local.depth, atol=1e-5)


@pytest.mark.parametrize(
    ("options", "fragment"),
    [
        ({"tile": 60}, "multiple of 16"),
        ({"overlap": 7}, "even"),
        ({"overlap": 200}, "overlap"),
        ({"out": "depth.png"}, "BigTIFF"),
        ({"light": "estimate"}, "direction"),
        ({"mask": np.ones((8, 8), bool)}, "whole frame"),
        ({"scheduler": "fastest"}, "scheduler"),
        ({"method": "magic"}, "method"),
    ],
)
def test_bad_options_are_one_line_input_errors(options, fragment):
    image = synth.bump_relief((64, 64), spacing=32).image
    with pytest.raises(InputError, match=fragment) as caught:
        tiled.reconstruct(image, **{"tile": 32, "overlap": 8, **options})
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
    for args in (["--tiles", "huge"], ["--tiles", "64", "--mask", str(geotiff)], ["--tiles", "24"]):
        bad = runner.invoke(app, ["reconstruct", str(geotiff), "-o", str(empty / "r.glb"), *args])
        assert bad.exit_code == 2, bad.output
        lines = bad.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in bad.output
    assert list(empty.iterdir()) == []
