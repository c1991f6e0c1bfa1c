"""The light direction: a unit vector toward a distant light, or slant and tilt in degrees.

Frame and angles as in ``docs/conventions.md``: x right, y up, z toward the viewer; ``(0, 0, 1)``
is a light behind the camera. Slant is the angle from +z, tilt the angle in the image plane from
+x toward +y, so ``L = (sin s cos t, sin s sin t, cos s)``. The 2002 system fixed the light at
+z; every solver here takes any light the camera can see lit surfaces under (z > 0), and
:func:`estimate_light` reads it, with ``k * albedo``, from one image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from shadeform._checks import is_number, shading_image
from shadeform.errors import InputError

__all__ = [
    "as_light",
    "light_from_slant_tilt",
    "slant_tilt",
    "parse_light",
    "LightEstimate",
    "estimate_light",
]


def as_light(light) -> np.ndarray:
    """Check a light direction and scale it to unit length.

    Parameters
    ----------
    light : (3,) array_like
        ``(x, y, z)`` toward the light, any non-zero length, with ``z > 0``.

    Returns
    -------
    (3,) float64
        The unit vector.

    Raises
    ------
    InputError
        If ``light`` is not three finite numbers, is zero, or has ``z <= 0`` (a light at or behind
        the object's horizon lights nothing the camera sees, or only at grazing angles).

    Examples
    --------
    >>> as_light([0, 0, 2])
    array([0., 0., 1.])
    """
    try:
        vector = np.array(light, dtype=np.float64)
    except (TypeError, ValueError):
        vector = None
    if vector is None or vector.shape != (3,):
        raise InputError(
            f"light must be three numbers (x, y, z) toward the light, got {light!r}; "
            "e.g. (0, 0, 1) for a light behind the camera"
        )
    if not np.isfinite(vector).all():
        raise InputError(f"light has NaN or infinite components: {light!r}; give finite numbers")
    length = math.sqrt(float(vector @ vector))
    if length == 0:
        raise InputError(
            "light is the zero vector; give a direction toward the light, e.g. (0, 0, 1)"
        )
    if vector[2] <= 0:
        raise InputError(
            f"light {tuple(float(v) for v in vector)} has z <= 0: it is at or behind the object's "
            "horizon and lights nothing the camera sees; give a light with z > 0"
        )
    return vector / length


def light_from_slant_tilt(slant: float, tilt: float) -> np.ndarray:
    """Light direction from slant and tilt in degrees.

    Parameters
    ----------
    slant : float
        Angle from the viewing direction +z, in degrees, ``0 <= slant < 90``.
    tilt : float
        Angle in the image plane from +x toward +y (up), in degrees; any value.

    Returns
    -------
    (3,) float64
        ``(sin s cos t, sin s sin t, cos s)``.

    Raises
    ------
    InputError
        If an angle is not a finite number or ``slant`` is outside ``[0, 90)``.

    Examples
    --------
    >>> light_from_slant_tilt(45, 90).round(4)
    array([0.    , 0.7071, 0.7071])
    """
    for name, value in (("slant", slant), ("tilt", tilt)):
        if not is_number(value) or not math.isfinite(value):
            raise InputError(f"{name} must be a finite number of degrees, got {value!r}")
    if not 0 <= slant < 90:
        raise InputError(
            f"slant must be in [0, 90) degrees, got {slant:g}; at 90 or more the light is at or "
            "behind the object's horizon and lights nothing the camera sees"
        )
    s, t = math.radians(slant), math.radians(tilt)
    return np.array([math.sin(s) * math.cos(t), math.sin(s) * math.sin(t), math.cos(s)])


def slant_tilt(light) -> tuple[float, float]:
    """Slant and tilt in degrees of a light direction; the inverse of :func:`light_from_slant_tilt`.

    Parameters
    ----------
    light : (3,) array_like
        Toward the light, any length, ``z > 0`` (see :func:`as_light`).

    Returns
    -------
    slant : float
        Degrees from +z, in ``[0, 90)``.
    tilt : float
        Degrees from +x toward +y, in ``(-180, 180]``; 0 when ``slant`` is 0.

    Raises
    ------
    InputError
        As :func:`as_light`.
    """
    x, y, z = as_light(light)
    # atan2 keeps full precision near slant 0, where acos(z) does not.
    slant = math.degrees(math.atan2(math.hypot(x, y), z))
    tilt = math.degrees(math.atan2(y, x)) if (x or y) else 0.0
    return slant, tilt


def parse_light(text: str) -> np.ndarray:
    """Read a light direction written ``"X,Y,Z"``, as on the command line.

    Parameters
    ----------
    text : str
        Three numbers separated by commas, spaces allowed, e.g. ``"0.3, 0.2, 1"``.

    Returns
    -------
    (3,) float64
        The unit vector (see :func:`as_light`).

    Raises
    ------
    InputError
        If the text is not three numbers, or the direction is not a valid light.
    """
    usage = "give three numbers X,Y,Z toward the light, e.g. '0,0,1'"
    if not isinstance(text, str):
        raise InputError(f"bad light {text!r}: {usage}")
    parts = text.split(",")
    if len(parts) != 3:
        raise InputError(f"bad light {text!r}: {usage}")
    try:
        values = [float(part) for part in parts]
    except ValueError:
        raise InputError(f"bad light {text!r}: not all numbers; {usage}") from None
    return as_light(values)



# --- the light from one image --------------------------------------------------------------------

#: Fewest object pixels whose light :func:`estimate_light` will estimate.
MIN_OBJECT_PIXELS = 100

# Gaussian smoothing (pixels) of the mask for the boundary's normals and sub-pixel distances.
_MASK_SIGMA = 2.0
# Neighbouring boundary pixels whose normals turn less than this belong to one straight run.
_RUN_TURN = math.radians(3.0)
_RUN_MIN_PIXELS = 8
# A run is a cut when its intensity spread exceeds what its normals' turn allows by this fraction
# of the peak (plus noise): the sub-pixel jitter of the outermost pixels alone moves a limb's
# intensity by up to ~0.1.
_CUT_SPREAD = 0.1
# A run whose normals turn less than this in all is straight.
_STRAIGHT_TURN = math.radians(4.0)
# A boundary ring whose fitted constant term exceeds this fraction of the top level, and whose
# fit it improves this much, is a tilted rim (a cap's edge), not an occluding contour.
_RIM_INTERCEPT = 0.2
_RIM_GAIN = 0.6
# An object with this fraction of its pixels at one level, shared by its edge, is a relief on a
# base facing the camera.
_RELIEF_FRACTION = 0.1
# Above this standard error (degrees) the contour alone cannot fix the slant.
_DEGENERATE_SLANT = 1.5
# Radius (pixels) of the quadratic fit at the brightest point: at most twice this.
_PEAK_RADIUS = 8
_MIN_BOUNDARY_PIXELS = 20
_FIT_ITERATIONS = 30
_MAX_SLANT = 89.9


@dataclass(frozen=True, eq=False)
class LightEstimate:
    """A light direction and brightness estimated from one image (see :func:`estimate_light`).

    Attributes
    ----------
    light : (3,) float64
        Unit vector from the surface toward the light, camera frame (``docs/conventions.md``);
        read-only.
    albedo : float
        ``k * albedo`` of the image model ``I = k * albedo * max(0, N . L)``, in the image's units.
    slant : float
        Degrees from the viewing direction +z, in ``[0, 90)``.
    tilt : float
        Degrees in the image plane from +x toward +y (up), in ``(-180, 180]``; 0 when the slant
        is 0.
    evidence : {"limb", "limb-peak", "rim", "relief", "round"}
        What fixed the light: the occluding contour and the top of the object; the top and the
        brightest point (the contour could not fix the slant); a tilted rim and the top; a relief
        on a base facing the camera; rings inside a round object.
    info : dict
        Measured quantities behind the estimate (levels, fitted coefficients, pixel counts).
    """

    light: np.ndarray
    albedo: float
    slant: float
    tilt: float
    evidence: str
    info: dict = field(default_factory=dict)


#: What :func:`estimate_light` reads the light from.
ESTIMATION_METHODS = ("contour", "round")


def estimate_light(
    image, mask=None, *, method: str = "contour", convex: bool = True
) -> LightEstimate:
    """Estimate the direction and brightness of a distant light from one shading image.

    Lambertian surface of uniform albedo, one distant light, orthographic camera, attached shadows
    (``I = k * albedo * max(0, N . L)``); only object pixels are read.

    ``method="contour"`` (default) reads, in order of reliability:

    1. **The occluding contour.** Where the silhouette of a smooth object is an occluding contour,
       the normal is the silhouette's outward 2-D normal ``b``, so the intensity there is
       ``k (b . L_xy)``, linear in ``b`` with coefficient ``k L_xy`` [3]_, [4]_. The outermost
       pixel centres lie a sub-pixel distance ``d`` inside the silhouette, where the normal has
       already turned toward the viewer by about ``sqrt(2 d / rho)`` [5]_; ``d`` is read from the
       smoothed mask, and the robust fit ``I = max(0, b . A + kappa sqrt(d))`` separates
       ``A = k L_xy`` from that offset. Straight runs of the boundary that are lit unevenly (the
       cut ends of a cylinder or a vase) are not occluding and are dropped; on straight runs that
       are, the mask cannot place the silhouette between two pixel rows, so each gets its own
       offset.
    2. **The top of the object.** The point deepest inside the silhouette is taken to face the
       viewer, so its intensity (a robust quadratic fit around it) is ``k L_z``. Then
       ``L ~ (A, k L_z)`` and ``k = |(A, k L_z)|``.
    3. **The brightest point** (``evidence="limb-peak"`` in the result). When the contour
       cannot fix ``A`` (only straight sides lit, as on a cylinder), the brightest point is taken
       to face the light: ``k = I_max``, ``cos(slant) = k L_z / I_max``, and the tilt is the lit
       contour's mean normal.
    4. **A tilted rim** (``"rim"``: the edge of a cap, a bowl or a saddle seen from above). The
       boundary normals share one slant ``theta`` and the fit gains a constant term
       ``k cos(theta) L_z``; with the top's ``k L_z`` that gives ``theta``, then ``k L_xy``.
    5. **A relief on a base facing the camera** (``"relief"``: an evenly lit edge at the level of
       a good part of the object). The base level is ``k L_z``; the brightest point bounds the
       slant from below, ``cos(slant) >= k L_z / I_max``, with equality when some facet faces
       the light. A relief changes the image along the light's tilt only to first order, so
       the line integrals of ``1 - I / (k L_z)`` along the tilt vanish and the image's spectrum
       is empty on the frequency line perpendicular to the tilt [6]_.

    ``method="round"`` suits photographs of round objects: real materials darken toward the
    occluding contour (Fresnel), which biases the contour's slant low. It fits rings at one
    distance inside the silhouette, between 15% and 85% of the way to the deepest point: on a
    sphere, or any object with round cross-sections, a ring's normals share one slant ``theta``
    and have the tilt of the nearest contour normal ``b``, so ``I = b . (k sin(theta) L_xy) +
    k cos(theta) L_z``; with the top's ``k L_z`` each ring gives ``k L_xy``, highlights are
    dropped as outliers and the rings are combined by a weighted median.

    Parameters
    ----------
    image : (H, W) array_like
        One channel of intensities, >= 0, any scale (integer images are scaled by their type's
        maximum). Use :func:`shadeform.load_image` with a ``channel`` for colour photos.
    mask : (H, W) array_like of bool, optional
        Object pixels; default :func:`shadeform.preprocess.object_mask`.
    method : {"contour", "round"}, optional
        What to read the light from (see above).
    convex : bool, optional
        Whether the object bulges toward the camera. A concave surface (a bowl seen from above,
        a relief of dents) lit from one side gives exactly the image of its convex twin lit from
        the opposite side [7]_, so the image cannot tell; ``False`` turns the tilt by 180 degrees.

    Returns
    -------
    LightEstimate
        ``light`` (3,), ``albedo``, ``slant`` and ``tilt`` in degrees, the ``evidence`` that
        fixed it and measured ``info``.

    Raises
    ------
    InputError
        An image that is not one channel or holds NaN, inf or negative values; a mask of another
        shape, empty or smaller than :data:`MIN_OBJECT_PIXELS`; a black object; an object whose
        outline lies on the image frame (unless it is a relief on a flat base); an unknown
        ``method``.

    Notes
    -----
    What one image cannot tell, whatever the method: a cylinder seen side-on looks the same
    under every light in the plane through its axis and the viewer, up to ``k``, so only the
    light's component across the axis is recovered (the estimate is the least slanted light that
    explains the image); a saddle ``z = x^2 - y^2`` looks like a dome lit from the tilt mirrored
    about the y axis. Estimators that assume statistically isotropic surfaces [1]_, [2]_ err by
    20 degrees or more at small slants on the synthetic scenes; ``benchmarks/bench_light.py``
    measures this one on all of them.

    References
    ----------
    .. [1] A. P. Pentland, "Finding the illuminant direction", J. Opt. Soc. Am. 72(4), 448-455,
       1982.
    .. [2] Q. Zheng and R. Chellappa, "Estimation of illuminant direction, albedo, and shape from
       shading", IEEE Trans. PAMI 13(7), 680-702, 1991.
    .. [3] Y. Yang and A. Yuille, "Sources from shading", Proc. CVPR 1991, 534-539.
    .. [4] P. Nillius and J.-O. Eklundh, "Automatic estimation of the projected light source
       direction", Proc. CVPR 2001, I-1076-1083.
    .. [5] J. J. Koenderink, "What does the occluding contour tell us about solid shape?",
       Perception 13, 321-330, 1984.
    .. [6] A. P. Pentland, "Linear shape from shading", IJCV 4, 153-162, 1990.
    .. [7] P. N. Belhumeur, D. J. Kriegman and A. L. Yuille, "The bas-relief ambiguity",
       IJCV 35(1), 33-44, 1999.

    Examples
    --------
    >>> from shadeform import synth
    >>> scene = synth.scene("sphere", size=128, light=light_from_slant_tilt(30, 45))
    >>> est = estimate_light(scene.image, scene.mask)
    >>> bool(abs(est.slant - 30) < 3 and abs(est.tilt - 45) < 5), est.evidence
    (True, 'limb')
    """
    image, mask = _estimation_input(image, mask)
    if method not in ESTIMATION_METHODS:
        raise InputError(
            f"unknown light estimation method {method!r}; choose one of: "
            f"{', '.join(ESTIMATION_METHODS)}"
        )
    if not isinstance(convex, (bool, np.bool_)):
        raise InputError(f"convex must be True or False, got {convex!r}")
    from scipy import ndimage as ndi

    inside = ndi.distance_transform_edt(mask)
    noise = _noise_level(image, mask, inside)
    brightest = float(image[mask].max())
    peak = max(_peak_level(image, mask, inside, noise), 1e-3 * brightest)
    # a top in shadow would put the light behind the object's horizon
    top = max(_top_level(image, mask, inside), 1e-3 * peak)
    rows, cols, normals, depth = _boundary(mask)
    values = image[rows, cols]
    scale = max(3.0 * noise, 0.02 * peak)
    info: dict = {"noise": noise, "peak": peak, "top": top, "boundary_pixels": int(rows.size)}
    if rows.size < _MIN_BOUNDARY_PIXELS:
        # the object fills the frame: only a relief on a flat base can still be read
        edge = mask & ~ndi.binary_erosion(mask, border_value=0)
        level = _base_level(image, mask, inside, image[edge], noise, peak)
        if level is None:
            raise InputError(
                f"the object's outline has only {rows.size} pixels off the image frame; frame "
                "the whole object with a margin of background"
            )
        return _relief(image, mask, level, peak, convex, info)
    if method == "round":
        across, rings = _round_rings(image, mask, inside, top, scale)
        info["rings"] = rings
        if across is None:
            raise InputError(
                "too few lit rings inside the object for method='round' (is it dark, tiny or "
                "lit from behind?); try method='contour'"
            )
        slant, tilt, albedo = _from_components(across, top)
        return _result(slant, tilt, albedo, "round", convex, info)

    level = _base_level(image, mask, inside, values, noise, peak)
    if level is not None:
        return _relief(image, mask, level, peak, convex, info)

    cut, runs = _boundary_runs(rows, cols, normals, values, mask.shape, peak, noise)
    keep = ~cut
    if cut.any():
        # where a cut meets the contour the silhouette has a corner: neither model holds there
        near = ndi.distance_transform_edt(~_paint(mask.shape, rows[cut], cols[cut]))
        keep &= near[rows, cols] > 3.0 * _MASK_SIGMA
    info.update(cut_pixels=int(cut.sum()), straight_runs=int(runs.max() + 1))
    if keep.sum() < _MIN_BOUNDARY_PIXELS:
        lit = values > scale
        return _from_peak(normals[lit], values[lit], top, peak, convex, info)
    b, root, v, run = normals[keep], np.sqrt(depth[keep]), values[keep], runs[keep]
    limb, limb_rms, limb_cov = _fit_ring(b, root, v, run, intercept=False, scale=scale)
    rim, rim_rms, _ = _fit_ring(b, root, v, None, intercept=True, scale=scale)
    info.update(limb_fit=tuple(map(float, limb[:3])), limb_rms=limb_rms,
                rim_fit=tuple(map(float, rim)), rim_rms=rim_rms)

    lit = v > scale
    curved_lit = int(np.count_nonzero(lit & (run < 0)))
    info["curved_lit_pixels"] = curved_lit
    if curved_lit < max(_MIN_BOUNDARY_PIXELS, 0.1 * np.count_nonzero(lit)):
        return _from_peak(b[lit], v[lit], top, peak, convex, info)

    if rim[3] > _RIM_INTERCEPT * top and rim_rms < _RIM_GAIN * limb_rms:
        cos_rim = min(rim[3] / top, 0.999)
        across = rim[:2] / math.sqrt(1.0 - cos_rim * cos_rim)  # k * L_xy
        info["rim_slant"] = math.degrees(math.acos(cos_rim))
        slant, tilt, albedo = _from_components(across, top)
        return _result(slant, tilt, albedo, "rim", convex, info)

    across = limb[:2]
    slant, tilt, albedo = _from_components(across, top)
    error = _slant_error(across, top, limb_cov[:2, :2])
    info["slant_error"] = error
    if error <= _DEGENERATE_SLANT:
        return _result(slant, tilt, albedo, "limb", convex, info)
    return _from_peak(b[lit], v[lit], top, peak, convex, info)


def _relief(image, mask, level, peak, convex, info) -> LightEstimate:
    """The light on a relief over a flat base facing the camera, at intensity ``level``."""
    info["base_level"] = level
    slant = math.degrees(math.acos(min(level / peak, 1.0)))
    tilt = _relief_tilt(image, mask, level)
    return _result(slant, tilt, max(peak, level), "relief", convex, info)


def _from_peak(normals, values, top, peak, convex, info) -> LightEstimate:
    """The light when the contour cannot fix the slant: the brightest point faces the light.

    The tilt is the lit contour's mean normal, weighted by intensity.
    """
    mean = (normals * values[:, None]).sum(axis=0) if values.size else np.zeros(2)
    tilt = math.degrees(math.atan2(mean[1], mean[0])) if np.hypot(*mean) > 0 else 0.0
    slant = math.degrees(math.acos(min(top / peak, 1.0)))
    return _result(slant, tilt, max(peak, top), "limb-peak", convex, info)


def _estimation_input(image, mask):
    """Validated ``(image float64 (H, W), mask bool (H, W))``."""
    array = shading_image(np.asarray(image))
    if mask is None:
        from shadeform.preprocess import object_mask

        mask = object_mask(array)
    mask = np.asarray(mask)
    if mask.shape != array.shape:
        raise InputError(
            f"mask has shape {mask.shape} but the image has {array.shape}; give a mask of the "
            "image's size"
        )
    mask = mask.astype(bool)
    count = int(mask.sum())
    if count == 0:
        raise InputError("mask is empty; it must mark the object's pixels")
    if count < MIN_OBJECT_PIXELS:
        raise InputError(
            f"the object has {count} pixels; estimating the light needs at least "
            f"{MIN_OBJECT_PIXELS} (use a larger image of the object)"
        )
    if array[mask].max() <= 0:
        raise InputError(
            "the object is black: there is no shading to estimate a light from; check the "
            "exposure or the mask"
        )
    return array, mask


def _result(slant, tilt, albedo, evidence, convex, info) -> LightEstimate:
    slant = min(slant, _MAX_SLANT)  # a light at the horizon or beyond lights nothing we see
    if slant < 1e-9:
        slant, tilt = 0.0, 0.0
    if not convex and slant > 0:
        tilt += 180.0
    tilt = -((-tilt + 180.0) % 360.0 - 180.0)  # into (-180, 180]
    light = light_from_slant_tilt(slant, tilt)
    light.flags.writeable = False
    return LightEstimate(light=light, albedo=float(albedo), slant=float(slant), tilt=float(tilt),
                         evidence=evidence, info=info)


def _from_components(across, along_view) -> tuple[float, float, float]:
    """Slant, tilt (degrees) and ``k`` from ``k L_xy`` (2,) and ``k L_z``."""
    size = math.hypot(float(across[0]), float(across[1]))
    slant = math.degrees(math.atan2(size, along_view))
    tilt = math.degrees(math.atan2(float(across[1]), float(across[0]))) if size > 0 else 0.0
    return slant, tilt, math.hypot(size, along_view)


def _slant_error(across, along_view, covariance) -> float:
    """Standard error (degrees) of ``atan2(|across|, along_view)``, given the covariance of
    ``across``; ``inf`` when the data leave ``across`` unconstrained."""
    if not np.isfinite(covariance).all():
        return math.inf
    size = math.hypot(float(across[0]), float(across[1]))
    gain = along_view / (size * size + along_view * along_view)
    if size > 1e-12:
        direction = np.asarray(across, dtype=np.float64) / size
        variance = float(direction @ covariance @ direction)
    else:
        variance = float(np.linalg.eigvalsh(covariance).max())
    return math.degrees(gain * math.sqrt(max(variance, 0.0)))


def _noise_level(image, mask, inside) -> float:
    """Standard deviation of pixel noise: the MAD of each interior pixel minus its 3x3 mean."""
    from scipy import ndimage as ndi

    interior = (inside > 2) & (image > 0)
    if interior.sum() < 20:
        return 0.0
    detail = (image - ndi.uniform_filter(image, 3))[interior]
    # x - mean(3x3 incl. x) has variance sigma^2 * (1 - 1/9) for independent noise
    mad = float(np.median(np.abs(detail - np.median(detail))))
    return 1.4826 * mad / math.sqrt(8.0 / 9.0)


def _quadratic_peak(rows, cols, values, centre, reach=None):
    """Value at the stationary point of a least-squares quadratic, or at ``centre`` if that point
    lies farther than ``reach`` (default :data:`_PEAK_RADIUS`) from it."""
    dr, dc = rows - centre[0], cols - centre[1]
    design = np.column_stack([np.ones_like(dr), dr, dc, dr * dr, dr * dc, dc * dc])
    coef, *_ = np.linalg.lstsq(design, values, rcond=None)
    hessian = np.array([[2 * coef[3], coef[4]], [coef[4], 2 * coef[5]]])
    try:
        offset = np.linalg.solve(hessian, -coef[1:3])
    except np.linalg.LinAlgError:
        offset = np.zeros(2)
    if not np.isfinite(offset).all() or np.hypot(*offset) > (reach or _PEAK_RADIUS):
        offset = np.zeros(2)
    r, c = offset
    return float(coef[0] + coef[1] * r + coef[2] * c + coef[3] * r * r + coef[4] * r * c
                 + coef[5] * c * c)


def _window(mask, centre, radius):
    r0, c0 = centre
    rr, cc = np.mgrid[max(r0 - radius, 0):min(r0 + radius + 1, mask.shape[0]),
                      max(c0 - radius, 0):min(c0 + radius + 1, mask.shape[1])]
    inside = mask[rr, cc] & ((rr - r0) ** 2 + (cc - c0) ** 2 <= radius * radius)
    return rr[inside], cc[inside]


def _peak_level(image, mask, inside, noise) -> float:
    """Brightest level of the object: the peak of a quadratic fitted around the brightest point.

    The fit covers a disk around the maximum of the smoothed image, sized from the blob that lies
    within a few noise levels (at least 1%) of that maximum. The maximum of a noisy image is
    biased upward; the fitted quadratic's peak is not.
    """
    from scipy import ndimage as ndi

    weight = mask.astype(np.float64)
    width = 1.5
    smooth = ndi.gaussian_filter(image * weight, width) / np.maximum(
        ndi.gaussian_filter(weight, width), 1e-12)
    region = mask & (inside > 2)
    if not region.any():
        region = mask
    centre = np.unravel_index(np.argmax(np.where(region, smooth, -np.inf)), mask.shape)
    top = float(smooth[centre])
    # noise left after smoothing: sigma / (2 sqrt(pi) width)
    drop = max(4.0 * noise / (2.0 * math.sqrt(math.pi) * width), 0.01 * top)
    labels, _ = ndi.label(region & (smooth >= top - drop))
    area = float(np.count_nonzero(labels == labels[centre]))
    # a disk, not the blob itself: choosing pixels by their noisy values would bias the fit
    radius = int(round(min(max(1.5 * math.sqrt(area / math.pi), 3.0), 2.0 * _PEAK_RADIUS)))
    rr, cc = _window(mask, centre, radius)
    if rr.size < 12:
        return top
    return _quadratic_peak(rr.astype(np.float64), cc.astype(np.float64), image[rr, cc], centre,
                           reach=float(radius))


def _top_level(image, mask, inside) -> float:
    """Intensity at the point deepest inside the silhouette, taken to face the viewer.

    A quadratic is fitted on a disk around that point; pixels far above the fit (specular
    highlights) are dropped and the fit repeated.
    """
    centre = np.unravel_index(np.argmax(inside), mask.shape)
    depth = float(inside[centre])
    radius = int(max(3, min(0.25 * depth, depth - 1)))
    rr, cc = _window(mask, centre, radius)
    values = image[rr, cc]
    keep = np.ones(values.size, dtype=bool)
    rf, cf = (rr - centre[0]).astype(np.float64), (cc - centre[1]).astype(np.float64)
    design = np.column_stack([np.ones_like(rf), rf, cf, rf * rf, rf * cf, cf * cf])
    coef = np.zeros(6)
    for _ in range(3):
        if keep.sum() < 12:
            return float(np.median(values))
        coef, *_ = np.linalg.lstsq(design[keep], values[keep], rcond=None)
        residual = values - design @ coef
        spread = 1.4826 * float(np.median(np.abs(residual[keep]))) + 1e-12
        keep = residual < 3.0 * spread
    return float(coef[0])


def _boundary(mask):
    """Outermost object pixels away from the image frame: rows, cols, outward normals (n, 2) in
    (x, y), and their distances (pixels, >= 0) inside the silhouette, from the smoothed mask."""
    from scipy import ndimage as ndi

    smooth = ndi.gaussian_filter(mask.astype(np.float64), _MASK_SIGMA, mode="constant")
    grad_r, grad_c = np.gradient(smooth)
    ring = mask & ~ndi.binary_erosion(mask, border_value=1)
    on_frame = np.zeros_like(mask)
    on_frame[[0, -1], :] = mask[[0, -1], :]
    on_frame[:, [0, -1]] = mask[:, [0, -1]]
    if on_frame.any():
        # the frame cuts the object there: no silhouette, and the smoothed mask's normal is off
        ring &= ndi.distance_transform_edt(~on_frame) > 3.0 * _MASK_SIGMA
    rows, cols = np.nonzero(ring)
    # outward is down the smoothed mask; x = col, y = -row
    normals = np.column_stack([-grad_c[rows, cols], grad_r[rows, cols]])
    length = np.hypot(normals[:, 0], normals[:, 1])
    good = length > 1e-9
    rows, cols, normals, length = rows[good], cols[good], normals[good], length[good]
    normals /= length[:, None]
    # the silhouette is where the smoothed mask crosses 1/2; linearised distance to it
    depth = np.clip((smooth[rows, cols] - 0.5) / length, 0.0, 1.5)
    return rows, cols, normals, depth


def _paint(shape, rows, cols) -> np.ndarray:
    canvas = np.zeros(shape, dtype=bool)
    canvas[rows, cols] = True
    return canvas


def _boundary_runs(rows, cols, normals, values, shape, peak, noise):
    """Straight runs of the boundary: which are cuts, and labels of the others.

    Along an occluding contour the intensity is ``k (b . L_xy)``: it changes only as fast as the
    normal ``b`` turns. A straight run lit unevenly is a cut (the end of a cylinder or a vase).
    On a straight run that is not a cut, the smoothed mask cannot place the silhouette between
    two pixel rows, so such runs get their own offset in the fit.

    Returns
    -------
    cut : (n,) bool
        Pixels on cut runs.
    runs : (n,) int
        Index of the straight, evenly lit run of each pixel, -1 elsewhere.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = rows.size
    index = -np.ones(shape, dtype=np.int64)
    index[rows, cols] = np.arange(n)
    angle = np.arctan2(normals[:, 1], normals[:, 0])
    heads, tails = [], []
    for dr, dc in ((0, 1), (1, -1), (1, 0), (1, 1)):
        r2, c2 = rows + dr, cols + dc
        ok = (r2 < shape[0]) & (c2 >= 0) & (c2 < shape[1])
        other = np.full(n, -1)
        other[ok] = index[r2[ok], c2[ok]]
        pair = other >= 0
        turn = np.abs(np.angle(np.exp(1j * (angle[pair] - angle[other[pair]]))))
        close = turn < _RUN_TURN
        heads.append(np.nonzero(pair)[0][close])
        tails.append(other[pair][close])
    heads, tails = np.concatenate(heads), np.concatenate(tails)
    graph = coo_matrix((np.ones(heads.size), (heads, tails)), shape=(n, n))
    count, labels = connected_components(graph, directed=False)
    cut = np.zeros(n, dtype=bool)
    runs = np.full(n, -1)
    sizes = np.bincount(labels, minlength=count)
    straight = 0
    for label in np.nonzero(sizes >= _RUN_MIN_PIXELS)[0]:
        run = labels == label
        unit = np.exp(1j * angle[run])
        deviation = np.angle(unit * np.conj(unit.mean()))
        turned = float(np.percentile(deviation, 95) - np.percentile(deviation, 5))
        lo, hi = np.percentile(values[run], [5, 95])
        if hi - lo > peak * turned + 4.0 * noise + _CUT_SPREAD * peak:
            cut[run] = True
        elif turned < _STRAIGHT_TURN:
            runs[run] = straight
            straight += 1
    return cut, runs


