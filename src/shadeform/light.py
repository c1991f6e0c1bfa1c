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
from shadeform.preprocess import noise_level

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
    evidence : {"limb", "limb-peak", "rim", "relief", "relief-spectrum", "round"}
        What fixed the light: the occluding contour and the top of the object; the top and the
        brightest point (the contour could not fix the slant); a tilted rim and the top; round
        features fitted to a relief on a base facing the camera; such a relief's brightest point
        and spectrum (its features are not round); rings inside a round object.
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
    5. **A relief on a base facing the camera** (an evenly lit edge at the level of a good part
       of the object). The base level is ``k L_z``. The relief is fitted as a sum of round
       features (bumps, dimples, craters: ``z = f(|x - c|)``, each profile free) together with
       ``tau = L_xy / L_z``, by Gauss-Newton on the image (``"relief"``): the least-squares
       light and shape within that family [8]_. Features are found one by one where rings
       around a pixel shade as a round feature's do, then refined jointly; the result is kept
       only if it explains the image to near the noise. Otherwise (``"relief-spectrum"``) the
       brightest point bounds the slant from below, ``cos(slant) >= k L_z / I_max``, with
       equality when some facet faces the light, and, since a relief changes the image along
       the light's tilt only to first order, the tilt is the direction along which the line
       integrals of ``1 - I / (k L_z)`` vanish, where the image's spectrum is empty on the
       perpendicular frequency line [6]_; that tilt is biased by tens of degrees below a slant
       of 45 (``benchmarks/results/light.md``).

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
    .. [8] M. J. Brooks and B. K. P. Horn, "Shape and source from shading", Proc. IJCAI 1985,
       932-936 (shape and light together, by minimising the rendering error).

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
    noise = noise_level(image, mask, inside=inside)
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
        return _relief(image, mask, level, peak, noise, convex, info)
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
        return _relief(image, mask, level, peak, noise, convex, info)

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


def _relief(image, mask, level, peak, noise, convex, info) -> LightEstimate:
    """The light on a relief over a flat base facing the camera, at intensity ``level``: from
    round features fitted to it, else from the brightest point and the image's spectrum."""
    from threadpoolctl import threadpool_limits

    info["base_level"] = level
    # the fit's many small matrix products: BLAS threads cost more than they give, and on a
    # busy machine they spin against each other (10-25x slower measured)
    with threadpool_limits(1, user_api="blas"):
        fit = _round_features(image, mask, level, noise)
    if fit is not None:
        info.update(relief_features=fit.features, relief_residual=fit.residual)
        slant, tilt, albedo = _from_components(fit.across * fit.level, fit.level)
        return _result(slant, tilt, albedo, "relief", convex, info)
    slant = math.degrees(math.acos(min(level / peak, 1.0)))
    tilt = _relief_tilt(image, mask, level)
    return _result(slant, tilt, max(peak, level), "relief-spectrum", convex, info)


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


# --- a relief of round features on a flat base ---------------------------------------------------

# The search for features runs on the image block-averaged to about this many pixels across the
# relief, the final fit on about twice as many: enough pixels per feature, seconds per estimate.
_SEARCH_SPAN = 64
_REFINE_SPAN = 128
# Radius of the ring windows that find feature centres, as a fraction of the relief's span (at
# least 4 pixels of the search image), first choice then the retries. Set for features a
# twentieth to a tenth of the relief across, those of the synthetic bumps scene.
_RING_WINDOWS = (0.1, 0.13, 0.075)
# Each feature's slope profile: cubic B-spline coefficients over a disk of this many ring windows.
_PROFILE_KNOTS = 14
_FEATURE_REACH = 3.5
_MAX_FEATURES = 12
# Slopes beyond this (84 degrees) are cut back during a fit: no relief is that steep.
_MAX_SLOPE = 10.0
# Cauchy scale (fraction of the base level) of the robust fits, which must not bend the features
# already found to explain the ones not yet modelled.
_ROBUST_SCALE = 0.02
# A window fit seeds the relief if its light agrees with the best window's within this angle and
# length ratio; a feature joins if it cuts the squared residual to this fraction, and leaves if
# dropping it raises that by less than this factor.
_SEED_ANGLE = math.radians(20.0)
_SEED_RATIO = (0.7, 1.4)
_FEATURE_GAIN = 0.8
# Joint fits tried per pass when growing the relief by a feature, best window fit first.
_GROW_TRIALS = 6
_PRUNE_LOSS = 1.05
# Mean squared residual, over noise^2 and a fraction of the relief's variance: where the search
# stops (five exact features leave about 1e-4 of the variance of the synthetic bumps at the search
# size), and what a final fit must reach to be trusted.
_SEARCH_FLOOR = (1.5, 3e-4)
_FIT_ACCEPT = (2.0, 1e-2)
# When no search reaches that, the best fit is still used if it leaves under this fraction of the
# relief's variance: it found the features' shading, if not every detail (the synthetic bumps at
# slant 60 leave 3.4 %; a straight ridge, a chain that round features do not fit, 12-16 %).
_FIT_FALLBACK = 5e-2


