"""Estimate the light, and ``k * albedo``, from one shading image.

One image of a Lambertian object under one distant light holds the light in several places,
none of which every object has: the occluding contour (:mod:`shadeform.light.contour`), rings
inside a round object (:mod:`shadeform.light.rings`), a relief's flat base and round features
(:mod:`shadeform.light.relief`). :func:`estimate_light` checks the input once (refusing masks
with no outline or no inside to read), measures the object's levels once, asks each kind of
evidence that applies for a reading (each answers one or None, with the spread it measures) and
turns the one it takes into a :class:`LightEstimate` with its confidence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from shadeform._checks import check_choice, check_mask, shading_image
from shadeform._deprecated import renamed_attributes, renamed_keywords
from shadeform.errors import InputError
from shadeform.light._evidence import (
    CONFIDENCE_ANGLE,
    MIN_OBJECT_PIXELS,
    Reading,
    angle_between,
    confidence,
    measure_levels,
)
from shadeform.light.contour import MIN_BOUNDARY_PIXELS, find_boundary, read_contour
from shadeform.light.relief import read_relief
from shadeform.light.rings import read_rings
from shadeform.light.vectors import light_from_slant_tilt

__all__ = ["LightEstimate", "estimate_light", "ESTIMATION_CUES", "MIN_OBJECT_PIXELS", "CONFIDENCE_ANGLE"]

#: The cues :func:`estimate_light` can read the light from (its ``cue``): ``"contour"``, the
#: occluding contour (or, without one, a flat base's relief); ``"round"``, the rings inside a
#: round object.
ESTIMATION_CUES = ("contour", "round")

# A mask none of whose pixels lies this far (pixels) from its edge is all outline: the outline's
# normals and sub-pixel positions come from the mask smoothed over 2 pixels, the top's level from
# a disk of 3 pixels' radius, so nothing would be left to read inside.
_MIN_DEPTH = 3.0
# A light at the horizon or beyond lights nothing the camera sees: slants are cut back to this.
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
    evidence : {"limb", "limb-brightest", "limb-peak", "rim", "relief", "relief-spectrum", "round"}
        What fixed the light: the occluding contour and the top of the object; the occluding
        contour and the brightest point (the mask stops at a shadow's edge, or the top is too dark
        to face the viewer); the top and the brightest point (the contour could not fix the
        slant); a tilted rim and the top; round features fitted to a relief on a base facing the
        camera; such a relief's brightest point and spectrum (its features are not round); rings
        inside a round object.
    confidence : float
        In ``[0, 1]``: the chance that the true light lies within :data:`CONFIDENCE_ANGLE` (10)
        degrees of this one, when the estimate's error is taken as an isotropic Gaussian on the
        sphere whose spread the evidence itself measures (``info["spread"]``, the root-mean-square
        angle in degrees): ``1 - exp(-(10 / spread)^2)``. How each kind of evidence measures its
        spread is in :func:`estimate_light` (Notes); 0.5 is a spread of 12 degrees, 0.9 one of 6.6.
    info : dict
        Measured quantities behind the estimate (levels, fitted coefficients, pixel counts).
    """

    light: np.ndarray
    albedo: float
    slant: float
    tilt: float
    evidence: str
    confidence: float = 0.0
    info: dict = field(default_factory=dict)

    @property
    def unsure(self) -> bool:
        """Whether the estimate is less likely than not to be within :data:`CONFIDENCE_ANGLE` of
        the true light (``confidence < 0.5``: even odds, not a tuned level); the CLI and the app
        then say so and ask for the light."""
        return self.confidence < 0.5


