"""Texture maps (``shadeform.texture``) against shapes whose maps are known exactly."""

from __future__ import annotations

import numpy as np
import pytest

import shadeform
from shadeform import synth, texture
from shadeform.errors import InputError


def test_the_compiled_occlusion_matches_the_reference():
    rng = np.random.default_rng(0)
    depth = np.cumsum(rng.normal(size=(24, 30)), axis=1) + 3 * rng.normal(size=(24, 30))
    mask = np.ones(depth.shape, dtype=bool)
    mask[:4, :7] = False
    mask[15:, 20:] = False
    fast = texture.ambient_occlusion(depth, mask, reach=9.0)
    slow = texture.ambient_occlusion_reference(depth, mask, reach=9.0)
    np.testing.assert_allclose(fast, slow, atol=1e-12)
    assert fast[mask].min() < 0.8 and (fast[~mask] == 1).all()


def test_occlusion_in_a_v_groove_is_the_analytic_sky_fraction():
    """At the bottom of a long groove with 45-degree walls the horizon along azimuth ``phi``
    (from the groove's normal) rises at ``tan h = |cos phi|``: the visible fraction is the mean
    of ``1 / (1 + cos^2 phi)``, ``1 / sqrt(2)`` over all azimuths; a plane sees the whole sky."""
    rows, cols = 81, 81
    x = np.arange(cols) - 40.0
    depth = np.tile(np.abs(x), (rows, 1))  # walls rise 1 pixel per pixel away from column 40
    mask = np.ones((rows, cols), dtype=bool)
    ao = texture.ambient_occlusion(depth, mask, reach=30.0)
    phi = 2 * np.pi * np.arange(texture.DIRECTIONS) / texture.DIRECTIONS
    expected = np.mean(1.0 / (1.0 + np.cos(phi) ** 2))
    assert ao[40, 40] == pytest.approx(expected, abs=1e-9)
    assert expected == pytest.approx(1 / np.sqrt(2), abs=1e-3)
    flat = texture.ambient_occlusion(np.full((20, 20), 3.0), np.ones((20, 20), dtype=bool), reach=8)
    assert (flat == 1.0).all()


def test_curvature_of_a_sphere_is_two_over_its_radius():
    scene = synth.scene("sphere", size=128)
    k = texture.curvature(scene.normals, scene.mask)
    radius = np.sqrt(scene.mask.sum() / np.pi)
    inner = scene.mask & (scene.normals[..., 2] > 0.7)
    assert np.median(k[inner]) == pytest.approx(2 / radius, rel=0.03)
    bowl = synth.scene("bowl", size=128)  # concave toward the viewer
    assert np.median(texture.curvature(bowl.normals, bowl.mask)[bowl.mask]) < 0


def test_maps_of_a_reconstruction():
    scene = synth.scene("sphere", size=96)
    rec = shadeform.reconstruct(scene.image)
    maps = shadeform.maps(rec)
    assert tuple(maps) == texture.MAPS
    for name, image in maps.items():
        assert image.shape[:2] == scene.image.shape and np.isfinite(image).all(), name
        assert image.min() >= 0 and image.max() <= 1, name
    inside = rec.mask
    top = (20, 48)  # the sphere's upper part faces up: +y, green above half in OpenGL
    assert inside[top] and maps["normal_opengl"][top][1] > 0.7
    np.testing.assert_allclose(maps["normal_directx"][..., 1], 1 - maps["normal_opengl"][..., 1])
    np.testing.assert_allclose(maps["normal_directx"][..., [0, 2]], maps["normal_opengl"][..., [0, 2]])
    height = maps["height"][inside]
    assert height.min() == 0 and height.max() == 1
    assert maps["height"][48, 48] > 0.9  # the centre is the top of the dome
    assert (maps["ambient_occlusion"][~inside] == 1).all() and maps["ambient_occlusion"][inside].min() > 0.5
    assert np.median(maps["curvature"][inside]) > 0.5  # convex