def _fit_ring(normals, root_depth, values, runs, *, intercept: bool, scale: float):
    """Robust clipped fit of the boundary intensities.

    Model: ``I = max(0, b . A + kappa sqrt(d) [+ c])`` on curved parts of the contour, and
    ``I = max(0, b . A + c_run)`` on each straight run (``runs >= 0``), whose sub-pixel offset the
    mask cannot tell.

    Returns
    -------
    params : (3 or 4 + runs,) float64
        ``(A_x, A_y, kappa[, c], c_run...)``.
    rms : float
        Root-mean-square residual.
    covariance : (p, p) float64
        Covariance of the parameters from the unclipped pixels; ``inf`` along directions the data
        do not constrain.
    """
    from scipy.optimize import lsq_linear

    curved = np.ones(values.size) if runs is None else (runs < 0).astype(np.float64)
    columns = [normals, (root_depth * curved)[:, None]]
    if intercept:
        columns.append(np.ones((values.size, 1)))
    if runs is not None and runs.max() >= 0:
        columns.append((runs[:, None] == np.arange(runs.max() + 1)[None, :]).astype(np.float64))
    design = np.hstack(columns)
    lower = np.full(design.shape[1], 0.0)
    lower[:2] = -np.inf
    params = np.zeros(design.shape[1])
    lit = values > scale
    if lit.sum() < design.shape[1]:
        lit = values > 0
    active = lit
    weight = np.ones(values.size)
    for _ in range(_FIT_ITERATIONS):
        # pixels predicted in shadow and seen in shadow agree; the others are fitted linearly
        root = np.sqrt(weight[active])[:, None]
        solution = lsq_linear(design[active] * root, values[active] * root[:, 0],
                              bounds=(lower, np.inf), method="bvls")
        change = float(np.abs(solution.x - params).max())
        params = solution.x
        predicted = design @ params
        residual = np.maximum(predicted, 0.0) - values
        weight = 1.0 / np.sqrt(1.0 + (residual / scale) ** 2)  # soft-L1 (pseudo-Huber) weights
        active = lit | (predicted > 0)
        if change < 1e-7 * max(float(np.abs(values).max()), 1e-300):
            break
    rms = float(np.sqrt(np.mean(residual * residual)))

    def jacobian(p):
        jac = design.copy()
        jac[design @ p <= 0] = 0.0
        return jac

    jac = jacobian(params)
    eigenvalues, vectors = np.linalg.eigh(jac.T @ jac)
    with np.errstate(divide="ignore"):
        inverse = np.where(eigenvalues > 1e-9 * max(eigenvalues.max(), 1e-300), 1.0 / eigenvalues,
                           np.inf)
    weights = vectors * vectors  # variance of p_i = sum_j V_ij^2 / lambda_j (inf if unconstrained)
    sigma2 = max(rms, scale / 3.0) ** 2
    covariance = sigma2 * (vectors * np.where(np.isfinite(inverse), inverse, 0.0)) @ vectors.T
    unconstrained = (weights[:, ~np.isfinite(inverse)] > 1e-6).any(axis=1)
    covariance[unconstrained, :] = np.inf
    covariance[:, unconstrained] = np.inf
    return params, rms, covariance


