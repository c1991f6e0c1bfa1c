"""Tests for shadeform.io.exporters: every registered format, read back by an independent reader.

Readers: Open Inventor's own ``ivinfo``/``ivcat`` for ``.iv``; three.js's ``VRMLLoader`` under
Node (``tests/js/check_vrml.mjs``) for ``.wrl``; trimesh's loaders for the formats it writes.
The round trip test loops over the registry, so a new format is tested as soon as it is
registered (with trimesh's loader unless a reader is added to ``READERS``).
"""

from __future__ import annotations

import json
import re
import shutil
import zipfile

import numpy as np
import pytest
import trimesh

from helpers.readers import (
    IVINFO_MISSING,
    check_inventor,
    check_vrml,
    require,
    run_tool,
    run_vrml_loader,
)
from shadeform.errors import InputError
from shadeform.io import exporters
from shadeform.io.exporters import available_formats, export, register
from shadeform.mesh import Mesh, to_mesh
from shadeform.reconstruction import Reconstruction


def hemisphere_mesh(step=2):
    """A hemisphere of radius 18 pixels on a disk mask, meshed every ``step`` pixels."""
    rows, cols = np.mgrid[:41, :41].astype(float)
    dx, dy = cols - 20, -(rows - 20)
    mask = dx**2 + dy**2 < 18.0**2
    depth = np.where(mask, np.sqrt(np.maximum(18.0**2 - dx**2 - dy**2, 0)), np.nan)
    normals = np.where(mask[..., None], np.stack([dx, dy, depth], -1) / 18.0, np.nan)
    return to_mesh(Reconstruction(normals, depth, mask, np.array([0, 0, 1.0]), 1.0), step=step)


@pytest.fixture(scope="module")
def mesh():
    return hemisphere_mesh()


def fewer_faces(mesh):
    """The same vertices with the last triangle dropped: a reader's check must notice."""
    return Mesh(mesh.vertices, mesh.faces[:-1], mesh.normals, mesh.uv)


def face_normals(vertices, faces):
    corners = vertices[faces]
    return np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])


# ------------------------------------------------------------------- trimesh's own loaders


def load_single(path):
    loaded = trimesh.load(path, process=False)
    if isinstance(loaded, trimesh.Scene):
        assert len(loaded.geometry) == 1
        loaded = next(iter(loaded.geometry.values()))
    return loaded


def check_with_trimesh(path, mesh):
    loaded = load_single(path)
    assert len(loaded.vertices) == mesh.n_vertices
    assert len(loaded.faces) == mesh.n_faces
    np.testing.assert_allclose(loaded.vertices, mesh.vertices, rtol=1e-6, atol=1e-5)
    np.testing.assert_array_equal(loaded.faces, mesh.faces)
    # normals read from the file (trimesh keeps them in its cache), not recomputed
    assert "vertex_normals" in loaded._cache.cache
    np.testing.assert_allclose(loaded.vertex_normals, mesh.normals, atol=1e-6)


def check_glb(path, mesh):
    check_with_trimesh(path, mesh)
    if mesh.uv is not None:
        np.testing.assert_allclose(load_single(path).visual.uv, mesh.uv, atol=1e-6)


def check_stl(path, mesh):
    # STL repeats the corners of every triangle: compare faces, bounds and stored face normals
    loaded = load_single(path)
    assert len(loaded.faces) == mesh.n_faces
    assert len(loaded.vertices) == 3 * mesh.n_faces
    bounds = [mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)]
    np.testing.assert_allclose(loaded.bounds, bounds, atol=1e-4)
    stored = loaded.face_normals
    expected = face_normals(mesh.vertices, mesh.faces)
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(stored, expected, atol=1e-5)
    assert (stored[:, 2] > 0).all()


def model_unit(path):
    """The ``unit`` attribute of a 3MF package's model, read with the standard library."""
    import xml.etree.ElementTree as ET

    with zipfile.ZipFile(path) as package:
        names = set(package.namelist())
        assert {"[Content_Types].xml", "_rels/.rels", "3D/3dmodel.model"} <= names
        root = ET.fromstring(package.read("3D/3dmodel.model"))
    assert root.tag == "{http://schemas.microsoft.com/3dmanufacturing/core/2015/02}model"
    return root.get("unit")


def check_3mf(path, mesh):
    # trimesh's 3MF reader (lxml): vertices and triangles in the file's order; 3MF has no normals
    loaded = trimesh.load(path, file_type="3mf", force="mesh", process=False)
    assert len(loaded.vertices) == mesh.n_vertices
    assert len(loaded.faces) == mesh.n_faces
    np.testing.assert_allclose(loaded.vertices, mesh.vertices, rtol=1e-7, atol=1e-6)
    np.testing.assert_array_equal(loaded.faces, mesh.faces)
    assert model_unit(path) == "millimeter"


