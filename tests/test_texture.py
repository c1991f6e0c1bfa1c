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