def _round_rings(image, mask, inside, top, scale):
    """``k L_xy`` from rings at equal distance inside the silhouette of a round object.

    On a sphere, and approximately on any object with round cross-sections, the normals on a ring
    at one distance from the silhouette share one slant ``theta`` and have the tilt of the nearest
    contour normal ``b``, so ``I = b . (k sin(theta) L_xy) + k cos(theta) L_z``: a plane in ``b``.
    With the top level ``k L_z``, each ring gives ``cos(theta)`` and ``k L_xy``. Rings are taken
    between 15% and 85% of the way to the deepest point, where real materials are closest to
    Lambertian; highlights are dropped as outliers above each ring's fit, and the rings are combined
    by a weighted median.

    Returns
    -------
    across : (2,) float64 or None
        ``k L_xy``, None when fewer than three rings could be fitted.
    rings : int
        Number of rings used.
    """
    from scipy import ndimage as ndi

    deepest = float(inside.max())
    smooth = ndi.gaussian_filter(inside, 1.0)
    grad_r, grad_c = np.gradient(smooth)
    length = np.maximum(np.hypot(grad_r, grad_c), 1e-12)
    out_x, out_y = -grad_c / length, grad_r / length
    step = max(1.0, deepest / 60.0)
    estimates, weights = [], []
    for low in np.arange(max(2.0, 0.15 * deepest), 0.85 * deepest, step):
        ring = mask & (inside > low) & (inside <= low + step)
        values = image[ring]
        lit = values > scale
        if lit.sum() < 20:
            continue
        design = np.column_stack([out_x[ring][lit], out_y[ring][lit], np.ones(lit.sum())])
        values = values[lit]
        keep = np.ones(values.size, dtype=bool)
        for _ in range(3):
            coef, *_ = np.linalg.lstsq(design[keep], values[keep], rcond=None)
            residual = values - design @ coef
            spread = 1.4826 * float(np.median(np.abs(residual[keep]))) + 1e-12
            keep = residual < 3.0 * spread
            if keep.sum() < 20:
                break
        cos_ring = coef[2] / top
        if not 0.3 <= cos_ring <= 0.95:
            continue
        sin_ring = math.sqrt(1.0 - cos_ring * cos_ring)
        estimates.append(coef[:2] / sin_ring)
        weights.append(keep.sum() * sin_ring * sin_ring)
    if len(estimates) < 3:
        return None, len(estimates)
    estimates, weights = np.array(estimates), np.array(weights)
    return np.array([_weighted_median(estimates[:, 0], weights),
                     _weighted_median(estimates[:, 1], weights)]), len(estimates)