@dataclass(frozen=True, eq=False)
class _Fit:
    """A joint fit of round features: ``k L_z``, ``tau`` (2,), the features as ``(centre (2,),
    slope coefficients (_PROFILE_KNOTS,))`` in ``(x, y)`` pixels, the mean squared residual and
    the residual (model minus image) at the fitted pixels."""

    level: float
    across: np.ndarray
    features: list
    mse: float
    residual: np.ndarray


@dataclass(frozen=True)
class _ReliefFit:
    """Round features fitted to a relief: ``across`` is ``L_xy / L_z`` (tangent of the slant
    along the tilt), ``level`` is ``k L_z``, ``residual`` the rms misfit over ``level``."""

    across: np.ndarray
    level: float
    features: int
    residual: float


def _round_features(image, mask, level, noise) -> _ReliefFit | None:
    """The light from round features (bumps, dimples, craters) on a flat base facing the camera.

    A round feature is a surface ``z = f(|x - c|)``: its normal at ``x`` leans along the radial
    direction ``u`` by the profile's slope ``s(r) = -f'(r)``, so with ``tau = L_xy / L_z`` it
    shades as ``I = k L_z (1 + s tau . u) / sqrt(1 + s^2)``, clipped at 0. Heights add where
    features overlap, and so do their gradients. A sum of such features, each profile a cubic
    B-spline, is fitted to the image with ``tau`` by Gauss-Newton: maximum likelihood under
    Gaussian noise for this family of surfaces (shape and source together by minimising the
    rendering error, after Brooks and Horn, 1985). A free-form relief could explain the image
    under many lights, each with its own distorted shape; restricted to round features the fit
    pins the light down (the shading's odd part around each centre follows the tilt, its even
    part the profile), and it reads the slant also when no facet faces the light, where the
    brightest point only bounds it.

    The features are found on a block-averaged copy of the image:

    1. at every pixel the rings around it are fitted by ``a(r) + b(r) . u``: around a round
       feature's centre ``a`` is ``n_z(r) - 1`` and ``b = sqrt(1 - n_z^2) tau`` (all in units of
       ``k L_z``). The share of the image's energy this explains peaks at the centres;
    2. a single feature, with its own light, is fitted in a window at each peak; those whose
       light agrees with the best one's (up to sign: a dimple lit from one side looks like a
       bump lit from the other) seed the joint fit, with that light;
    3. while the residual is above the noise, window fits at the residual's energy and ring
       peaks and at the unused seeds are tried, best first, and the first that cuts the residual
       by a fifth joins. These fits use a robust loss, so that the features found are not bent
       toward those still missing. Features whose loss the others make up for are dropped.

    The final fit, on a finer copy, is trusted when its residual is near the noise; if it is not,
    the search is repeated with larger, then smaller rings, and if none is, the best fit is still
    used when it explains all but a few per cent of the relief's variance. Of the two opposite lights a relief
    allows (raised features lit from one side, sunk ones from the other), the one that makes the
    features' total volume positive is returned.

    Returns
    -------
    _ReliefFit or None
        None when no feature is found or the fit does not explain the image (the relief is not
        made of round features, or they were not all found).
    """
    rows, cols = np.nonzero(mask)
    span = max(int(rows.max() - rows.min()) + 1, int(cols.max() - cols.min()) + 1)
    coarse = max(1, round(span / _SEARCH_SPAN))
    fine = max(1, round(span / _REFINE_SPAN))
    small, small_mask = _block_mean(image, mask, coarse)
    if np.count_nonzero(small_mask) < MIN_OBJECT_PIXELS:
        return None
    big, big_mask = _block_mean(image, mask, fine)
    x, y, values = _pixels(big, big_mask)
    variance = float(np.mean((values - level) ** 2))
    scale = coarse / fine
    tried = set()
    best = None
    # a search that misses a feature or misplaces one is tried again with other ring windows
    for size in _RING_WINDOWS:
        window = max(4, round(size * span / coarse))
        if window in tried:
            continue
        tried.add(window)
        # independent noise averages down with the block's side
        found = _search_features(small, small_mask, level, noise / coarse, window)
        if found is None:
            continue
        # the centre of block pixel c at one size is at (c + 0.5) * scale - 0.5 at the other
        features = [(np.array([(c[0] + 0.5) * scale - 0.5, (c[1] - 0.5) * scale + 0.5]), s)
                    for c, s in found.features]
        fit = _fit_features(x, y, values, found.level, found.across, features, window * scale,
                            robust=False)
        floor = _FIT_ACCEPT[0] * (noise / fine) ** 2
        if fit.mse <= floor + _FIT_ACCEPT[1] * variance:
            return _relief_fit(fit)
        if fit.mse <= floor + _FIT_FALLBACK * variance and (best is None or fit.mse < best.mse):
            best = fit
    # no search explained the image to near the noise: the best one, if it explains most of it
    return None if best is None else _relief_fit(best)