@renamed_keywords(method="cue")
def estimate_light(image, mask=None, *, cue: str = "contour", convex: bool = True) -> LightEstimate:
    """Estimate the direction and brightness of a distant light from one shading image.

    Lambertian surface of uniform albedo, one distant light, orthographic camera, attached shadows
    (``I = k * albedo * max(0, N . L)``); only object pixels are read.

    ``cue="contour"`` (default) reads, in order of reliability:

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

       **Or the brightest point** (``"limb-brightest"``), when the top cannot be: a smooth
       object whose outline is one occluding contour has every normal of the visible hemisphere
       somewhere, so its brightest Lambertian level is ``k`` and ``k L_z =
       sqrt(I_max^2 - |A|^2)``. That is used where the mask stops at the edge of the attached
       shadow rather than at the outline, as a mask thresholded from the image does under an
       oblique light: the mask's deepest point then lies toward the light and is brighter than
       the top. The limb fit of the outline's lit side says how deep the attached shadow reaches
       inside the far side of the outline (``b . A + kappa sqrt(d) < 0``); where the mask holds
       that shadow the image is dark there, where it stops at the shadow's edge the image is
       lit just inside it. The far side is then no outline and only the lit side is fitted;
       where the shadow is too thin to tell, the far-side pixels that are dim but lit (a shadow's
       edge, or the shadowed outline) are left out of the fit. The brightest point is used too
       where the top is darker than the light would allow (three quarters of the lit pixels
       brighter than ``|(A, top)|``, no Lambertian surface can be: dark paint or a shadow at
       the top, as on DiLiGenT's ``reading``).
    3. **The brightest point** (``evidence="limb-peak"`` in the result). When the contour
       cannot fix ``A`` (only straight sides lit, as on a cylinder), the brightest point is taken
       to face the light: ``k = I_max``, ``cos(slant) = k L_z / I_max``, and the tilt is the lit
       contour's mean normal. Where the contour does read a light but leaves its slant loose
       (standard error above 1.5 degrees), the two are weighed by their spreads and the surer is
       kept: paint can make the brightest point a poor witness (a dark-painted top under a
       white-painted foot reads as a grazing light: MIT-Berkeley's raw ``frog1``, ``deer``).
    4. **A tilted rim** (``"rim"``: the edge of a cap, a bowl or a saddle seen from above). The
       boundary normals share one slant ``theta`` and the fit gains a constant term
       ``k cos(theta) L_z``; with the top's ``k L_z`` that gives ``theta``, then ``k L_xy``.
    5. **A relief on a base facing the camera** (an evenly lit edge at the level of a good part
       of the object). The base level is ``k L_z``. The relief is fitted as a sum of round
       features (bumps, dimples, craters: ``z = f(|x - c|)``, each profile free) together with
       ``tau = L_xy / L_z``, by nonlinear least squares on the image (``"relief"``): the
       least-squares light and shape within that family [8]_. Features are found one by one where rings
       around a pixel shade as a round feature's do, then refined jointly; the result is kept
       only if it explains the image to near the noise. Otherwise (``"relief-spectrum"``) the
       brightest point bounds the slant from below, ``cos(slant) >= k L_z / I_max``, with
       equality when some facet faces the light, and, since a relief changes the image along
       the light's tilt only to first order, the tilt is the direction along which the line
       integrals of ``1 - I / (k L_z)`` vanish, where the image's spectrum is empty on the
       perpendicular frequency line [6]_; that tilt is biased by tens of degrees below a slant
       of 45 (``benchmarks/results/light.md``).

    ``cue="round"`` suits photographs of round objects: real materials darken toward the
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
    cue : {"contour", "round"}, optional
        What the estimate reads (see above, :data:`ESTIMATION_CUES`): the occluding contour
        (else a flat base's relief), or the rings inside a round object.
    convex : bool, optional
        Whether the object bulges toward the camera. A concave surface (a bowl seen from above,
        a relief of dents) lit from one side gives exactly the image of its convex twin lit from
        the opposite side [7]_, so the image cannot tell; ``False`` turns the tilt by 180 degrees.

    Returns
    -------
    LightEstimate
        ``light`` (3,), ``albedo``, ``slant`` and ``tilt`` in degrees, the ``evidence`` that
        fixed it, its ``confidence`` and measured ``info``.

    Raises
    ------
    InputError
        An image that is not one channel or holds NaN, inf or negative values; a mask of another
        shape, empty or smaller than :data:`MIN_OBJECT_PIXELS`; a black object; a mask every pixel
        of which lies within 2 pixels of its edge (a strip or an outline: no inside to read); a mask touching
        all four sides of the image (no outline in view, or the mask is the background) unless
        the object is a relief of round features on a flat base filling the frame; an object
        whose outline has fewer than 20 pixels off the image frame (unless it is a relief on a
        flat base); an unknown ``cue``.

    Notes
    -----
    **Highlights, clipping and shadows.** The fits at the top and the brightest point leave out
    values far above their quadratic (narrow specular highlights) and a plateau at the brightest
    value (clipped by the camera), reaching past it; the outline fit clips at zero (attached
    shadows) and weighs large misfits down. A broad glossy lobe at the top still raises
    ``k L_z``, and, where the brightest point fixes ``k``, a highlight raises ``k`` (the slant
    comes out low); the confidence then falls where the top and the brightest point disagree.

    **Confidence.** Each kind of evidence measures the spread of its own light (the
    root-mean-square angle between it and the truth) from independent readings of it, and
    :attr:`LightEstimate.confidence` turns that into the chance of being within 10 degrees:

    - outline readings (``limb``, ``limb-brightest``, ``rim``): a jackknife over eight sectors of
      the outline, the whole reading made again with each left out (decisions a sector tips
      count too), in quadrature with the angle between the lights the top and the brightest
      point give; for ``limb``, also the angle to the rings' light (``cue="round"``), which
      the darkening of real materials toward the outline does not bias;
    - ``relief``: the covariance of the fitted ``L_xy / L_z`` (the residual's variance times the
      inverse of ``J^T J``);
    - ``round``: a jackknife over the rings;
    - ``limb-peak`` and ``relief-spectrum``, where the brightest point only bounds the slant from
      below: the slant spread evenly between that bound and the horizon, for ``limb-peak`` in
      quadrature with the angle to the contour's loose light where there is one (and that loose
      light's own spread: its slant's standard error and the top's disagreement with the
      brightest point, in quadrature).

    Measured on held-out real photos (every MIT-Berkeley photo, every sixth DiLiGenT one; not the
    frontal photos the bars use) in ``benchmarks/results/light.md``; the spread misses biases
    that every reading shares, so it is too small where the outline and the interior are biased
    alike.

    **What one image cannot tell.**
    What one image cannot tell, whatever the cue: a cylinder seen side-on looks the same
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
    cue = check_choice(cue, ESTIMATION_CUES, "light estimation cue")
    if not isinstance(convex, (bool, np.bool_)):
        raise InputError(f"convex must be True or False, got {convex!r}")
    levels = measure_levels(image, mask)
    depth = float(levels.inside.max())
    if depth < _MIN_DEPTH:
        raise InputError(
            f"the mask is nowhere more than {2 * depth:.0f} pixels across (a strip or an outline, not "
            "a filled object), so it holds no shading to read a light from; give a filled mask of "
            "the whole object"
        )
    boundary = find_boundary(mask)
    all_round = bool(mask[0].any() and mask[-1].any() and mask[:, 0].any() and mask[:, -1].any())
    if all_round or boundary.rows.size < MIN_BOUNDARY_PIXELS:
        # no outline in view: only a relief on a flat base filling the frame can still be read
        from scipy import ndimage as ndi

        edge = mask & ~ndi.binary_erosion(mask, border_value=0)
        reading = read_relief(image, mask, levels, image[edge])
        if all_round and reading is not None and reading.evidence != "relief":
            reading = None  # a flat stretch with no features read: likely the background
        if reading is None and all_round:
            raise InputError(
                "the mask touches all four sides of the image, so the object's outline is not in "
                "view (or the mask is the background); frame the whole object with a margin of "
                "background, or give the object's mask"
            )
        if reading is None:
            raise InputError(
                f"the object's outline has only {boundary.rows.size} pixels off the image frame; "
                "frame the whole object with a margin of background"
            )
    elif cue == "round":
        reading = read_rings(image, mask, levels)
        if reading is None:
            raise InputError(
                "too few lit rings inside the object for cue='round' (is it dark, tiny or "
                "lit from behind?); try cue='contour'"
            )
    else:
        reading = read_relief(image, mask, levels, image[boundary.rows, boundary.cols])
        if reading is None:
            reading = _checked_by_rings(read_contour(image, mask, levels, boundary), image, mask, levels)
    info = {
        "noise": levels.noise,
        "peak": levels.peak,
        "top": levels.top,
        "boundary_pixels": int(boundary.rows.size),
    }
    return _estimate(reading, convex, info | reading.info)


def _checked_by_rings(reading: Reading, image, mask, levels) -> Reading:
    """A limb reading whose spread also counts its disagreement with the rings inside the object
    (:func:`shadeform.light.rings.read_rings`), an independent reading of ``k L_xy`` that real
    materials' darkening toward the outline does not bias; the angle between the two lights is
    added in quadrature (``info["rings_angle"]``). Other readings, and images without enough lit
    rings, are returned as they are."""
    if reading.evidence != "limb":
        return reading  # the rings read the top's level too, which the other readings set aside
    rings = read_rings(image, mask, levels)
    if rings is None:
        return reading
    gap = angle_between(rings.light, reading.light)
    reading.info["rings_angle"] = gap
    return replace(reading, spread=math.hypot(reading.spread, gap))


def _estimation_input(image, mask):
    """Validated ``(image float64 (H, W), mask bool (H, W))``."""
    array = shading_image(np.asarray(image))
    if mask is None:
        from shadeform.preprocess import object_mask

        mask = object_mask(array)
    mask = check_mask(mask, array.shape)
    count = int(mask.sum())
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


def _estimate(reading: Reading, convex: bool, info: dict) -> LightEstimate:
    """The :class:`LightEstimate` of a reading: slant cut back to :data:`_MAX_SLANT`, tilt turned
    by 180 degrees for a concave object and brought into ``(-180, 180]``."""
    slant, tilt = min(reading.slant, _MAX_SLANT), reading.tilt
    if slant < 1e-9:
        slant, tilt = 0.0, 0.0
    if not convex and slant > 0:
        tilt += 180.0
    tilt = -((-tilt + 180.0) % 360.0 - 180.0)  # into (-180, 180]
    light = light_from_slant_tilt(slant, tilt)
    light.flags.writeable = False
    return LightEstimate(
        light=light,
        albedo=float(reading.albedo),
        slant=float(slant),
        tilt=float(tilt),
        evidence=reading.evidence,
        confidence=confidence(reading.spread),
        info=info | {"spread": float(reading.spread)},
    )


#: The old name of ESTIMATION_CUES, for one release.
OLD_NAMES = {"ESTIMATION_METHODS": ("ESTIMATION_CUES", lambda: ESTIMATION_CUES)}
__getattr__ = renamed_attributes(__name__, OLD_NAMES)