def _weighted_median(values, weights) -> float:
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])


def _base_level(image, mask, inside, boundary_values, noise, peak) -> float | None:
    """The level of a flat base facing the camera, or None if the object has none.

    A relief on such a base has an evenly lit edge, the same level a few pixels further in (a
    curved rim gets brighter or darker inward), and a good part of its pixels at that level.
    """
    level = float(np.median(boundary_values))
    spread = 1.4826 * float(np.median(np.abs(boundary_values - level)))
    if spread > max(2.0 * noise, 0.01 * peak):
        return None
    inner = image[mask & (inside > 4) & (inside <= 6)]
    if inner.size == 0 or abs(float(np.median(inner)) - level) > max(0.2 * noise, 0.005 * peak):
        return None
    band = max(2.0 * noise, 0.01 * level)
    fraction = float(np.count_nonzero(np.abs(image[mask] - level) <= band)) / float(mask.sum())
    return level if fraction >= _RELIEF_FRACTION else None


def _relief_tilt(image, mask, level) -> float:
    """Tilt (degrees) of the light on a relief over a base at intensity ``level``.

    To first order a relief darkens the base by ``tan(slant)`` times its slope along the tilt, so
    the darkening's line integrals along the tilt vanish and, by the projection-slice theorem, its
    spectrum is empty on the frequency line perpendicular to the tilt [6]_ (in
    :func:`estimate_light`). Of the two opposite tilts, the one that makes the relief mostly
    raised is returned.
    """
    from scipy import ndimage as ndi

    darkening = np.where(mask, 1.0 - image / level, 0.0)
    height, width = darkening.shape
    size = 2 * max(height, width)
    power = np.fft.fftshift(np.abs(np.fft.fft2(darkening, s=(size, size))) ** 2)
    centre = size // 2
    radii = np.arange(1, size // 4, dtype=np.float64)
    angles = np.radians(np.arange(0.0, 180.0, 0.5))
    energy = np.empty(angles.size)
    for i, angle in enumerate(angles):
        # frequencies along (-sin, cos) in (x, y); y is up, frequency rows go down
        fr = centre - radii * math.cos(angle)
        fc = centre - radii * math.sin(angle)
        energy[i] = ndi.map_coordinates(power, [fr, fc], order=1).sum()
    best = int(np.argmin(energy))
    before, after = energy[best - 1], energy[(best + 1) % angles.size]
    curve = before - 2.0 * energy[best] + after
    shift = 0.5 * (before - after) / curve if curve > 0 else 0.0
    tilt = math.degrees(angles[best]) + 0.5 * float(np.clip(shift, -1.0, 1.0))
    # a raised relief lit from tilt t has first moment sum(darkening * x . t) = -tan(s) * volume
    rows, cols = np.nonzero(mask)
    x = cols - cols.mean()
    y = -(rows - rows.mean())
    direction = (math.cos(math.radians(tilt)), math.sin(math.radians(tilt)))
    moment = float((darkening[rows, cols] * (x * direction[0] + y * direction[1])).sum())
    return tilt + 180.0 if moment > 0 else tilt