def _relief_fit(fit: _Fit) -> _ReliefFit:
    """The light of a joint fit: of the two opposite lights a relief allows, the one that makes
    the features' total volume positive (pi * integral of r^2 s(r) dr, from the coefficients)."""
    knots = np.arange(1, _PROFILE_KNOTS + 1, dtype=np.float64)
    raised = sum(float(knots ** 2 @ s) for _, s in fit.features) >= 0
    return _ReliefFit(across=fit.across if raised else -fit.across, level=fit.level,
                      features=len(fit.features), residual=math.sqrt(fit.mse) / fit.level)


def _search_features(image, mask, level, noise, window) -> _Fit | None:
    """Round features of a relief, found one by one (steps 1-3 of :func:`_round_features`)."""
    x, y, values = _pixels(image, mask)
    variance = float(np.mean((values - level) ** 2))
    floor = _SEARCH_FLOOR[0] * noise ** 2 + _SEARCH_FLOOR[1] * variance
    seeded = _seed_features(image, mask, level, window)
    if seeded is None:
        return None
    across, features, pool = seeded
    fit = _fit_features(x, y, values, level, across, features, window, robust=True,
                        tolerance=1e-6)
    tried: list = []
    while len(fit.features) < _MAX_FEATURES and fit.mse > floor:
        grown = _grow(image, mask, x, y, values, fit, window, pool, tried)
        if grown is None:
            break
        fit = grown
        pool = [(misfit, p) for misfit, p in pool if _is_new(p, fit.features)]
    while len(fit.features) > 1:
        # drop the feature the image misses least, if the others can make up for it
        params = _feature_params(fit.level, fit.across, fit.features)
        reaches = [_FEATURE_REACH * window] * len(fit.features)
        loss = []
        for i in range(len(fit.features)):
            without = params.copy()
            first = 5 + i * (2 + _PROFILE_KNOTS)
            without[first:first + _PROFILE_KNOTS] = 0.0
            miss = _render_features(without, x, y, reaches) - values
            loss.append(float(miss @ miss))
        i = int(np.argmin(loss))
        trial = _fit_features(x, y, values, fit.level, fit.across,
                              fit.features[:i] + fit.features[i + 1:], window, robust=True,
                              iterations=25, tolerance=1e-6)
        if trial.mse > max(_PRUNE_LOSS * fit.mse, floor):
            break
        fit = trial
    return fit


