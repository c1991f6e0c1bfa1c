"""The numpy mesh renderer behind result.png."""

import numpy as np

from shadeform import reconstruct, synth, to_mesh
from shadeform.render import BACKGROUND, render_mesh, result_picture


def sphere_mesh(size=48):
    scene = synth.scene("sphere", size=size)
    return scene, to_mesh(reconstruct(scene.image, mask=scene.mask), step=1)


class TestRenderMesh:
    def test_shape_and_coverage(self):
        _, mesh = sphere_mesh()
        picture = render_mesh(mesh, 120, 160)
        assert picture.shape == (120, 160, 3) and picture.dtype == np.uint8
        covered = np.any(picture != BACKGROUND, axis=-1)
        # a disk seen at an angle fills a good part of the frame, and the corners stay empty
        assert 0.2 < covered.mean() < 0.8
        assert not covered[0, 0] and not covered[-1, -1]

    def test_lit_from_the_upper_left(self):
        _, mesh = sphere_mesh()
        gray = render_mesh(mesh, 100, 100, tilt_deg=0, turn_deg=0).astype(float).mean(axis=-1)
        assert gray[30:45, 30:45].mean() > gray[55:70, 55:70].mean()


class TestResultPicture:
    def test_three_panels_side_by_side(self):
        scene, mesh = sphere_mesh()
        rec = reconstruct(scene.image, mask=scene.mask)
        picture = result_picture(scene.image, rec.normals, mesh)
        assert picture.ndim == 3 and picture.shape[1] > 2.5 * picture.shape[0] * 0.8