READERS = {
    ".3mf": check_3mf,
    ".iv": check_inventor,
    ".wrl": check_vrml,
    ".obj": check_with_trimesh,
    ".ply": check_with_trimesh,
    ".glb": check_glb,
    ".stl": check_stl,
}


def reader_for(suffix):
    if suffix in READERS:
        return READERS[suffix]
    if suffix.lstrip(".") in trimesh.available_formats():
        return check_with_trimesh
    pytest.fail(f"no independent reader for {suffix}; add one to READERS in {__file__}")


class TestExport:
    @pytest.mark.parametrize("suffix", sorted(available_formats()))
    def test_round_trip_with_independent_reader(self, tmp_path, mesh, suffix):
        path = export(mesh, tmp_path / f"mesh{suffix}")
        assert path == tmp_path / f"mesh{suffix}" and path.stat().st_size > 0
        reader_for(suffix)(path, mesh)
        assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]

    @pytest.mark.parametrize("suffix", sorted(available_formats()))
    def test_reader_notices_a_wrong_mesh(self, tmp_path, mesh, suffix):
        path = export(mesh, tmp_path / f"mesh{suffix}")
        with pytest.raises(AssertionError):
            reader_for(suffix)(path, fewer_faces(mesh))

    @pytest.mark.parametrize("suffix", sorted(available_formats()))
    def test_round_trip_without_uv(self, tmp_path, suffix):
        textured = hemisphere_mesh(step=3)
        plain = Mesh(textured.vertices, textured.faces, textured.normals)
        reader_for(suffix)(export(plain, tmp_path / f"plain{suffix}"), plain)

    def test_suffix_is_case_insensitive(self, tmp_path, mesh):
        path = export(mesh, tmp_path / "MESH.WRL")
        assert path.name == "MESH.WRL"
        assert path.read_bytes().startswith(b"#VRML V2.0 utf8\n")

    @pytest.mark.parametrize("name", ["mesh.xyz", "mesh", "mesh.wrl.bak"])
    def test_unknown_suffix_is_input_error_and_creates_nothing(self, tmp_path, mesh, name):
        with pytest.raises(InputError) as info:
            export(mesh, tmp_path / name)
        message = str(info.value)
        assert "\n" not in message
        for suffix in available_formats():
            assert suffix in message
        assert list(tmp_path.iterdir()) == []

    def test_missing_folder_is_input_error(self, tmp_path, mesh):
        with pytest.raises(InputError, match="does not exist; create it first"):
            export(mesh, tmp_path / "missing" / "mesh.iv")

    def test_failure_mid_write_keeps_the_old_file(self, tmp_path, mesh):
        target = tmp_path / "model.wrl"
        export(mesh, target)
        good = target.read_bytes()

        def write_half_then_fail(mesh, file_obj):
            file_obj.write(b"#VRML V2.0 utf8\nShape { geometry IndexedFaceSet { coord")
            raise OSError("disk full")

        with exporters.EXPORTERS.restored(), pytest.raises(OSError, match="disk full"):
            register(".wrl", write_half_then_fail, description="fails half way")
            export(hemisphere_mesh(3), target)
        assert available_formats()[".wrl"].startswith("VRML")  # the registry as it was
        assert target.read_bytes() == good
        assert sorted(p.name for p in tmp_path.iterdir()) == ["model.wrl"]

    def test_not_a_mesh_is_type_error(self, tmp_path):
        with pytest.raises(TypeError, match="Mesh"):
            export(np.zeros((3, 3)), tmp_path / "x.wrl")


def stated_unit(path):
    """The unit a file says its coordinates are in, read the way each format keeps it."""
    data = path.read_bytes()
    suffix = path.suffix
    if suffix == ".3mf":
        return model_unit(path)
    if suffix == ".glb":
        length = int.from_bytes(data[12:16], "little")
        return json.loads(data[20 : 20 + length])["asset"]["extras"]["unit"]
    if suffix == ".stl":
        return re.fullmatch(rb"shadeform mesh, units: (\w+) *", data[:80]).group(1).decode()
    if suffix == ".ply":
        header = data[: data.index(b"end_header")].decode("ascii")
        return re.search(r"^comment units: (\w+)$", header, flags=re.MULTILINE).group(1)
    return re.search(r"^# .*units: (\w+)$", data.decode("ascii"), flags=re.MULTILINE).group(1)