def _seed_features(image, mask, level, window):
    """Window fits at the ring peaks of the image (steps 1-2 of :func:`_round_features`).

    Returns ``(across, features, pool)``: the seeds' light, the seeds as features, and the
    window fits whose light disagrees as ``(misfit, params)`` to try later; or None.
    """
    reach = 2 * window
    seeds = []
    for _, centre, across in _ring_peaks(np.where(mask, image / level - 1.0, 0.0), mask, window,
                                         (), count=8, threshold=math.log(10.0)):
        params, misfit = _fit_window(image, mask, centre, reach, level, across)
        # a fit that ran off its peak, or onto a feature already seeded, found nothing new
        if math.dist(params[3:5], centre) > window or any(
                math.dist(params[3:5], other[3:5]) < 2 for other, _ in seeds):
            continue
        seeds.append((params, misfit))
    if not seeds:
        return None
    best = seeds[0][0][1:3]
    size = float(np.hypot(*best))
    if size == 0:
        return None

    def agrees(params):
        length = float(np.hypot(*params[1:3]))
        return (length > 0
                and abs(float(params[1:3] @ best)) >= math.cos(_SEED_ANGLE) * length * size
                and _SEED_RATIO[0] < length / size < _SEED_RATIO[1])

    axis = best / size
    start = [params for params, _ in seeds if agrees(params)]
    pool = [(misfit, params) for params, misfit in seeds if not agrees(params)]
    across = axis * float(np.median([abs(float(p[1:3] @ axis)) for p in start]))
    features = [_window_feature(p, reach, window, 1.0 if p[1:3] @ axis >= 0 else -1.0)
                for p in start]
    return across, features, pool


def _grow(image, mask, x, y, values, fit, window, pool, tried) -> _Fit | None:
    """The joint fit with one more feature (step 3 of :func:`_round_features`), or None.

    Window fits are made at the residual's energy and ring peaks not yet ``tried`` (then, if
    none joins, around them) and added to the ``pool``'s; of the :data:`_GROW_TRIALS` best, the
    first whose joint fit cuts the mean squared residual to :data:`_FEATURE_GAIN` of it joins.
    """
    from scipy import ndimage as ndi
    from skimage.feature import peak_local_max

    reach = 2 * window
    rest = np.zeros(image.shape)
    rest[mask] = -fit.residual / fit.level
    energy = ndi.gaussian_filter(rest ** 2, window / 2)
    spots = [np.array([float(c), -float(r)])
             for r, c in peak_local_max(energy, min_distance=window, num_peaks=3)]
    spots += [c for _, c, _ in _ring_peaks(rest, mask, window, [c for c, _ in fit.features],
                                           count=2, threshold=0.0)]
    spots = [s for s in spots if all(math.dist(s, t) >= 1 for t in tried)]
    tried += spots
    candidates = [(misfit, p) for misfit, p in pool if _is_new(p, fit.features)]
    for spot in spots:
        params, misfit = _fit_window(image, mask, spot, reach, fit.level, fit.across,
                                     iterations=25)
        if _is_new(params, fit.features) and all(
                math.dist(params[3:5], p[3:5]) >= 1 for _, p in candidates):
            candidates.append((misfit, params))
    candidates.sort(key=lambda item: item[0])
    for _, params in candidates[:_GROW_TRIALS]:
        sign = 1.0 if params[1:3] @ fit.across >= 0 else -1.0
        trial = _fit_features(x, y, values, fit.level, fit.across,
                              fit.features + [_window_feature(params, reach, window, sign)],
                              window, robust=True, iterations=10, tolerance=1e-5)
        if trial.mse < _FEATURE_GAIN * fit.mse:
            return _fit_features(x, y, values, trial.level, trial.across, trial.features,
                                 window, robust=True, tolerance=1e-6)
    return None


def _is_new(params, features) -> bool:
    """Whether a window fit's centre is at least 2 pixels from every feature's."""
    return all(math.dist(params[3:5], centre) >= 2 for centre, _ in features)


def _pixels(image, mask):
    """Object pixels as ``x`` (column), ``y`` (minus row) and intensity, each (n,)."""
    rows, cols = np.nonzero(mask)
    return cols.astype(np.float64), -rows.astype(np.float64), image[rows, cols]


