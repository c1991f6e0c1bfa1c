"""The 2002 propagation solver: gradient, per-pixel rule, compiled kernel vs reference, refinement."""

import numpy as np
import pytest

from shadeform import metrics, synth
from shadeform.errors import InputError
from shadeform.light import light_from_slant_tilt
from shadeform.solvers.propagation import (
    image_gradient,
    project_to_cone,
    propagate_normals,
    propagate_normals_reference,
    refine_by_integrability,
)

Z = np.array([0.0, 0.0, 1.0])


def brightest(scene):
    return np.unravel_index(np.argmax(np.where(scene.mask, scene.image, -1)), scene.mask.shape)


class TestImageGradient:
    def test_ramp_exact_inside_and_at_edges(self):
        rows, cols = np.mgrid[0:20, 0:30]
        image = 0.01 * cols - 0.02 * rows  # dI/dx = 0.01, dI/dy = +0.02 (y is up)
        mask = np.zeros((20, 30), bool)
        mask[3:17, 4:25] = True
        gx, gy = image_gradient(image, mask)
        np.testing.assert_allclose(gx[mask], 0.01, atol=1e-12)
        np.testing.assert_allclose(gy[mask], 0.02, atol=1e-12)
        assert not gx[~mask].any() and not gy[~mask].any()

    def test_dark_background_does_not_leak(self):
        image = np.zeros((9, 9))
        mask = np.zeros((9, 9), bool)
        mask[2:7, 2:7] = True
        image[mask] = 0.8  # flat object on black: no gradient anywhere on it
        gx, gy = image_gradient(image, mask)
        assert np.abs(gx).max() == 0 and np.abs(gy).max() == 0

    def test_isolated_pixel_has_zero_gradient(self):
        mask = np.zeros((5, 5), bool)
        mask[2, 2] = True
        gx, gy = image_gradient(np.random.default_rng(0).random((5, 5)), mask)
        assert gx[2, 2] == 0 and gy[2, 2] == 0


class TestProjectToCone:
    def test_brightness_is_met_and_tilt_kept(self):
        rng = np.random.default_rng(1)
        normals = rng.normal(size=(50, 3))
        normals[:, 2] = np.abs(normals[:, 2])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        light = light_from_slant_tilt(30, 60)
        cos_theta = rng.uniform(0, 1, 50)
        out = project_to_cone(normals, cos_theta, light)
        np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1, atol=1e-12)
        np.testing.assert_allclose(out @ light, cos_theta, atol=1e-12)
        # the tilt around the light keeps its direction
        tilt_in = normals - (normals @ light)[:, None] * light
        tilt_out = out - (out @ light)[:, None] * light
        cosines = np.sum(tilt_in * tilt_out, axis=1) / (
            np.linalg.norm(tilt_in, axis=1) * np.linalg.norm(tilt_out, axis=1)
        )
        np.testing.assert_allclose(cosines[cos_theta < 0.999], 1, atol=1e-9)