class TestUnits:
    @pytest.mark.parametrize("suffix", sorted(available_formats()))
    @pytest.mark.parametrize("unit", ["pixel", "millimeter"])
    def test_every_format_states_its_unit(self, tmp_path, mesh, suffix, unit):
        scaled = Mesh(mesh.vertices, mesh.faces, mesh.normals, mesh.uv, unit=unit)
        path = export(scaled, tmp_path / f"mesh{suffix}")
        if suffix == ".3mf":  # 3MF has no pixel: one pixel is written as one millimetre
            assert stated_unit(path) == "millimeter"
            with zipfile.ZipFile(path) as package:
                text = package.read("3D/3dmodel.model").decode()
            assert ("coordinates in pixels" in text) is (unit == "pixel")
        else:
            assert stated_unit(path) == unit
        reader_for(suffix)(path, scaled)  # and the file still reads back as before

    def test_meshes_are_in_pixels_unless_told(self, mesh):
        assert mesh.unit == "pixel"
        with pytest.raises(InputError, match="mesh unit must be one of"):
            Mesh(mesh.vertices, mesh.faces, mesh.normals, unit="inch")


class TestAvailableFormats:
    def test_smoke(self):
        formats = available_formats()
        assert {".wrl", ".iv", ".obj", ".ply", ".stl", ".glb"} <= set(formats)
        assert all(isinstance(d, str) and d and "\n" not in d for d in formats.values())

    def test_returns_a_copy(self):
        available_formats().clear()
        assert ".wrl" in available_formats()


class TestRegister:
    @pytest.fixture(autouse=True)
    def _restored(self):
        with exporters.EXPORTERS.restored():
            yield

    def test_registered_format_is_listed_and_written(self, tmp_path, mesh):
        def write_counts(mesh, file_obj):
            file_obj.write(f"{mesh.n_vertices} {mesh.n_faces}\n".encode())

        register("CNT", write_counts, description="vertex and face counts")
        assert available_formats()[".cnt"] == "vertex and face counts"
        path = export(mesh, tmp_path / "m.Cnt")
        assert path.read_text() == f"{mesh.n_vertices} {mesh.n_faces}\n"
        assert exporters.EXPORTERS.get(".cnt").writer is write_counts

    def test_bad_suffix_is_rejected(self):
        with pytest.raises(ValueError, match="suffix"):
            register(".", lambda mesh, f: None, description="nothing")


class TestVrmlWriter:
    def test_header_and_structure(self, tmp_path, mesh):
        text = export(mesh, tmp_path / "m.wrl").read_text(encoding="utf-8")
        assert text.startswith("#VRML V2.0 utf8\n")
        for token in (
            "Material",
            "IndexedFaceSet",
            "coord Coordinate",
            "normal Normal",
            "normalPerVertex TRUE",
            "solid FALSE",
            "creaseAngle",
            "texCoord TextureCoordinate",
        ):
            assert token in text
        assert text.count("-1") >= mesh.n_faces
        assert "nan" not in text.lower()

    def test_vrml_loader_rejects_malformed_files(self, tmp_path, mesh):
        text = export(mesh, tmp_path / "m.wrl").read_text()
        broken = {
            "truncated.wrl": text[: len(text) // 2],
            "brace.wrl": text.replace("IndexedFaceSet {", "IndexedFaceSet", 1),
            "bracket.wrl": text.replace("coordIndex [", "coordIndex", 1),
        }
        for name, content in broken.items():
            (tmp_path / name).write_text(content)
            done = run_vrml_loader(tmp_path / name)
            assert done.returncode != 0, name
            assert "VRMLLoader failed" in done.stderr, name


class TestInventorWriter:
    def test_header_and_structure(self, tmp_path, mesh):
        text = export(mesh, tmp_path / "m.iv").read_text(encoding="ascii")
        assert text.startswith("#Inventor V2.1 ascii\n")
        assert text.count("{") == text.count("}")
        for token in ("Coordinate3", "NormalBinding", "PER_VERTEX_INDEXED", "COUNTERCLOCKWISE"):
            assert token in text

    def test_ivinfo_and_ivcat_reject_malformed_files(self, tmp_path, mesh):
        require(shutil.which("ivinfo") is not None, IVINFO_MISSING)
        text = export(mesh, tmp_path / "m.iv").read_text()
        broken = {
            "truncated.iv": text[: len(text) // 2],
            "brace.iv": text.replace("IndexedFaceSet {", "IndexedFaceSet", 1),
            "field.iv": text.replace("point [", "pointz [", 1),
        }
        for name, content in broken.items():
            (tmp_path / name).write_text(content)
            info = run_tool("ivinfo", str(tmp_path / name))
            assert info.returncode != 0 and "read error" in info.stderr, name
            cat = run_tool("ivcat", str(tmp_path / name))
            assert cat.returncode != 0 and "read error" in cat.stderr, name