def _block_mean(image, mask, factor):
    """The image averaged over ``factor x factor`` blocks; a block is object if all its pixels
    are (cropping the last rows and columns that do not fill a block)."""
    if factor == 1:
        return image, mask
    height, width = image.shape[0] // factor, image.shape[1] // factor

    def blocks(a):
        return a[:height * factor, :width * factor].reshape(height, factor, width, factor)

    return blocks(image).mean(axis=(1, 3)), blocks(mask).all(axis=(1, 3))


def _ring_scores(deviation, window):
    """Rings around every pixel fitted by a round feature (step 1 of :func:`_round_features`).

    ``deviation`` is ``I / (k L_z) - 1`` (0 off the object). Around a round feature's centre the
    ring of radius ``r`` reads ``a(r) + b(r) . u``, ``u`` the unit vector from the centre, with
    ``a = n_z - 1 <= 0`` and ``b = sqrt(1 - n_z^2) tau``. Ring means, and first harmonics by
    correlation with ``cos`` and ``sin`` of the angle, come from FFT correlations that share the
    image's transform.

    Returns
    -------
    across : (H, W, 2) float64
        Least-squares ``tau`` from the rings around each pixel.
    score : (H, W) float64
        ``-log`` of the share of the energy within ``window`` that the rings leave unexplained.
    energy : (H, W) float64
        Sum of ``deviation^2`` within ``window``.
    """
    from scipy import fft

    reach = window + 1
    dr, dc = np.mgrid[-reach:reach + 1, -reach:reach + 1]
    radius = np.hypot(dc, dr)
    angle = np.arctan2(-dr, dc)  # y up
    height, width = deviation.shape
    shape = tuple(fft.next_fast_len(n + 2 * reach, real=True) for n in (height, width))
    spectrum = fft.rfft2(deviation, shape)

    def correlate(kernel, transform=spectrum):
        # sum over the kernel's offsets v of deviation(x + v) kernel(v), zero past the image
        full = fft.irfft2(transform * fft.rfft2(kernel[::-1, ::-1], shape), shape)
        return full[reach:reach + height, reach:reach + width]

    disk = (radius < window + 0.5).astype(np.float64)
    energy = correlate(disk, fft.rfft2(deviation * deviation, shape))
    explained = np.zeros(deviation.shape)
    moment = np.zeros(deviation.shape + (2,))
    weight = np.full(deviation.shape, 1e-300)
    for k in range(1, window + 1):
        ring = np.abs(radius - k) < 0.5
        count = float(ring.sum())
        spread = float((ring * np.cos(angle) ** 2).sum())
        mean = correlate(ring.astype(np.float64)) / count
        harmonic = np.stack([correlate(ring * np.cos(angle)), correlate(ring * np.sin(angle))],
                            axis=-1) / spread
        # a brighter ring than the base is not a round feature's
        explained += count * np.minimum(mean, 0.0) ** 2
        lean = np.sqrt(1.0 - np.clip(1.0 + mean, 0.0, 1.0) ** 2)
        moment += (spread * lean)[..., None] * harmonic
        weight += spread * lean * lean
    explained += (moment ** 2).sum(axis=-1) / weight
    across = moment / weight[..., None]
    left = 1.0 - np.clip(explained / np.maximum(energy, 1e-300), 0.0, 1.0)
    return across, -np.log(np.maximum(left, 1e-9)), energy


