"""Before shading is read: find the object, and smooth the image inside it.

Steps 2 and 3 of the 2002 system (``DESIGN.md``): the object's silhouette, on a dark background
as in 2002 or on a light one (:func:`object_mask`; its rules are in :mod:`shadeform.masks`), then
an optional filter with a window radius (:func:`apply_filter`): none, Gaussian, mean, median or
minimum. Filters work inside the mask only, so the background never bleeds into the object's
edge, where shape from shading is most sensitive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage as ndi

from shadeform._checks import check_mask, is_number
from shadeform.errors import InputError

__all__ = [
    "object_mask",
    "Filter",
    "FILTER_KINDS",
    "parse_filter",
    "apply_filter",
    "noise_level",
    "image_detail",
    "Detail",
    "OUTLIER_SIGMAS",
    "srgb_to_linear",
]

#: Filter kinds, in the order the 2002 system offered them ("none" was called "blank").
FILTER_KINDS = ("none", "gaussian", "mean", "median", "minimum")


def object_mask(
    image: np.ndarray,
    *,
    threshold: float | None = None,
    dark: bool | None = None,
    fill_holes: bool = True,
    largest: bool = True,
) -> np.ndarray:
    """Find the object in a photo: bright on a dark background, or dark on a light one.

    Without ``threshold``, :func:`shadeform.masks.find_object` decides (its description says
    how): the background is the class of Otsu's split that covers more of the image's frame,
    with its uneven light (a plane fitted to the frame) taken off; pixels of the object's class
    seed the object and it grows (hysteresis) through every connected pixel that stands out
    from the background as the frame shows it (3 noise sigmas, its 95th percentile, at least
    2 % of the way to Otsu's threshold): a Lambertian object's rim, where the surface turns
    away, is dim but still object. Parts with most of their outline on the frame are
    background; a picture with no distinct background (one surface filling the frame) is all
    object.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) array_like
        Intensities, e.g. from :func:`shadeform.load_image`, or linear colours (without
        ``threshold``: :func:`shadeform.masks.find_object` then models colours too).
    threshold : float, optional
        Use ``image > threshold`` (``<`` with ``dark=True``) instead of the automatic choice.
    dark : bool, optional
        Whether the object is darker than its background. Automatic by default; with
        ``threshold``, None means False (a bright object).
    fill_holes : bool
        Fill holes inside the object (dark spots, specular pits, shadows enclosed by it).
    largest : bool
        Keep only the largest 8-connected part that is not mostly frame border (drops dust,
        stray reflections and strips of background).

    Returns
    -------
    (H, W) bool
        True on the object.

    Raises
    ------
    InputError
        If ``image`` is neither (H, W) nor (H, W, 3) or holds NaN, if it is black or constant (nothing to separate),
        or if no pixel is on the object's side of ``threshold``.

    References
    ----------
    N. Otsu, "A threshold selection method from gray-level histograms", IEEE Trans. SMC 9(1),
    1979. J. Canny, "A computational approach to edge detection", IEEE TPAMI 8(6), 1986
    (hysteresis).
    """
    from shadeform.masks import find_object, threshold_object

    if threshold is None:
        return find_object(image, dark=dark, fill_holes=fill_holes, largest=largest).mask
    return threshold_object(image, threshold, dark=bool(dark), fill_holes=fill_holes, largest=largest)


@dataclass(frozen=True)
class Filter:
    """A smoothing filter and its size.

    Attributes
    ----------
    kind : {"none", "gaussian", "mean", "median", "minimum"}
        What to apply.
    size : float
        Gaussian: the standard deviation sigma in pixels. Mean, median, minimum: the window
        radius r, a whole number; the window is ``(2r + 1) x (2r + 1)``. Ignored for "none".
        0 leaves the image unchanged.
    """

    kind: str = "none"
    size: float = 0.0

    def __post_init__(self):
        if self.kind not in FILTER_KINDS:
            raise InputError(f"unknown filter kind {self.kind!r}; choose one of {', '.join(FILTER_KINDS)}")
        size = self.size
        if not is_number(size):
            raise InputError(f"filter size must be a number, got {size!r}")
        if not math.isfinite(size) or size < 0:
            raise InputError(f"filter size must be finite and >= 0, got {size!r}")
        if self.kind in ("mean", "median", "minimum") and size != int(size):
            raise InputError(
                f"{self.kind} filter needs a whole-number window radius, got {size!r}; "
                f"e.g. '{self.kind}:{max(1, round(size))}'"
            )
        object.__setattr__(self, "size", float(size))

    def __str__(self) -> str:
        if self.kind == "none":
            return "none"
        return f"{self.kind}:{self.size:g}"


def parse_filter(spec: str | Filter | None) -> Filter:
    """Read a filter from text such as ``"gaussian:2"``, ``"median:3"`` or ``"none"``.

    Parameters
    ----------
    spec : str, Filter or None
        ``"KIND:SIZE"`` with KIND one of :data:`FILTER_KINDS` (case and spaces ignored), or
        ``"none"``; ``None`` means no filter; a :class:`Filter` is returned as it is.

    Returns
    -------
    Filter

    Raises
    ------
    InputError
        If the text is not of that form.

    Examples
    --------
    >>> parse_filter("median:2")
    Filter(kind='median', size=2.0)
    >>> str(parse_filter(" Gaussian : 1.5 "))
    'gaussian:1.5'
    """
    if spec is None:
        return Filter()
    if isinstance(spec, Filter):
        return spec
    help_text = (
        f"give 'KIND:SIZE' with KIND one of {', '.join(FILTER_KINDS)} "
        "(e.g. 'gaussian:1.5', 'median:2'), or 'none'"
    )
    if not isinstance(spec, str):
        raise InputError(f"bad filter {spec!r}: {help_text}")
    kind, sep, size = (part.strip() for part in spec.strip().lower().partition(":"))
    if kind == "none" and not sep:
        return Filter()
    if kind not in FILTER_KINDS or not sep:
        raise InputError(f"bad filter {spec!r}: {help_text}")
    try:
        value = float(size)
    except ValueError:
        raise InputError(f"bad filter {spec!r}: size {size!r} is not a number; {help_text}") from None
    return Filter(kind, value)


def apply_filter(image: np.ndarray, mask: np.ndarray | None, filter: Filter | str | None) -> np.ndarray:
    """Smooth an image inside the object without the background bleeding in.

    Gaussian and mean use normalised convolution, ``filter(image * mask) / filter(mask)``: each
    pixel averages the object pixels in its window only. Median and minimum first give every
    background pixel the value of its nearest object pixel, then filter the whole image. The
    image's own border is treated the same way (as outside the object).

    Parameters
    ----------
    image : (H, W) array_like
        Intensities; must be finite inside the mask.
    mask : (H, W) bool array_like or None
        Object pixels; None means the whole image.
    filter : Filter, str or None
        What to apply, or a spec for :func:`parse_filter`.

    Returns
    -------
    (H, W) float64
        The filtered image inside the mask; outside the mask the input values, unchanged.

    Raises
    ------
    InputError
        If ``image`` is not 2-D, ``mask`` has another shape or is empty, ``image`` is not finite
        inside the mask, or ``filter`` is not a valid filter or its size is larger than the
        image's longer side.
    """
    spec = parse_filter(filter)
    image = np.array(image, dtype=np.float64)  # a copy: the result, where no filtering happens
    if image.ndim != 2:
        raise InputError(f"image must be 2-D (H, W), got shape {image.shape}; pick one channel first")
    if mask is None:
        mask = np.ones(image.shape, dtype=bool)
    mask = check_mask(mask, image.shape)
    if not np.isfinite(image[mask]).all():
        raise InputError("image has NaN or infinite values inside the mask; fix them or the mask")
    if spec.kind == "none" or spec.size == 0:
        return image
    longest = max(image.shape)
    if spec.size > longest:
        # a window (or a Gaussian's reach) wider than the image adds nothing, and scipy would
        # allocate its kernel first (a size of 1e9 ended in MemoryError, 1e300 in OverflowError)
        raise InputError(
            f"{spec.kind} filter size {spec.size:g} is larger than the image "
            f"({image.shape[1]}x{image.shape[0]} pixels); choose a size of at most {longest}"
        )

    radius = int(spec.size)
    if spec.kind in ("gaussian", "mean"):
        inside = np.where(mask, image, 0.0)
        weight = mask.astype(np.float64)
        if spec.kind == "gaussian":
            numerator = ndi.gaussian_filter(inside, spec.size, mode="constant")
            denominator = ndi.gaussian_filter(weight, spec.size, mode="constant")
        else:
            numerator = ndi.uniform_filter(inside, 2 * radius + 1, mode="constant")
            denominator = ndi.uniform_filter(weight, 2 * radius + 1, mode="constant")
        # Every object pixel weighs itself, so the denominator is positive on the mask.
        return np.divide(numerator, denominator, out=image, where=mask)

    filled = image
    if not mask.all():
        _, (rows, cols) = ndi.distance_transform_edt(~mask, return_indices=True)
        filled = image[rows, cols]
    window = 2 * radius + 1
    if spec.kind == "median":
        smoothed = ndi.median_filter(filled, size=window, mode="nearest")
    else:
        smoothed = ndi.minimum_filter(filled, size=window, mode="nearest")
    return np.where(mask, smoothed, image)


#: Detail beyond this many of its robust standard deviations counts as outlying: independent
#: Gaussian noise leaves 6e-5 of the pixels there (:func:`image_detail`).
OUTLIER_SIGMAS = 4.0


@dataclass(frozen=True)
class Detail:
    """What an image's finest detail (each pixel minus the mean of its 3x3 window) says about it.

    Attributes
    ----------
    noise : float
        Standard deviation of independent pixel noise, in the image's units (:func:`noise_level`).
    outliers : float
        Share of the detail lying beyond :data:`OUTLIER_SIGMAS` robust standard deviations: about
        6e-5 for a smooth rendering plus independent noise, far more where highlights, texture,
        paint or the edges of cast shadows break the smooth shading (1-13 % on the photographs
        of ``benchmarks/results/real.md``). It only means that on a noisy image: on a noise-free
        one the robust scale is the shading's own curvature.
    """

    noise: float
    outliers: float


def image_detail(image: np.ndarray, mask: np.ndarray, *, inside: np.ndarray | None = None) -> Detail:
    """The noise and the share of outlying detail on the object, from the image alone.

    The detail is each pixel minus the mean of its 3x3 window, over pixels more than 2 pixels
    inside the object: smooth shading leaves next to nothing there, while independent noise of
    standard deviation ``sigma`` leaves ``sigma sqrt(8 / 9)``, measured robustly as the median
    absolute deviation (Donoho and Johnstone's robust scale of a high-pass band, 1994).

    Parameters
    ----------
    image : (H, W) float array
        Intensities.
    mask : (H, W) bool array
        Object pixels.
    inside : (H, W) float array, optional
        ``scipy.ndimage.distance_transform_edt(mask)`` if the caller has it; else the same
        pixels are found by an erosion.

    Returns
    -------
    Detail
        Both 0 when fewer than 20 pixels lie that deep inside the object.
    """
    interior = _more_than_two_inside(mask) if inside is None else inside > 2
    interior &= image > 0
    if np.count_nonzero(interior) < 20:
        return Detail(0.0, 0.0)
    detail = (image - ndi.uniform_filter(image, 3))[interior]
    spread = np.abs(detail - np.median(detail))
    scale = 1.4826 * float(np.median(spread))
    outliers = float(np.mean(spread > OUTLIER_SIGMAS * scale)) if scale > 0 else 0.0
    return Detail(scale / math.sqrt(8.0 / 9.0), outliers)


def _more_than_two_inside(mask: np.ndarray) -> np.ndarray:
    """``distance_transform_edt(mask) > 2``: the mask eroded by the disc of radius 2 (13 pixels;
    the image's edge counts as inside, as for the transform), some 30 times faster."""
    offsets = np.arange(-2, 3)
    disc = offsets[:, None] ** 2 + offsets[None, :] ** 2 <= 4
    return ndi.binary_erosion(mask, structure=disc, border_value=1)


def noise_level(image: np.ndarray, mask: np.ndarray, *, inside: np.ndarray | None = None) -> float:
    """Standard deviation of independent pixel noise on the object, from the image alone
    (:func:`image_detail`).

    Parameters
    ----------
    image, mask, inside
        As for :func:`image_detail`.

    Returns
    -------
    float
        The noise's standard deviation in the image's units; 0 when fewer than 20 pixels lie
        that deep inside the object.
    """
    return image_detail(image, mask, inside=inside).noise


def srgb_to_linear(image: np.ndarray) -> np.ndarray:
    """Undo the sRGB encoding of an 8-bit photo (JPEG, most PNGs from phones and cameras).

    Shading methods assume intensities proportional to the light received; an sRGB file stores
    them raised to about 1 / 2.2, which makes a Lambertian surface look flatter and biases its
    normals. :func:`shadeform.load_image` already does this for 8-bit files unless told they are
    linear (``linear=True``); this is for values obtained otherwise.

    Parameters
    ----------
    image : (H, W) or (H, W, C) array_like
        Encoded values in [0, 1] (as ``shadeform.load_image(path, linear=True)`` gives them).

    Returns
    -------
    ndarray, same shape, float64
        Linear values in [0, 1]: ``v / 12.92`` up to 0.04045, ``((v + 0.055) / 1.055) ** 2.4``
        above (IEC 61966-2-1).

    Raises
    ------
    InputError
        Values outside [0, 1] or not finite.

    Examples
    --------
    >>> round(float(srgb_to_linear(np.array(0.5))), 4)
    0.214
    """
    from shadeform.io.colour import srgb_decode  # the one implementation of the curve

    values = np.asarray(image, dtype=np.float64)
    if not np.isfinite(values).all() or values.min(initial=0.0) < 0 or values.max(initial=0.0) > 1:
        raise InputError(
            "sRGB values must be finite and in [0, 1], as load_image(..., linear=True) gives them"
        )
    return srgb_decode(values)
