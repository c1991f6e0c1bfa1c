"""Tests for shadeform.relief (shadeform.solid): print-ready solids in millimetres, and ``shadeform relief``.

Every solid is checked by tools that did not make it: manifold3d (a valid manifold), trimesh
(watertight, consistently wound, positive volume), an edge count (no edge with other than two
triangles), and, for self-intersections, a brute-force test of every edge against every other
triangle plus the projection test a height-field solid allows (the top and the base each cover
the outline once). The real photographs are read from ``../shared/data/real``.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
import trimesh

import shadeform
from shadeform import synth
from shadeform.errors import InputError
from shadeform.solid import MIN_WALL_MM, Relief, check_options, compress_depth, relief

manifold3d = pytest.importorskip("manifold3d", reason="the print extra: pip install 'shadeform[print]'")
pytest.importorskip("fast_simplification", reason="the print extra: pip install 'shadeform[print]'")

VASE = dict(width_mm=100.0, height_mm=4.0, base_mm=2.0)


# ------------------------------------------------------------------------------- the checks


def edge_counts(faces):
    """How many triangles share each undirected edge."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return counts


def projected_areas(vertices, faces):
    a, b, c = (vertices[faces[:, k], :2] for k in range(3))
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))


def assert_valid_solid(mesh):
    """A slicer's checks: a valid manifold, watertight, no non-manifold edge, outward normals, and
    a height-field solid whose top and base each tile the same outline once (so no part of it
    passes through another)."""
    assert isinstance(mesh, Relief) and mesh.unit == "millimeter"
    solid = manifold3d.Manifold(
        manifold3d.Mesh(
            vert_properties=mesh.vertices.astype(np.float32), tri_verts=mesh.faces.astype(np.uint32)
        )
    )
    assert solid.status() == manifold3d.Error.NoError
    loaded = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    assert loaded.is_watertight and loaded.is_winding_consistent
    assert loaded.volume > 0  # outward: a positive enclosed volume
    assert loaded.volume == pytest.approx(solid.volume(), rel=1e-4)
    assert mesh.volume_mm3 == pytest.approx(loaded.volume, rel=1e-9)
    assert (edge_counts(mesh.faces) == 2).all()
    # the parts: top (above the base), base (z = 0), walls (vertical)
    corners = mesh.vertices[mesh.faces]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    base = (corners[..., 2] == 0).all(axis=1)
    flat = np.abs(normal[:, 2]) <= 1e-9 * np.linalg.norm(normal, axis=1)
    top = ~base & ~flat
    assert (mesh.vertices[:, 2] >= 0).all()
    assert (corners[top][..., 2] > 0).all() and (normal[top, 2] > 0).all() and (normal[base, 2] < 0).all()
    up = projected_areas(mesh.vertices, mesh.faces[top])
    down = -projected_areas(mesh.vertices, mesh.faces[base])
    assert up.min() > 0 and down.min() > 0
    assert up.sum() == pytest.approx(down.sum(), rel=1e-9)  # each covers the outline exactly once
    walls = mesh.faces[flat & ~base]
    assert np.abs(projected_areas(mesh.vertices, walls)).max(initial=0) < 1e-9