class TestPropagateNormals:
    def test_smoke_shapes_units(self):
        scene = synth.scene("sphere", size=64)
        n = propagate_normals(scene.image, scene.mask, light=Z, reference=brightest(scene), albedo=1.0)
        assert n.shape == (64, 64, 3)
        assert np.isnan(n[~scene.mask]).all()
        np.testing.assert_allclose(np.linalg.norm(n[scene.mask], axis=1), 1, atol=1e-12)

    def test_brightness_is_explained(self):
        scene = synth.scene("ellipsoid", size=64, light=light_from_slant_tilt(20, 45))
        n = propagate_normals(
            scene.image, scene.mask, light=scene.light, reference=brightest(scene), albedo=scene.image.max()
        )
        np.testing.assert_allclose(
            (n @ scene.light)[scene.mask], scene.image[scene.mask] / scene.image.max(), atol=1e-12
        )

    def test_sphere_is_recovered(self):
        scene = synth.scene("sphere", size=128)
        n = propagate_normals(scene.image, scene.mask, light=Z, reference=brightest(scene), albedo=1.0)
        assert metrics.angular_error(n, scene.normals) < 0.5

    @pytest.mark.parametrize(
        "name,light,concave",
        [
            ("ellipsoid", (0, 0, 1), None),
            ("bumps", (0, 0, 1), None),
            ("sphere", tuple(light_from_slant_tilt(30, 120)), None),
            ("bowl", (0, 0, 1), "both"),
            ("saddle", (0, 0, 1), "x"),
        ],
    )
    def test_compiled_kernel_matches_reference(self, name, light, concave):
        scene = synth.scene(name, size=40, light=light)
        cx = scene.mask if concave in ("x", "both") else None
        cy = scene.mask if concave in ("y", "both") else None
        kwargs = dict(
            light=np.asarray(scene.light),
            reference=brightest(scene),
            albedo=float(scene.image.max()),
            concave_x=cx,
            concave_y=cy,
        )
        fast = propagate_normals(scene.image, scene.mask, **kwargs)
        slow = propagate_normals_reference(scene.image, scene.mask, **kwargs)
        np.testing.assert_array_equal(np.isnan(fast), np.isnan(slow))
        np.testing.assert_allclose(fast[scene.mask], slow[scene.mask], atol=1e-12)

    def test_concave_flags_flip_the_bowl(self):
        scene = synth.scene("bowl", size=96)
        ref = brightest(scene)
        convex = propagate_normals(scene.image, scene.mask, light=Z, reference=ref, albedo=1.0)
        concave = propagate_normals(
            scene.image,
            scene.mask,
            light=Z,
            reference=ref,
            albedo=1.0,
            concave_x=scene.mask,
            concave_y=scene.mask,
        )
        assert metrics.angular_error(convex, scene.normals) > 10
        assert metrics.angular_error(concave, scene.normals) < 1

    def test_reference_normal_is_kept(self):
        scene = synth.scene("sphere", size=32)
        given = np.array([0.1, 0.2, 0.97])
        given /= np.linalg.norm(given)
        n = propagate_normals(
            scene.image, scene.mask, light=Z, reference=(16, 16), reference_normal=given, albedo=1.0
        )
        np.testing.assert_allclose(n[16, 16], given)

    def test_disconnected_part_stays_nan(self):
        image = np.full((10, 10), 0.9)
        mask = np.zeros((10, 10), bool)
        mask[1:4, 1:4] = True
        mask[6:9, 6:9] = True
        n = propagate_normals(image, mask, light=Z, reference=(2, 2), albedo=0.9)
        assert np.isfinite(n[1:4, 1:4]).all() and np.isnan(n[6:9, 6:9]).all()

    def test_reference_off_the_mask_is_an_input_error(self):
        scene = synth.scene("sphere", size=32)
        with pytest.raises(InputError, match="not on the object"):
            propagate_normals(scene.image, scene.mask, light=Z, reference=(0, 0), albedo=1.0)


class TestRefineByIntegrability:
    def test_improves_the_ellipsoid_and_keeps_the_brightness(self):
        scene = synth.scene("ellipsoid", size=128)
        n0 = propagate_normals(scene.image, scene.mask, light=Z, reference=brightest(scene), albedo=1.0)
        n3 = refine_by_integrability(n0, scene.image, scene.mask, light=Z, iterations=3)
        assert metrics.angular_error(n3, scene.normals) < metrics.angular_error(n0, scene.normals) - 0.5
        np.testing.assert_allclose(n3[scene.mask][:, 2], scene.image[scene.mask], atol=1e-9)

    def test_sphere_stays_right(self):
        scene = synth.scene("sphere", size=128)
        n0 = propagate_normals(scene.image, scene.mask, light=Z, reference=brightest(scene), albedo=1.0)
        n3 = refine_by_integrability(n0, scene.image, scene.mask, light=Z, iterations=3)
        assert metrics.angular_error(n3, scene.normals) < 0.5