def _ring_peaks(deviation, mask, window, exclude, *, count, threshold):
    """Up to ``count`` peaks of :func:`_ring_scores` at least ``window / 2`` from the centres in
    ``exclude``, best first, as ``(score, centre (x, y), across)``. Pixels whose window leaves the
    object, or holds under 5% of the largest energy (the bare base), are not candidates."""
    from scipy import ndimage as ndi
    from skimage.feature import peak_local_max

    across, score, energy = _ring_scores(deviation, window)
    inner = ndi.binary_erosion(mask, iterations=max(window // 2, 1))
    if not inner.any():
        return []
    score = np.where(inner & (energy > 0.05 * energy[inner].max()), score, 0.0)
    found = []
    for r, c in peak_local_max(score, min_distance=2, threshold_abs=threshold):
        centre = np.array([float(c), -float(r)])
        if all(math.dist(centre, e) >= window / 2 for e in exclude):
            found.append((float(score[r, c]), centre, across[r, c]))
    found.sort(key=lambda item: -item[0])
    return found[:count]


def _bspline(t):
    """Uniform cubic B-spline at ``t >= 0`` (n,): index of the first of the four coefficients
    that count, their weights (4, n) and the weights' derivatives in ``t`` (4, n)."""
    first = np.floor(t).astype(np.int64)
    u = t - first
    u2, u3 = u * u, u * u * u
    weights = np.stack([(1 - u) ** 3, 3 * u3 - 6 * u2 + 4, -3 * u3 + 3 * u2 + 3 * u + 1, u3]) / 6
    slopes = np.stack([-(1 - u) ** 2, 3 * u2 - 4 * u, -3 * u2 + 2 * u + 1, u2]) / 2
    return first - 1, weights, slopes


def _profile(coefficients, spacing, radius):
    """Slope profile ``s(radius)`` and ``ds/dr`` of B-spline ``coefficients`` c_1..c_K on knots
    ``spacing`` apart, with ``c_0 = 0`` and ``c_-1 = -c_1`` (odd about the centre, so the top is
    level and smooth) and ``c_j = 0`` past ``K`` (the feature ends at ``(K + 2) * spacing``).
    Also returns the coefficient index of each weight (4, n) and the weights (4, n)."""
    knots = coefficients.size
    padded = np.zeros(knots + 6)  # c_j at j + 1, j = -1 .. K + 4
    padded[2:knots + 2] = coefficients
    padded[0] = -coefficients[0]
    first, weights, slopes = _bspline(radius / spacing)
    index = first[None, :] + np.arange(4)[:, None]
    value = (padded[index + 1] * weights).sum(axis=0)
    rate = (padded[index + 1] * slopes).sum(axis=0) / spacing
    return value, rate, index, weights


def _feature_params(level, across, features) -> np.ndarray:
    """Parameter vector ``(k L_z, tau_x, tau_y, then per feature c_x, c_y, c_1..c_K)``."""
    return np.concatenate([[level, *across]] + [np.r_[c, s] for c, s in features])


def _render_features(params, x, y, reaches, *, jacobian=False):
    """Image of round features on a flat base, and its Jacobian (compiled; the numpy
    :func:`_render_features_reference` below is its reference)."""
    from shadeform._relief import render_features

    knots = (params.size - 3) // len(reaches) - 2 if reaches else 0
    image = np.empty(x.size)
    jac = np.zeros((x.size, params.size) if jacobian else (0, 0))
    render_features(np.ascontiguousarray(params, dtype=np.float64), np.ascontiguousarray(x, dtype=np.float64),
                    np.ascontiguousarray(y, dtype=np.float64), np.asarray(reaches, dtype=np.float64).reshape(-1),
                    knots, image, jac, jacobian)
    return (image, jac) if jacobian else image


def _render_features_reference(params, x, y, reaches, *, jacobian=False):
    """Image of round features on a flat base, and its Jacobian, vectorised over pixels.

    Parameters
    ----------
    params : (3 + F * (2 + K),) float64
        See :func:`_feature_params`; slopes are ``-dz/dr`` (positive on a bump's flanks).
    x, y : (n,) float64
        Pixel coordinates (``x`` = column, ``y`` = minus row).
    reaches : sequence of float
        Each feature's radius.
    jacobian : bool
        Also return the (n, P) derivatives of the image in ``params``.

    Returns
    -------
    (n,) float64, and (n, P) float64 if ``jacobian``
        ``k L_z max(0, (1 - tau . grad z) / sqrt(1 + |grad z|^2))``.
    """
    count = x.size
    level, tx, ty = params[:3]
    knots = (params.size - 3) // len(reaches) - 2 if reaches else 0
    gx = np.zeros(count)
    gy = np.zeros(count)
    parts = []
    for f, reach in enumerate(reaches):
        base = 3 + f * (2 + knots)
        dx, dy = x - params[base], y - params[base + 1]
        radius = np.hypot(dx, dy)
        near = np.nonzero(radius < reach)[0]
        r = np.maximum(radius[near], 1e-12)
        slope, rate, index, weights = _profile(params[base + 2:base + 2 + knots],
                                               reach / (knots + 2), r)
        ux, uy = dx[near] / r, dy[near] / r
        # grad z = -s(r) u; overlapping features add their heights, so their gradients
        gx[near] -= slope * ux
        gy[near] -= slope * uy
        parts.append((base, near, r, slope, rate, index, weights, ux, uy))
    root = np.sqrt(1.0 + gx * gx + gy * gy)
    facing = 1.0 - tx * gx - ty * gy
    shade = facing / root
    lit = shade > 0
    image = level * np.where(lit, shade, 0.0)
    if not jacobian:
        return image
    total = params.size
    jac = np.zeros((count, total))
    jac[:, 0] = np.where(lit, shade, 0.0)
    jac[:, 1] = np.where(lit, -level * gx / root, 0.0)
    jac[:, 2] = np.where(lit, -level * gy / root, 0.0)
    # d image / d grad z
    ex = np.where(lit, level * (-tx / root - facing * gx / root ** 3), 0.0)
    ey = np.where(lit, level * (-ty / root - facing * gy / root ** 3), 0.0)
    flat = jac.reshape(-1)
    for base, near, r, slope, rate, index, weights, ux, uy in parts:
        qx, qy = ex[near], ey[near]
        # d(grad z)/d(centre) = s' u u^T + (s / r)(I - u u^T)
        radial = rate - slope / r
        along = slope / r
        jac[near, base] = qx * (radial * ux * ux + along) + qy * (radial * uy * ux)
        jac[near, base + 1] = qx * (radial * ux * uy) + qy * (radial * uy * uy + along)
        # d(grad z)/d c_j = -B_j(r) u; c_-1 is -c_1
        outward = -(qx * ux + qy * uy)
        column = np.where(index == -1, 1, index)
        value = np.where(index == -1, -weights, weights) * outward
        keep = (column >= 1) & (column <= knots)
        pixel = np.broadcast_to(near, column.shape)
        np.add.at(flat, pixel[keep] * total + base + 1 + column[keep], value[keep])
    return image, jac


def _levenberg(fun, params, values, *, scale=None, bounded=None, iterations=50,
               tolerance=1e-7) -> np.ndarray:
    """Levenberg-Marquardt on ``sum(rho(fun(p) - values))``, ``rho(e) = e^2`` or, with a
    ``scale``, the Cauchy loss ``scale^2 log(1 + e^2 / scale^2)`` (by reweighted steps).
    ``fun(p, True)`` returns the model and its Jacobian, ``fun(p, False)`` the model. Parameters
    where ``bounded`` is true are kept within ``+-_MAX_SLOPE``."""

    def loss(error):
        if scale is None:
            return float(error @ error), np.ones(error.size)
        z = (error / scale) ** 2
        return float(scale * scale * np.log1p(z).sum()), 1.0 / (1.0 + z)

    damping = 1e-3
    model, jac = fun(params, True)
    error = model - values
    cost, weight = loss(error)
    for _ in range(iterations):
        root = np.sqrt(weight)
        scaled = jac * root[:, None]
        normal = scaled.T @ scaled
        gradient = scaled.T @ (error * root)
        diagonal = np.diag(normal) + 1e-12 * max(float(normal.diagonal().max()), 1e-300)
        while True:
            try:
                step = np.linalg.solve(normal + damping * np.diag(diagonal), gradient)
            except np.linalg.LinAlgError:
                damping *= 10.0
                continue
            trial = params - step
            if bounded is not None:
                trial = np.where(bounded, np.clip(trial, -_MAX_SLOPE, _MAX_SLOPE), trial)
            trial_error = fun(trial, False) - values
            trial_cost, trial_weight = loss(trial_error)
            if trial_cost < cost:
                done = cost - trial_cost <= tolerance * cost
                params, error, cost, weight = trial, trial_error, trial_cost, trial_weight
                damping = max(damping / 3.0, 1e-12)
                break
            damping *= 4.0
            if damping > 1e10:
                return params
        if done:
            break
        model, jac = fun(params, True)
    return params


def _slopes_from_rings(values, radius, level, knots, spacing):
    """First guess of a bump's slope coefficients: each ring's mean brightness read as ``n_z``
    (the light's lean averages out around a ring), ``s = sqrt(1 / n_z^2 - 1)``, at most 1.5."""
    index = np.rint(radius / spacing).astype(np.int64)
    keep = (index >= 1) & (index <= knots)
    sums = np.bincount(index[keep], values[keep], minlength=knots + 1)
    counts = np.bincount(index[keep], minlength=knots + 1)
    mean = np.where(counts > 0, sums / np.maximum(counts, 1), level)[1:] / level
    return np.minimum(np.sqrt(np.maximum(1.0 / np.clip(mean, 0.05, 1.0) ** 2 - 1.0, 0.0)), 1.5)


def _fit_window(image, mask, centre, reach, level, across, iterations=40):
    """One round feature with its own light, fitted to the object pixels within ``reach`` of
    ``centre``. Returns its parameters (:func:`_feature_params`) and the misfit's share of the
    window's energy about ``level``."""
    x, y, values = _pixels(image, mask)
    near = np.hypot(x - centre[0], y - centre[1]) <= reach
    x, y, values = x[near], y[near], values[near]
    if values.size < 4 * (_PROFILE_KNOTS + 5):
        return _feature_params(level, across, [(centre, np.zeros(_PROFILE_KNOTS))]), math.inf
    slopes = _slopes_from_rings(values, np.hypot(x - centre[0], y - centre[1]), level,
                                _PROFILE_KNOTS, reach / (_PROFILE_KNOTS + 2))
    bounded = np.arange(5 + _PROFILE_KNOTS) >= 5
    params = _levenberg(lambda p, j: _render_features(p, x, y, [reach], jacobian=j),
                        _feature_params(level, across, [(centre, slopes)]), values,
                        bounded=bounded, iterations=iterations)
    miss = _render_features(params, x, y, [reach]) - values
    spread = float(np.mean((values - level) ** 2))
    return params, float(np.mean(miss * miss)) / max(spread, 1e-300)


def _window_feature(params, reach, window, sign):
    """A window fit as a feature of the joint fit: its centre, and its slope profile (times
    ``sign``, -1 to read it as a dimple under the opposite light) on the joint fit's knots,
    0 past the window."""
    spacing = _FEATURE_REACH * window / (_PROFILE_KNOTS + 2)
    radius = spacing * np.arange(1, _PROFILE_KNOTS + 1)
    slope = _profile(params[5:], reach / (_PROFILE_KNOTS + 2), np.minimum(radius, reach))[0]
    return params[3:5].copy(), sign * np.where(radius < reach, slope, 0.0)


def _fit_features(x, y, values, level, across, features, window, *, robust, iterations=40,
                  tolerance=1e-7):
    """Joint fit of round features and the light (:class:`_Fit`), from a first guess, with the
    Cauchy loss if ``robust``."""
    reaches = [_FEATURE_REACH * window] * len(features)
    params = _feature_params(level, across, features)
    bounded = np.ones(params.size, dtype=bool)
    bounded[:3] = False
    for f in range(len(features)):
        bounded[3 + f * (2 + _PROFILE_KNOTS):5 + f * (2 + _PROFILE_KNOTS)] = False
    params = _levenberg(lambda p, j: _render_features(p, x, y, reaches, jacobian=j), params,
                        values, scale=_ROBUST_SCALE * level if robust else None, bounded=bounded,
                        iterations=iterations, tolerance=tolerance)
    residual = _render_features(params, x, y, reaches) - values
    step = 2 + _PROFILE_KNOTS
    fitted = [(params[3 + f * step:5 + f * step], params[5 + f * step:3 + (f + 1) * step])
              for f in range(len(features))]
    return _Fit(level=float(params[0]), across=params[1:3].copy(), features=fitted,
                mse=float(np.mean(residual * residual)), residual=residual)