def self_intersections(vertices, faces):
    """Edges of the mesh that pierce a triangle they do not touch (brute force, Moller-Trumbore)."""
    edges = np.unique(
        np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1), axis=0
    )
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    e1, e2 = b - a, c - a
    scale = np.abs(vertices).max()
    found = 0
    for chunk in np.array_split(edges, max(1, len(edges) // 100)):
        p = vertices[chunk[:, 0]][:, None]
        d = vertices[chunk[:, 1]][:, None] - p
        h = np.cross(d, e2[None])
        det = np.einsum("ijk,jk->ij", h, e1)
        ok = np.abs(det) > 1e-12 * scale**2
        s = p - a[None]
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        u = np.einsum("ijk,ijk->ij", s, h) * inv
        q = np.cross(s, e1[None])
        v = np.einsum("ijk,ijk->ij", d, q) * inv
        t = np.einsum("jk,ijk->ij", e2, q) * inv
        eps = 1e-9
        hit = ok & (t > eps) & (t < 1 - eps) & (u > eps) & (v > eps) & (u + v < 1 - eps)
        touching = (chunk[:, None, :, None] == faces[None, :, None, :]).any(axis=(2, 3))
        found += int((hit & ~touching).sum())
    return found


def longest_side(mesh):
    return float(mesh.size_mm[:2].max())


@pytest.fixture(scope="module")
def vase():
    return synth.scene("vase", size=256)


@pytest.fixture(scope="module")
def vase_solid(vase):
    return relief(vase.depth, **VASE)


def sphere_depth(size=48):
    return synth.scene("sphere", size=size).depth


# ------------------------------------------------------------------------------- relief()


class TestRelief:
    def test_vase_bar(self, vase_solid):
        assert_valid_solid(vase_solid)
        assert longest_side(vase_solid) == pytest.approx(100.0, abs=0.05)
        assert vase_solid.size_mm[2] == pytest.approx(6.0, abs=0.05)
        assert vase_solid.vertices.min(axis=0) == pytest.approx([0, 0, 0], abs=1e-12)
        assert vase_solid.deviation_mm == 0.0

    def test_vase_as_3mf_loads_back_with_the_same_size(self, vase_solid, tmp_path):
        path = shadeform.export(vase_solid, tmp_path / "vase.3mf")
        loaded = trimesh.load(path, file_type="3mf", force="mesh", process=False)
        np.testing.assert_allclose(loaded.vertices, vase_solid.vertices, rtol=1e-7, atol=1e-6)
        np.testing.assert_array_equal(loaded.faces, vase_solid.faces)
        np.testing.assert_allclose(loaded.extents, vase_solid.size_mm, atol=1e-6)
        assert loaded.is_watertight and loaded.volume == pytest.approx(vase_solid.volume_mm3, rel=1e-6)
        with zipfile.ZipFile(path) as package:
            model = ET.fromstring(package.read("3D/3dmodel.model"))
        assert model.get("unit") == "millimeter"

    def test_the_solid_is_the_surface_on_walls_and_a_base(self, vase, vase_solid):
        # top vertices: every object pixel (bar the rows no cell reaches), at base + scaled depth
        top = vase_solid.vertices[vase_solid.vertices[:, 2] > 0]
        assert len(top) == len(vase_solid.vertices) // 2
        depth = vase.depth[np.isfinite(vase.depth)]
        assert top[:, 2].min() == pytest.approx(2.0) and top[:, 2].max() == pytest.approx(6.0)
        assert len(top) <= depth.size
        assert vase_solid.pixel_mm == pytest.approx(100.0 / (np.ptp(np.nonzero(vase.mask)[0])), rel=0.01)

    def test_reconstruction_in(self, sphere64):
        rec = shadeform.reconstruct(sphere64.image, refine=0)
        solid = shadeform.relief(rec, width_mm=40, height_mm=3, base_mm=1)
        assert_valid_solid(solid)
        assert longest_side(solid) == pytest.approx(40.0)
        assert solid.size_mm[2] == pytest.approx(4.0)

    def test_frame_is_the_whole_image(self):
        depth = sphere_depth(48)[:, 4:40]  # 48 rows, 36 columns
        solid = relief(depth, width_mm=60, height_mm=5, base_mm=2, outline="frame")
        assert_valid_solid(solid)
        np.testing.assert_allclose(solid.size_mm, [60 * 35 / 47, 60, 7])
        assert solid.pixel_mm == pytest.approx(60 / 47)

    def test_invert_engraves(self):
        depth = sphere_depth()
        raised = relief(depth, width_mm=50, height_mm=5, base_mm=2)
        engraved = relief(depth, width_mm=50, height_mm=5, base_mm=2, invert=True)
        assert_valid_solid(engraved)
        np.testing.assert_allclose(engraved.size_mm, raised.size_mm)
        top = raised.vertices[:, 2] > 0
        # same vertices, heights mirrored inside [base, base + height]
        np.testing.assert_allclose(engraved.vertices[top, 2], 2 + 7 - raised.vertices[top, 2])

    @pytest.mark.parametrize("outline", ["mask", "frame"])
    def test_border_is_a_flat_rim(self, outline):
        depth = sphere_depth()
        solid = relief(depth, width_mm=50, height_mm=5, base_mm=2, border_mm=4, outline=outline)
        assert_valid_solid(solid)
        assert longest_side(solid) == pytest.approx(50.0)
        plain = relief(depth, width_mm=50, height_mm=5, base_mm=2, outline=outline)
        # the object is smaller by the rim on each side, to within a pixel
        assert plain.pixel_mm * 50 / (50 - 8) == pytest.approx(solid.pixel_mm, abs=2 * solid.pixel_mm)
        # the rim: the top vertices within 4 mm of the outline lie at the base's level + 0
        top = solid.vertices[solid.vertices[:, 2] > 0]
        centre = solid.size_mm[:2] / 2
        outer = np.abs(top[:, :2] - centre).max(axis=1) > 25 - 3.5 if outline == "frame" else None
        if outer is None:
            radius = np.linalg.norm(top[:, :2] - centre, axis=1)
            outer = radius > radius.max() - 3.5
        assert top[outer, 2] == pytest.approx(2.0)

    def test_engraved_rim_is_the_top(self):
        solid = relief(sphere_depth(), width_mm=50, height_mm=5, base_mm=2, border_mm=4, invert=True)
        assert_valid_solid(solid)
        edge = solid.vertices[:, 0] == 0
        assert solid.vertices[edge, 2].max() == pytest.approx(7.0)

    def test_holes_and_several_parts(self):
        rows, cols = np.mgrid[:60, :90]
        ring = (np.hypot(rows - 30, cols - 30) < 25) & (np.hypot(rows - 30, cols - 30) > 10)
        blob = np.hypot(rows - 30, cols - 75) < 12
        depth = np.where(ring | blob, 10.0 + np.sin(rows / 5.0) * np.cos(cols / 7.0), np.nan)
        solid = relief(depth, width_mm=90, height_mm=3, base_mm=1)
        assert_valid_solid(solid)
        loaded = trimesh.Trimesh(solid.vertices, solid.faces, process=False)
        assert len(loaded.split(only_watertight=True)) == 2
        assert loaded.euler_number == 2 + 0  # a torus (0) and a ball (2)

    def test_cells_touching_at_a_corner_make_no_pinch(self):
        # a checkerboard of 2x2 blocks: every block meets its neighbours at corners only
        rows, cols = np.mgrid[:24, :24]
        board = ((rows // 3) + (cols // 3)) % 2 == 0
        depth = np.where(board, (rows + cols) / 8.0, np.nan)
        depth[6:15, 6:15] = 1.0 + np.arange(9)[None] / 4  # and a solid patch in the middle
        solid = relief(depth, width_mm=30, height_mm=2, base_mm=1)
        assert_valid_solid(solid)
        assert self_intersections(solid.vertices, solid.faces) == 0

    @pytest.mark.parametrize(
        "options",
        [
            dict(),
            dict(max_triangles=400),
            dict(max_triangles=60, outline="frame"),
            dict(compress=0.6, border_mm=3),
        ],
    )
    def test_no_self_intersection_brute_force(self, options):
        solid = relief(sphere_depth(20), width_mm=20, height_mm=4, base_mm=1, **options)
        assert_valid_solid(solid)
        assert self_intersections(solid.vertices, solid.faces) == 0

    def test_the_brute_force_finds_an_intersection(self):
        box = trimesh.creation.box()
        other = trimesh.creation.box()
        other.apply_translation([0.3, 0.2, 0.1])  # corners inside, edges off the diagonals
        both = trimesh.util.concatenate([box, other])
        assert self_intersections(np.asarray(both.vertices), np.asarray(both.faces)) > 0

    @pytest.mark.parametrize(
        "options",
        [
            dict(),
            dict(outline="frame"),
            dict(invert=True, border_mm=3),
            dict(compress=0.5),
            dict(max_triangles=20_000),
            dict(max_triangles=2_000, outline="frame", compress=0.3, invert=True, border_mm=2),
        ],
    )
    def test_sizes_are_exact_with_every_option(self, vase, options):
        solid = relief(vase.depth, **VASE, **options)
        assert_valid_solid(solid)
        assert longest_side(solid) == pytest.approx(100.0, abs=1e-9)
        assert solid.size_mm[2] == pytest.approx(6.0, abs=1e-9)
        if "max_triangles" in options:
            assert solid.n_faces <= options["max_triangles"]

    def test_budget(self, vase):
        solid = relief(vase.depth, **VASE, max_triangles=5_000)
        assert_valid_solid(solid)
        assert 4_500 <= solid.n_faces <= 5_000
        assert 0 < solid.deviation_mm < 0.5
        finer = relief(vase.depth, **VASE, max_triangles=50_000)
        assert finer.deviation_mm < solid.deviation_mm
        # a budget the full grid fits in changes nothing
        full = relief(vase.depth, **VASE)
        same = relief(vase.depth, **VASE, max_triangles=full.n_faces)
        np.testing.assert_array_equal(same.faces, full.faces)
        assert same.deviation_mm == 0

    def test_tiny_budget_still_closed(self, vase):
        solid = relief(vase.depth, **VASE, max_triangles=40)
        assert_valid_solid(solid)
        assert solid.n_faces <= 40

    def test_deviation_is_the_largest_distance_to_the_printed_top(self):
        depth = sphere_depth(40) + 0.0
        depth[np.isnan(depth)] = 0.0
        depth[10:14, 5:30] += 3.0  # a ledge: cliffs a vertical measure would overstate
        full = relief(depth, width_mm=40, height_mm=5, base_mm=2, outline="frame")
        budget = relief(depth, width_mm=40, height_mm=5, base_mm=2, outline="frame", max_triangles=300)
        assert full.pixel_mm == budget.pixel_mm  # same frame, same scale
        points = full.vertices[full.vertices[:, 2] > 0]  # the relief at every pixel
        top = budget.faces[(budget.vertices[budget.faces, 2] > 0).all(axis=1)]
        surface = trimesh.Trimesh(budget.vertices, top, process=False)
        _, distance, _ = trimesh.proximity.closest_point_naive(surface, points)
        assert budget.deviation_mm == pytest.approx(distance.max(), rel=1e-6)

    def test_print_extra_missing(self, vase, monkeypatch):
        import builtins

        real_import = builtins.__import__

        def no_simplifier(name, *args, **kwargs):
            if name.startswith("fast_simplification"):
                raise ImportError("No module named 'fast_simplification'", name="fast_simplification")
            return real_import(name, *args, **kwargs)

        monkeypatch.setattr(builtins, "__import__", no_simplifier)
        monkeypatch.setattr("importlib.util.find_spec", lambda name, *a: None)
        with pytest.raises(InputError, match=r"pip install 'shadeform\[print\]'"):
            relief(vase.depth, **VASE, max_triangles=1000)
        relief(vase.depth, **VASE)  # without a budget the extra is not needed

    @pytest.mark.parametrize(
        "options, message",
        [
            (dict(width_mm=0), "width_mm must be > 0"),
            (dict(width_mm=-5), "width_mm must be > 0"),
            (dict(height_mm=0), "height_mm must be > 0"),
            (dict(base_mm=-1), "base_mm must be > 0"),
            (dict(width_mm=float("nan")), "width_mm must be a finite number"),
            (dict(base_mm=0.5), "thinner than the thinnest wall"),
            (dict(base_mm=2, min_wall_mm=2.5), "thinner than the thinnest wall"),
            (dict(compress=1.5), r"compress must be in \[0, 1\]"),
            (dict(compress=-0.1), r"compress must be in \[0, 1\]"),
            (dict(border_mm=-1), "border_mm must be >= 0"),
            (dict(border_mm=50), "less than half of the width"),
            (dict(max_triangles=0), "max_triangles must be a whole number >= 12"),
            (dict(max_triangles=11), "max_triangles must be a whole number >= 12"),
            (dict(max_triangles=1e5), "max_triangles must be a whole number"),
            (dict(outline="box"), "unknown outline 'box'"),
        ],
    )
    def test_bad_options(self, options, message):
        with pytest.raises(InputError, match=message) as info:
            relief(sphere_depth(), **{**VASE, **options})
        assert "\n" not in str(info.value)

    def test_base_as_thick_as_the_thinnest_wall_is_fine(self):
        assert_valid_solid(relief(sphere_depth(), width_mm=30, height_mm=2, base_mm=MIN_WALL_MM))

    @pytest.mark.parametrize(
        "source, message",
        [
            (np.full((20, 20), 3.0), "flat"),
            (np.where(np.eye(20, dtype=bool), 1.0, np.nan), "no 2 x 2 block"),
            (np.zeros(20), "2-D array"),
            ([[1.0, 2.0], [3.0, 4.0]], "Reconstruction or a depth map"),
        ],
    )
    def test_bad_sources(self, source, message):
        with pytest.raises(InputError, match=message):
            relief(source, **VASE)

    def test_check_options_names_the_flags(self):
        with pytest.raises(InputError, match="--width must be > 0"):
            check_options(width_mm=0, height_mm=1, base_mm=1, names={"width_mm": "--width"})
        assert check_options(width_mm=10, height_mm=1, base_mm=1)["max_triangles"] is None

    def test_the_package_function_is_the_module_s(self):
        import shadeform.solid as module

        assert shadeform.relief is module.relief and callable(shadeform.relief)


# ------------------------------------------------------------------------- compress_depth()


def step_with_bumps(bumps=True):
    """A 60-pixel depth jump across the middle (a steep ramp 6 pixels wide) and four small bumps
    (amplitude 1, sigma 4 pixels), two on each side: what bas-relief is for."""
    rows, cols = np.mgrid[:96, :192].astype(float)
    depth = 60.0 / (1 + np.exp(-(cols - 96) / 1.5))
    centres = [(30, 40), (66, 60), (30, 140), (66, 160)]
    if bumps:
        depth += sum(np.exp(-((rows - r) ** 2 + (cols - c) ** 2) / (2 * 4.0**2)) for r, c in centres)
    return depth, centres


def bump_share(height, centres):
    """Each bump's height above the ring around it, as a share of the whole height's range."""
    rows, cols = np.indices(height.shape)
    height = (height - np.nanmin(height)) / np.nanmax(height - np.nanmin(height))
    shares = []
    for r, c in centres:
        ring = (np.hypot(rows - r, cols - c) > 12) & (np.hypot(rows - r, cols - c) < 16)
        shares.append(height[r, c] - height[ring].mean())
    return np.array(shares)


class TestCompress:
    def test_zero_is_the_depth(self):
        depth, _ = step_with_bumps()
        mask = np.ones(depth.shape, dtype=bool)
        np.testing.assert_array_equal(compress_depth(depth, mask, compress=0), depth)

    def test_a_ramp_is_left_alone(self):
        # every slope is the mean slope: nothing to compress; the integration gives it back
        rows, cols = np.mgrid[:40, :50].astype(float)
        ramp = 0.7 * cols - 0.2 * rows
        mask = np.hypot(rows - 20, cols - 25) < 18
        out = compress_depth(ramp, mask, compress=0.8)
        assert np.isnan(out[~mask]).all()
        np.testing.assert_allclose(out[mask], ramp[mask], atol=1e-6)

    def test_fine_detail_survives_better_than_linear_scaling(self):
        depth, centres = step_with_bumps()
        mask = np.ones(depth.shape, dtype=bool)
        linear = bump_share(depth, centres)
        compressed = bump_share(compress_depth(depth, mask, compress=0.5), centres)
        assert linear == pytest.approx(1 / 61, rel=0.05)  # 1 of 60 + 1
        assert (compressed > 3.5 * linear).all()
        stronger = bump_share(compress_depth(depth, mask, compress=1.0), centres)
        assert (stronger > 2 * compressed).all()

    def test_bumps_keep_their_shape(self):
        depth, centres = step_with_bumps()
        plain, _ = step_with_bumps(bumps=False)
        mask = np.ones(depth.shape, dtype=bool)
        detail = compress_depth(depth, mask, compress=0.5) - compress_depth(plain, mask, compress=0.5)
        truth = depth - plain
        near = truth > 0.05
        assert np.corrcoef(detail[near], truth[near])[0, 1] > 0.95

    def test_in_the_solid(self):
        depth, centres = step_with_bumps()
        plain = relief(depth, width_mm=100, height_mm=5, base_mm=2, outline="frame")
        bas = relief(depth, width_mm=100, height_mm=5, base_mm=2, outline="frame", compress=0.5)
        assert_valid_solid(bas)
        shape = depth.shape
        share = [
            bump_share((s.vertices[s.vertices[:, 2] > 0, 2]).reshape(shape), centres) for s in (plain, bas)
        ]
        assert (share[1] > 3.5 * share[0]).all()

    def test_parts_keep_their_offsets(self):
        depth = np.full((30, 60), np.nan)
        depth[5:25, 5:25] = 10.0 + np.arange(20)[None] * 0.1
        depth[5:25, 35:55] = 30.0 + np.arange(20)[None] * 0.1
        mask = np.isfinite(depth)
        out = compress_depth(depth, mask, compress=0.5)
        assert np.nanmean(out[:, 35:]) > np.nanmean(out[:, :30])


# ------------------------------------------------------------------------------ real photos


class TestRealPhotos:
    @pytest.mark.parametrize(
        "name, method, options",
        [
            ("diligent/reading", "auto", dict()),
            ("diligent/cat", "propagation", dict(max_triangles=20_000, compress=0.4)),
            ("diligent/buddha", "propagation", dict(border_mm=2, invert=True)),
            ("mit/deer", "propagation", dict(outline="frame", max_triangles=5_000)),
            ("mit/raccoon", "propagation", dict(compress=0.3, border_mm=1.5)),
        ],
    )
    def test_valid_solids(self, real_data, name, method, options):
        kind, object_name = name.split("/")
        case = real_data.diligent(object_name) if kind == "diligent" else real_data.mit(object_name)
        rec = shadeform.reconstruct(case.image, light=case.light, mask=case.mask, solver=method, refine=0)
        solid = shadeform.relief(rec, width_mm=80, height_mm=5, base_mm=1.5, **options)
        assert_valid_solid(solid)
        assert longest_side(solid) == pytest.approx(80.0)
        assert solid.size_mm[2] == pytest.approx(6.5)


# ------------------------------------------------------------------------------------- CLI


@pytest.fixture(scope="module")
def vase_png(tmp_path_factory):
    from PIL import Image

    path = tmp_path_factory.mktemp("photos") / "vase.png"
    image = synth.scene("vase", size=128).image
    Image.fromarray(np.round(image * 65535).astype(np.uint16)).save(path)
    return path


class TestCli:
    def test_vase_bar(self, cli, vase_png, out):
        target = out / "vase.stl"
        result = cli("relief", vase_png, "-o", target, "--width", 100, "--height", 4, "--base", 2)
        assert result.exit_code == 0, result.output
        assert "100.00" in result.stdout and "6.00 mm" in result.stdout
        assert "volume" in result.stdout and "triangles" in result.stdout
        assert [p.name for p in out.iterdir()] == ["vase.stl"]
        loaded = trimesh.load(target, process=True)  # STL: merge the repeated corners
        assert loaded.is_watertight and loaded.is_winding_consistent and loaded.volume > 0
        assert loaded.extents[:2].max() == pytest.approx(100.0, abs=0.05)
        assert loaded.extents[2] == pytest.approx(6.0, abs=0.05)
        assert target.read_bytes()[:80].rstrip() == b"shadeform mesh, units: millimeter"

    def test_3mf_with_options_and_json(self, cli, vase_png, out):
        target = out / "vase.3mf"
        result = cli(
            "relief", vase_png, "-o", target, "--compress", 0.3, "--invert", "--border", 3,
            "--max-triangles", 5000, "--depth", out / "depth.npy", "--json",
        )  # fmt: skip
        assert result.exit_code == 0, result.output
        report = json.loads(result.stdout)["solid"]
        assert report["triangles"] <= 5000 and report["volume_mm3"] > 0
        assert max(report["size_mm"][:2]) == pytest.approx(100.0) and report["size_mm"][2] == pytest.approx(
            6.0
        )
        assert report["deviation_mm"] > 0
        loaded = trimesh.load(target, file_type="3mf", force="mesh", process=False)
        assert loaded.is_watertight and len(loaded.faces) == report["triangles"]
        assert sorted(p.name for p in out.iterdir()) == ["depth.npy", "vase.3mf"]

    def test_a_budget_solves_only_its_grid(self, cli, out):
        """With --max-triangles only the grid the budget samples is solved (grid_step); the solid
        matches the one from every pixel (--full-resolution) to a small share of its depth."""
        from PIL import Image

        from shadeform.solid import grid_step

        scene = synth.scene("vase", size=256)
        photo, concave = out.parent / "vase256.png", out.parent / "neck.json"
        Image.fromarray(np.round(scene.image * 65535).astype(np.uint16)).save(photo)
        concave.write_text(json.dumps(synth.concave_regions("vase", size=256)))
        reports, solids = {}, {}
        for how in ("grid", "full"):
            target = out / f"{how}.stl"
            flags = ["--full-resolution"] if how == "full" else []
            result = cli(
                "relief", photo, "-o", target, "--max-triangles", 1000, "--concave", concave, "--json", *flags
            )  # fmt: skip
            assert result.exit_code == 0, result.output
            reports[how] = json.loads(result.stdout)["solid"]
            solids[how] = trimesh.load(target, process=True)
        assert reports["grid"]["solved_step"] == grid_step(int(scene.mask.sum()), 1000) >= 2
        assert reports["full"]["solved_step"] == 1
        for how in ("grid", "full"):
            assert reports[how]["triangles"] <= 1000
            assert solids[how].is_watertight and solids[how].volume > 0
            assert solids[how].extents[:2].max() == pytest.approx(100.0, abs=0.05)
            assert solids[how].extents[2] == pytest.approx(6.0, abs=0.05)
        # one input pixel is the same size in both; the surfaces agree (heights sampled on a raster)
        assert reports["grid"]["pixel_mm"] == pytest.approx(reports["full"]["pixel_mm"], rel=0.02)
        # the top surface, interpolated on its own triangles (matplotlib's), at points inside
        from matplotlib.tri import LinearTriInterpolator, Triangulation

        x, y = np.meshgrid(np.linspace(20, 35, 6), np.linspace(20, 80, 13))
        tops = []
        for how in ("grid", "full"):
            mesh = solids[how]
            up = mesh.faces[
                (mesh.face_normals[:, 2] > 0.01) & (mesh.vertices[mesh.faces, 2].min(axis=1) > 1.0)
            ]
            flat = Triangulation(mesh.vertices[:, 0], mesh.vertices[:, 1], up)
            tops.append(np.ma.filled(LinearTriInterpolator(flat, mesh.vertices[:, 2])(x, y), np.nan).ravel())
        both = np.isfinite(tops[0]) & np.isfinite(tops[1])
        assert both.sum() > 40
        # solving only the grid moves the surface less than the budget's simplification does
        gap = np.abs(tops[0] - tops[1])[both]
        assert gap.max() < min(reports["grid"]["deviation_mm"], reports["full"]["deviation_mm"])
        assert gap.mean() < 0.05  # mm, of a 4 mm relief
        assert solids["grid"].volume == pytest.approx(solids["full"].volume, rel=0.02)

    @pytest.mark.parametrize(
        "args, message",
        [
            (["--width", "0"], "--width must be > 0"),
            (["--width", "-10"], "--width must be > 0"),
            (["--height", "0"], "--height must be > 0"),
            (["--base", "-2"], "--base must be > 0"),
            (["--base", "0.5"], "thinner than the thinnest wall"),
            (["--base", "1", "--min-wall", "1.2"], "thinner than the thinnest wall"),
            (["--max-triangles", "0"], "--max-triangles must be a whole number >= 12"),
            (["--compress", "1.5"], "--compress must be in"),
            (["--border", "50"], "--border must be"),
            (["--outline", "circle"], "unknown --outline"),
            (["-o", "{out}/relief.xyz"], "cannot write a mesh to"),
        ],
    )
    def test_bad_requests(self, cli, vase_png, out, args, message):
        args = [arg.format(out=out) for arg in args]
        if "-o" not in args:
            args += ["-o", str(out / "relief.stl")]
        result = cli("relief", vase_png, *args)
        assert result.exit_code == 2
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], result.stderr
        assert list(out.iterdir()) == []
