"""Tests for ``fuse(..., surface="poisson")``: the screened Poisson surface of the placed views
(:mod:`shadeform.fusion.poisson`, the optional ``shadeform[fusion]`` extra with Open3D).

Without Open3D the option fails with one line naming the extra (library and CLI); with it, the
true depths of four turntable views fuse to the closed synthetic objects within the issue's bars,
scored as in ``test_fusion.py``.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

import shadeform
from helpers.fusion import SMALL, scores, true_views
from shadeform import synth
from shadeform.errors import InputError

ANGLES = (0, 90, 180, 270)


@pytest.fixture
def no_open3d(monkeypatch):
    """Open3D made unimportable, whether or not it is installed."""
    monkeypatch.setitem(sys.modules, "open3d", None)


class TestWithoutOpen3D:
    def test_fuse_names_the_extra(self, no_open3d):
        views = list(zip(true_views("ellipsoid", ANGLES, size=64), ANGLES))
        with pytest.raises(InputError) as caught:
            shadeform.fuse(views, surface="poisson")
        message = str(caught.value)
        assert "shadeform[fusion]" in message and "\n" not in message, message

    def test_cli_prints_one_line_and_exits_2(self, no_open3d, tmp_path):
        from PIL import Image
        from typer.testing import CliRunner

        from shadeform.cli import app

        names = []
        for view in synth.render_views("pebble", (0, 90), size=64):
            names.append(str(tmp_path / f"p{int(view.angle)}.png"))
            Image.fromarray(np.rint(np.array(view.image) * 255).astype(np.uint8)).save(names[-1])
        out = tmp_path / "model.glb"
        args = ["fuse", *names, "--angles", "0,90", "--surface", "poisson", "-o", str(out)]
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 2, result.output
        assert "shadeform[fusion]" in result.output and result.output.count("\n") == 1, result.output
        assert not out.exists()

    def test_an_open3d_that_does_not_load_says_why(self, monkeypatch):
        import builtins

        from shadeform.fusion.poisson import require_open3d

        real = builtins.__import__

        def broken(name, *args, **kwargs):
            if name == "open3d":
                # what Python raises when the extension's shared libraries are missing
                raise ImportError("libEGL.so.1: cannot open shared object file", name="open3d.pybind")
            return real(name, *args, **kwargs)

        monkeypatch.delitem(sys.modules, "open3d", raising=False)
        monkeypatch.setattr(builtins, "__import__", broken)
        with pytest.raises(InputError) as caught:
            require_open3d()
        message = str(caught.value)
        assert "does not load (libEGL.so.1" in message and "libegl1" in message and "\n" not in message

    def test_a_bad_surface_gets_one_line_listing_the_choices(self):
        views = list(zip(true_views("ellipsoid", ANGLES, size=64), ANGLES))
        with pytest.raises(InputError) as caught:
            shadeform.fuse(views, surface="marching")
        message = str(caught.value)
        assert "'marching'" in message and "volume, poisson" in message and "\n" not in message


class TestWithOpen3D:
    """Open3D is in the test extra (``shadeform[test]`` includes ``fusion``): these run in CI."""

    @pytest.mark.parametrize("name", ["ellipsoid", "pebble", "lumpy"])
    def test_true_depths_fuse_to_the_object(self, name):
        mesh = shadeform.fuse(list(zip(true_views(name, ANGLES), ANGLES)), surface="poisson")
        chamfer, fscore, volume, closed = scores(mesh, name, size=SMALL)
        assert closed
        assert chamfer <= 0.5 and fscore >= 95 and volume <= 3, (chamfer, fscore, volume)
        # outward normals: they point away from the object's centre
        outward = np.sum(mesh.normals * (mesh.vertices - mesh.vertices.mean(axis=0)), axis=1)
        assert np.mean(outward > 0) > 0.99

    def test_depth_is_about_one_cell_per_voxel_and_checked(self):
        from shadeform.fusion import place
        from shadeform.fusion.poisson import oriented_points, poisson_depth, poisson_solid

        placement = place(list(zip(true_views("ellipsoid", ANGLES, size=64), ANGLES)))
        points, normals = oriented_points(placement)
        assert np.allclose(np.linalg.norm(normals, axis=1), 1, atol=1e-6)
        # the ellipsoid's points span ~51 px at 64: 1.1 x that in 2**6 = 64 one-pixel cells
        assert poisson_depth(points, placement.grid, 1.1) == 6
        for depth in (1, 13, 6.5, True):
            with pytest.raises(InputError, match="depth must be a whole number from 2 to 12"):
                poisson_solid(placement, depth=depth)
        coarse = poisson_solid(placement, depth=4)
        fine = poisson_solid(placement, depth=6)
        assert len(coarse.faces) < len(fine.faces) / 4