def test_a_reconstruction_without_object_is_refused():
    class Empty:
        normals = np.full((4, 4, 3), np.nan)
        depth = np.full((4, 4), np.nan)
        mask = np.zeros((4, 4), dtype=bool)

    with pytest.raises(InputError, match="no object pixels"):
        texture.maps(Empty())
    with pytest.raises(InputError, match="reach"):
        texture.ambient_occlusion(np.zeros((4, 4)), np.ones((4, 4), dtype=bool), reach=0.5)


class TestMaterial:
    """Material mode: photos of a textured surface filling the frame."""

    @staticmethod
    def photo(light, *, seed=0, size=128):
        from shadeform.light import light_from_slant_tilt

        height, truth = synth.material_surface(size, seed=seed)
        image = synth.render(truth, np.ones((size, size), dtype=bool), light=light_from_slant_tilt(*light),
                             albedo=0.7, noise=0.01, seed=seed)  # fmt: skip
        y, x = np.mgrid[:size, :size] / (size - 1) - 0.5
        return image * np.exp(0.4 * x - 0.3 * y - 0.5 * (x * x + y * y)), truth  # a lighting gradient

    def test_normals_from_shading_under_a_given_light(self):
        from shadeform.light import light_from_slant_tilt

        for light in ((45, 135), (60, 20)):
            image, truth = self.photo(light)
            result = texture.material(image, light=light_from_slant_tilt(*light))
            error = np.degrees(
                np.arccos(np.clip(np.sum((result.maps["normal_opengl"] * 2 - 1) * truth, -1), -1, 1))
            )
            flat = np.degrees(np.arccos(truth[..., 2]))
            assert error.mean() < 0.5 * flat.mean(), (light, error.mean(), flat.mean())
            assert not result.light_estimated and set(result.maps) == {*texture.MAPS, "albedo"}

    def test_the_light_axis_is_read_and_its_side_taken_from_above(self):
        for tilt in (60, 135, 300):
            image, _ = self.photo((45, tilt), seed=1)
            result = texture.material(image)
            read = np.degrees(np.arctan2(result.light[1], result.light[0])) % 360
            axis_error = min(abs(read - tilt) % 180, 180 - abs(read - tilt) % 180)
            assert axis_error < 10, (tilt, read)
            assert result.light_estimated and result.light[1] > 0  # above: tilt 300 comes out as 120
            assert result.light[2] == pytest.approx(np.cos(np.radians(texture.MATERIAL_SLANT)))

    def test_maps_tile_without_seams(self):
        image, _ = self.photo((45, 100))
        result = texture.material(image, light=[-0.1, 0.7, 0.7], tile=True)
        for name in ("height", "albedo", "normal_opengl"):
            values = result.maps[name]
            across = np.abs(values[:, 0] - values[:, -1]).mean() + np.abs(values[0] - values[-1]).mean()
            inside = np.abs(np.diff(values, axis=1)).mean() + np.abs(np.diff(values, axis=0)).mean()
            assert across < 1.5 * inside, name  # an edge pair is no more different than neighbours
        # the raw photo's lighting gradient makes its opposite edges differ far more
        raw = np.abs(image[:, 0] - image[:, -1]).mean()
        assert raw > 3 * np.abs(np.diff(image, axis=1)).mean()

    def test_the_periodic_component_removes_only_a_harmonic_field(self):
        rng = np.random.default_rng(3)
        image = rng.normal(size=(40, 56)) + np.linspace(0, 5, 56)  # noise on a ramp
        smooth = image - texture.periodic_component(image)
        inner = smooth[1:-1, 1:-1]
        laplacian = smooth[:-2, 1:-1] + smooth[2:, 1:-1] + smooth[1:-1, :-2] + smooth[1:-1, 2:] - 4 * inner
        assert np.abs(laplacian).max() < 1e-10

    def test_what_it_cannot_do_is_refused(self):
        image, _ = self.photo((45, 100))
        with pytest.raises(InputError, match="oblique light"):
            texture.material(image, light=[0, 0, 1])
        with pytest.raises(InputError, match="mostly black"):
            texture.material(np.zeros((32, 32)))
        with pytest.raises(InputError, match="at least 8x8"):
            texture.material(np.ones((4, 40)))
