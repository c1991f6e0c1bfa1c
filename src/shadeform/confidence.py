"""Say when unsure: where one photo cannot settle convexity, and how well the normals explain it.

Under one light a surface point whose normal points at the light (a *singular point*, where the
image reaches the albedo) is a brightness maximum whether the surface there is a bump, a dimple or
a saddle: the image gives the size of the curvatures, not their signs. The solvers take it convex.
Away from a singular point the signs are tied to it: each object pixel belongs to the *basin* of
one singular point (the watershed of the negated image from those points). The occluding outline
settles a basin it bounds, since the surface turns away from the viewer there (convex); in the
other basins the choice is the solver's guess, and that is what :func:`assess` reports, with the
image axis (or both) along which the guess may be wrong.

One kind of singular point needs more than its maximum: where the surface is flat along one
direction at the singular point (on a parabolic line, where one curvature changes sign), the
brightness falls off as the fourth power of the distance along that direction instead of the
square, and the surface is convex along it on one side and concave on the other (the neck of a
vase above its belly). Such a maximum is read as two singular points, one at each end of its
bright area; the outline then settles one of them at most.

The confidence map multiplies how well the recovered normals explain the photo (the shading
residual) by how settled the pixel's basin is. Of the unsure areas (print and texture make many)
the :data:`MAX_NAMED` whose flip would move the most depth are named, the others counted.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numba
import numpy as np

from shadeform.errors import InputError
from shadeform.regions import outline_polygon

#: Brightness tolerance, a fraction of the albedo. A singular point must reach ``1 - TOLERANCE``
#: of the albedo (its normal within about 18 degrees of the light) and stand this much above its
#: surroundings (the height of :func:`skimage.morphology.h_maxima`), so that noise and texture do
#: not make thousands. A 5 % brightness tolerance, chosen on synthetic renders: with 2 % and 4 %
#: Gaussian noise (three seeds, 256 pixels, light (5, 5, 7)) it finds one maximum each on the
#: sphere, ellipsoid, vase and bowl, where 3 % finds two on the bowl and 1 % up to six. The price:
#: a dimple whose walls tilt less than about 18 degrees (a brightness dip under 5 %) is not seen.
TOLERANCE = 0.05
#: Smallest basin, a fraction of the object's pixels, that is reported as unsure.
MIN_SHARE = 0.02
#: Unsure areas named at most (:attr:`Confidence.unsure`, ``info["unsure"]``, the CLI, the app):
#: what a reader takes in at a glance, as many as :func:`shadeform.fusion.settle` tries; a choice,
#: not a measurement (a photo with a printed label gave 13).
MAX_NAMED = 3
#: Shading residual, a fraction of the albedo, at which the map falls to ``exp(-1)``: what a real
#: photo's noise and texture leave where the normals are right (with the true normals the smoothed
#: residual's median is 0.03 to 0.12 on the twelve MIT-Berkeley shading photos of
#: ../shared/data/real; 0.04 to 0.5 on the painted DiLiGenT objects read with one albedo).
RESIDUAL_SCALE = 0.1
# Gaussian smoothing (pixels) of the image and of the residual: enough to quiet pixel noise, small
# enough to keep a 2 % basin whole.
_SIGMA = 1.0
# A singular point's bright area {I > peak - TOLERANCE} shrinks to half its extent at a quarter of
# the tolerance where the brightness falls off as the square of the distance, to 4^(-1/4) = 0.71
# where it falls off as the fourth power (a parabolic singular point) and not at all on a ridge
# that stays flat (a cylinder). Measured: 0.48 to 0.55 on the synthetic sphere, ellipsoid, saddle
# and bowl, 0.77 along the vase's belly under the light (5, 5, 7), 1.0 along the cylinder and 1.05
# on the flat base of the bumps; a maximum is parabolic when one direction lies in this band and
# the other below it (the extent's ratio is the standard deviation's).
_PARABOLIC_BAND = (0.65, 0.9)
# The flat direction must also be the bright area's long one, this many times its short one: on
# the real photos of ../shared/data/real (MIT-Berkeley shading, DiLiGenT) the band catches
# roundish areas too (the apple's top, 1.2 times as long as wide, flat across its short axis),
# which textures and small bumps make, while the vase's belly is 2.9 times as long as wide at 128
# and 256 pixels.
_PARABOLIC_ELONGATION = 2.0
# Fewest pixels of the bright area at a quarter of the tolerance for that test to be read.
_MIN_TOP_PIXELS = 12


@dataclass(frozen=True, eq=False)
class Unsure:
    """An area whose convexity the photo leaves open.

    Attributes
    ----------
    polygon : (N, 2) float64
        Outline of the area, ``(x, y)`` = (column, row) in pixels, simplified to about one pixel,
        N >= 3; a polygon of :mod:`shadeform.regions`.
    axis : {"x", "y", "both"}
        Image direction(s) along which the surface there may be concave: the suggested region
        axis.
    share : float
        Fraction of the object's pixels in the area.
    centre : tuple of float
        ``(x, y)`` = (column, row) of the area's singular point.
    relief : float
        Mean distance (pixels) of the recovered depth over the area from the plane through its
        edge: reading the area concave mirrors its surface about its edge, moving the depth there
        by about twice that. NaN when assessed without a depth.
    """

    polygon: np.ndarray
    axis: str
    share: float
    centre: tuple[float, float]
    relief: float = float("nan")

    @property
    def weight(self) -> float:
        """How much the area matters: ``share * relief``, the depth a flip would move over the
        object's pixel count; ``share`` alone without a depth."""
        return self.share if np.isnan(self.relief) else self.share * self.relief


@dataclass(frozen=True, eq=False)
class Confidence:
    """How far to trust a reconstruction, pixel by pixel, and the areas to check.

    Attributes
    ----------
    map : (H, W) float32
        In [0, 1] on the object, NaN off it: how well the normals explain the photo times how
        settled the pixel's convexity is (1, 0.5 with one axis open, 0 with both).
    unsure : tuple of Unsure
        The areas whose convexity the photo leaves open that matter most (:attr:`Unsure.weight`),
        at most :data:`MAX_NAMED`, the most first.
    others : int
        How many more unsure areas there are (each mattering less than every named one).
    others_share : float
        Fraction of the object's pixels in those.
    """

    map: np.ndarray
    unsure: tuple[Unsure, ...]
    others: int = 0
    others_share: float = 0.0


def assess(image, mask, light, normals, *, albedo, depth=None) -> Confidence:
    """Where a single-photo reconstruction may have a concave part convex, and how well its
    normals explain the photo.

    Parameters
    ----------
    image : (H, W) array_like
        Linear intensities, finite on the object.
    mask : (H, W) array_like of bool
        Object pixels; at least one.
    light : (3,) array_like
        Direction toward the light (normalised here).
    normals : (H, W, 3) array_like
        Unit normals of the recovered shape; NaN (no information) where the solver gave none.
    albedo : float or (H, W) array_like
        Brightness of a pixel facing the light (``I = albedo * max(0, N . L)``), positive on the
        object.
    depth : (H, W) array_like, optional
        The recovered depth (pixels), NaN where unknown: the unsure areas are ranked by the depth
        their flip would move (:attr:`Unsure.weight`); without it by their share of the object.

    Returns
    -------
    Confidence
        The map and the unsure areas (:class:`Unsure`) that matter most, the most first.

    Raises
    ------
    InputError
        Arrays of the wrong shape or mismatched, an empty mask, non-finite intensities on the
        object, a zero or non-finite light, a non-positive albedo.

    Notes
    -----
    Singular points are the maxima of the smoothed ``image / albedo`` at least :data:`TOLERANCE`
    above their surroundings and within it of 1. Every object pixel joins the basin of one of them
    (watershed of the negated image). The basin holding most occluding-outline pixels
    (:func:`shadeform.light.contour.find_boundary`) is settled; another of at least
    :data:`MIN_SHARE` of the object is unsure along x unless the row through its singular point,
    followed both ways inside the basin, ends on the outline both times (not on another basin or
    the image frame), and likewise along y with the column. Where no pixel is on the outline
    nothing is settled by it. A maximum that is flat along its bright area's long axis (a parabolic
    singular point, see the module's description) counts as two, one at each end.

    References
    ----------
    .. [1] J. Oliensis, "Uniqueness in shape from shading", IJCV 6(2), 75-104, 1991 (singular
       points fix the shape up to the convex / concave choice at each).
    .. [2] J. J. Koenderink and A. J. van Doorn, "Photometric invariants related to solid shape",
       Optica Acta 27(7), 981-996, 1980 (brightness extrema away from singular points lie on
       parabolic lines).

    Examples
    --------
    >>> from shadeform import synth
    >>> s = synth.scene("sphere", size=64)
    >>> result = assess(s.image, s.mask, s.light, s.normals, albedo=s.albedo)
    >>> result.unsure, round(float(np.nanmin(result.map)), 2)
    ((), 1.0)
    """
    image, mask, light, normals, albedo = _checked(image, mask, light, normals, albedo)
    if depth is not None and np.shape(depth) != mask.shape:
        raise InputError(f"depth must have shape {mask.shape} (H, W), got {np.shape(depth)}")
    confidence = np.full(mask.shape, np.nan, dtype=np.float32)
    # the work is done on the object's box: one pixel of margin keeps what find_boundary and the
    # smoothing see unchanged, and where the box meets the image frame so does the object
    rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    top, left = max(rows[0] - 1, 0), max(cols[0] - 1, 0)
    box = (slice(top, rows[-1] + 2), slice(left, cols[-1] + 2))
    image, mask, normals = image[box], mask[box], normals[box]
    depth = None if depth is None else _numbers(depth, "depth")[box]
    if albedo.ndim:
        albedo = albedo[box]
    # Memory: a few box-sized arrays at a time (this runs while the reconstruction's arrays are
    # held), each freed as soon as its step is done; smoothing is done in place.
    total = _blur(mask.astype(np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        shading = np.divide(image, albedo, dtype=np.float64)
    shading[~mask] = 0.0
    smooth = _smooth(shading.copy(), mask, total)

    markers, centres = _singular_points(smooth, mask)
    basins = _basins(smooth, mask, markers, len(centres))
    del smooth, markers

    # how well the normals explain the photo, where they say anything (a NaN component: nothing);
    # the residual is made in the shading's array
    known = _residual(shading, normals, light, mask)
    residual = shading
    del shading
    if np.array_equal(known, mask):
        residual = _smooth(residual, mask, total)
    else:
        residual = _smooth(residual, known, _blur(known.astype(np.float64)))
    del total
    explained = residual  # exp(-(residual / scale)^2), in place
    explained /= RESIDUAL_SCALE
    np.square(explained, out=explained)
    np.negative(explained, out=explained)
    np.exp(explained, out=explained)
    del residual

    unsure, openness = _unsure_areas(basins, centres, mask, (top, left), depth)
    for label, open_axes in openness.items():
        explained[basins == label] *= 1.0 - 0.5 * open_axes  # how settled the basin is
    explained[~known] = 0.0
    np.copyto(confidence[box], explained, where=mask)
    others = unsure[MAX_NAMED:]
    return Confidence(confidence, unsure[:MAX_NAMED], len(others), float(sum(area.share for area in others)))


def _residual(out, normals, light, mask):
    """``|out - max(N . L, 0)|`` written into ``out`` (H, W) float64 where the normals (H, W, 3)
    are finite on ``mask``, 0 elsewhere; a band of rows at a time (no (H, W, 3) temporary).
    Returns where they are known, (H, W) bool."""
    known = np.zeros(mask.shape, dtype=bool)
    rows = max(1, (1 << 16) // max(mask.shape[1], 1))
    for start in range(0, mask.shape[0], rows):
        band = slice(start, start + rows)
        facing = np.einsum("ijk,k->ij", normals[band], light)
        known[band] = mask[band] & np.isfinite(facing)
        with np.errstate(invalid="ignore"):
            np.maximum(facing, 0.0, out=facing)
        np.subtract(out[band], facing, out=facing)
        np.abs(facing, out=facing)
        out[band] = np.where(known[band], facing, 0.0)
    return known


def _checked(image, mask, light, normals, albedo):
    """The inputs as float64 / bool arrays and a unit light, or an :class:`InputError`."""
    image = _numbers(image, "image")
    if image.ndim != 2:
        raise InputError(f"image must have shape (H, W) (one channel), got {image.shape}")
    mask = np.asarray(mask)
    if mask.shape != image.shape:
        raise InputError(f"mask shape {mask.shape} does not match image shape {image.shape}")
    mask = mask.astype(bool)
    if not mask.any():
        raise InputError("mask is empty; give the object's pixels")
    normals = _numbers(normals, "normals", single=True)
    if normals.shape != (*image.shape, 3):
        raise InputError(f"normals must have shape {(*image.shape, 3)} (H, W, 3), got {normals.shape}")
    if not np.isfinite(image[mask]).all():
        raise InputError("image has NaN or inf on the object; fix those pixels or leave them out of the mask")
    light = _numbers(light, "light")
    if light.shape != (3,) or not np.isfinite(light).all() or not np.any(light):
        raise InputError(f"light must be three finite numbers, not all zero, got shape {light.shape}")
    light = light / np.linalg.norm(light)
    albedo = _numbers(albedo, "albedo")
    if albedo.ndim == 0:
        if not np.isfinite(albedo) or albedo <= 0:
            raise InputError(f"albedo must be a positive number, got {float(albedo)}")
    elif albedo.shape != image.shape:
        raise InputError(f"albedo must be a number or of shape {image.shape}, got {albedo.shape}")
    elif not (np.isfinite(albedo[mask]).all() and (albedo[mask] > 0).all()):
        raise InputError("albedo must be positive and finite on every object pixel")
    return image, mask, light, normals, albedo


def _numbers(values, name, *, single=False):
    """``values`` as a float64 array (float32 ones kept as they are with ``single``: no copy of
    the normals), or an :class:`InputError` naming ``name``."""
    try:
        if single and np.asarray(values).dtype == np.float32:
            return np.asarray(values)
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an array of numbers, got {type(values).__name__}") from None


def _blur(values):
    """``values`` (H, W) float64 smoothed by the Gaussian of :data:`_SIGMA`, zero outside, in
    place (scipy's one-dimensional filters read each line into a buffer first); returns it."""
    from scipy import ndimage as ndi

    ndi.gaussian_filter1d(values, _SIGMA, axis=1, mode="constant", output=values)
    ndi.gaussian_filter1d(values, _SIGMA, axis=0, mode="constant", output=values)
    return values


def _smooth(values, weight, total):
    """``values`` (H, W) float64, zero where ``weight`` (H, W) bool is False, smoothed by
    :func:`_blur` averaging only where ``weight`` is set (``total`` the blur of ``weight``), so
    the background does not darken the edge; 0 where it is not. In place; returns ``values``."""
    _blur(values)
    with np.errstate(divide="ignore", invalid="ignore"):
        np.divide(values, total, out=values, where=weight)
    values[~weight] = 0.0
    return values


def _singular_points(smooth, mask):
    """The singular points of the smoothed shading ``smooth`` (H, W) on ``mask`` (H, W).

    Returns
    -------
    markers : (H, W) int32
        0, or the number (from 1) of the singular point whose area the pixel starts.
    centres : list of (int, int)
        ``(row, col)`` of each singular point, in the order of its number.
    """
    markers = np.zeros(mask.shape, dtype=np.int32)
    centres: list[tuple[int, int]] = []
    # whether a maximum reaching 1 - TOLERANCE stands TOLERANCE above its surroundings depends
    # on the levels above 1 - 2 TOLERANCE only: below that floor and outside its box the image
    # cannot change the answer
    floor = 1.0 - 2.0 * TOLERANCE
    high = mask & (smooth >= floor)
    if not high.any():
        return markers, centres
    rows, cols = np.nonzero(high)
    box = (slice(rows.min(), rows.max() + 1), slice(cols.min(), cols.max() + 1))
    part = np.where(mask[box], np.maximum(smooth[box], floor), floor - TOLERANCE)
    rim = None
    for (row, col), area in _standing_maxima(part, 1.0 - TOLERANCE, floor):
        if rim is None:
            rim = _rim(mask, box)
        areas = [area]
        direction = _parabolic_direction(part, (row, col), area, rim)
        if direction is not None:
            # the two ends of the flat direction, each a singular point of its own
            r, c = np.nonzero(area)
            along = c * direction[0] - r * direction[1]  # x = col, y = -row
            ends = (along < along.mean(), along >= along.mean())
            areas = [np.zeros_like(area) for _ in ends]
            for end_area, end in zip(areas, ends):
                end_area[r[end], c[end]] = True
        for end_area in areas:
            if len(areas) == 1:
                at = (row, col)
            else:
                # an end's brightness is level to within the tolerance: its middle stands for it
                r, c = np.nonzero(end_area)
                nearest = np.argmin((r - r.mean()) ** 2 + (c - c.mean()) ** 2)
                at = (r[nearest], c[nearest])
            centres.append((int(at[0] + box[0].start), int(at[1] + box[1].start)))
            markers[box][end_area] = len(centres)
    return markers, centres


def _standing_maxima(part, level, floor):
    """The maxima of ``part`` (h, w) that reach ``level`` and stand at least :data:`TOLERANCE`
    above their surroundings: those of :func:`skimage.morphology.h_maxima` with that height.

    A maximum stands that high when the pixels connected to it less than the tolerance below it
    hold none higher. Taking the candidates (local maxima) from the highest down, each one's
    area settles every lower candidate in it, so a few labellings of the bright parts
    (``part > floor``) replace h_maxima's grey reconstruction of the whole (5 to 10 times faster
    on a megapixel with large bright areas).

    Returns
    -------
    list of ((int, int), (h, w) bool)
        Each maximum's ``(row, col)`` and its area: the pixels connected to it less than the
        tolerance below it.
    """
    from scipy import ndimage as ndi

    eight = np.ones((3, 3), dtype=bool)
    candidates = (part >= level) & (part == ndi.maximum_filter(part, size=3))
    rows, cols = np.nonzero(candidates)
    order = np.argsort(-part[rows, cols], kind="stable")
    # each area lies in one bright part: label only within its box
    parts, _ = ndi.label(part > floor, structure=eight)
    boxes = ndi.find_objects(parts)
    taken = np.zeros(part.shape, dtype=bool)
    found = []
    for row, col in zip(rows[order], cols[order]):
        if taken[row, col]:
            continue
        top = part[row, col]
        where = boxes[parts[row, col] - 1]
        labels, _ = ndi.label(part[where] > top - TOLERANCE, structure=eight)
        area = np.zeros(part.shape, dtype=bool)
        area[where] = labels == labels[row - where[0].start, col - where[1].start]
        taken |= area
        if part[where][area[where]].max() <= top:
            found.append(((int(row), int(col)), area))
    return found


def _rim(mask, box):
    """The pixels of ``mask`` (H, W) in ``box`` with a neighbour (of 8) off the object or off the
    image, (h, w) bool."""
    from scipy import ndimage as ndi

    rows, cols = box
    top, left = max(rows.start - 1, 0), max(cols.start - 1, 0)
    # off the image counts as off the object
    around = np.pad(mask[top : rows.stop + 1, left : cols.stop + 1], 1, constant_values=False)
    inner = ndi.binary_erosion(around, structure=np.ones((3, 3), dtype=bool))
    r0, c0 = rows.start - top + 1, cols.start - left + 1
    height, width = rows.stop - rows.start, cols.stop - cols.start
    return (around & ~inner)[r0 : r0 + height, c0 : c0 + width]


def _parabolic_direction(part, peak, area, rim):
    """The image direction ``(x, y)`` along which the maximum at ``peak`` of ``part`` (h, w) is
    flat (its brightness falling as the fourth power of the distance, :data:`_PARABOLIC_BAND`,
    along the long axis of its bright ``area`` (h, w) bool, :data:`_PARABOLIC_ELONGATION`), or
    None: where it falls off as the square both ways or is flat both ways, where the area is
    roundish, or where it meets the object's ``rim`` (h, w) bool and its extent is cut."""
    top = area & (part > part[peak] - TOLERANCE / 4.0)
    if np.count_nonzero(top) < _MIN_TOP_PIXELS:
        return None
    spreads = []
    for pixels in (area, top):
        r, c = np.nonzero(pixels)
        spreads.append(np.column_stack([c, -r]).astype(np.float64))
    variances, axes = np.linalg.eigh(np.cov(spreads[0].T))  # the long axis last
    if variances[1] < _PARABOLIC_ELONGATION**2 * variances[0]:
        return None
    # extent at a quarter of the tolerance over the extent at the whole, along each axis
    ratios = [np.std(spreads[1] @ axes[:, k]) / np.std(spreads[0] @ axes[:, k]) for k in (0, 1)]
    low, high = _PARABOLIC_BAND
    if not (ratios[0] < low and low <= ratios[1] <= high) or (area & rim).any():
        return None
    return axes[:, 1]


def _basins(smooth, mask, markers, count):
    """Basin (H, W) int32 of every object pixel: the number of its singular point, 0 where none
    (off the object, or in a part of it that holds no singular point)."""
    from scipy import ndimage as ndi

    if count == 0:
        return np.zeros(mask.shape, dtype=np.int32)
    if count == 1:
        # one source: its basin is the part of the object it lies in
        parts, _ = ndi.label(mask)
        return np.where(parts == parts[markers > 0][0], 1, 0).astype(np.int32)
    # a singular point's area is its basin's already: only its rim starts the flooding, which
    # spares the watershed a large bright plateau (a flat base facing the light)
    inner = ndi.binary_erosion(markers > 0, structure=np.ones((3, 3), dtype=bool))
    basins = np.where(inner | ~mask, 0, markers).astype(np.int32)
    _flood(smooth, mask & ~inner, basins)
    basins[inner] = markers[inner]
    return basins


def _basins_reference(smooth, mask, markers, count):
    """:func:`_basins` by :func:`skimage.segmentation.watershed` of ``-smooth``: the slow,
    memory-hungry reference of the compiled flooding, for the tests."""
    from scipy import ndimage as ndi
    from skimage.segmentation import watershed

    if count < 2:
        return _basins(smooth, mask, markers, count)
    inner = ndi.binary_erosion(markers > 0, structure=np.ones((3, 3), dtype=bool))
    basins = watershed(-smooth, np.where(inner, 0, markers), mask=mask & ~inner).astype(np.int32)
    basins[inner] = markers[inner]
    return basins


@numba.njit(cache=True)
def _flood(smooth, allowed, labels):
    """Watershed of ``-smooth`` (H, W) float64 from the labelled pixels of ``labels`` (H, W)
    int32 (0: not yet), through the 4-connected pixels of ``allowed`` (H, W) bool, in place.

    Priority flooding as :func:`skimage.segmentation.watershed` does it (compactness 0, no
    watershed line): a pixel takes the label of the neighbour that reaches it first, and pixels
    are taken brightest first, equal ones in the order they were reached (the seeds first). The
    queue is a heap (:mod:`heapq`, compiled by numba) of ``(-smooth, age, pixel)`` that grows with
    the front, so the memory is the labels' alone (skimage's copies and pads the image and the
    markers).
    """
    height, width = labels.shape
    queue = [(0.0, 0, 0)]  # typed by its first entry, which goes at once
    queue.pop()
    for r in range(height):
        for c in range(width):
            if labels[r, c] != 0 and allowed[r, c]:
                heapq.heappush(queue, (-smooth[r, c], 0, r * width + c))
    age = 0
    while len(queue) > 0:
        item = heapq.heappop(queue)[2]
        r = item // width
        c = item % width
        for k in range(4):
            rr = r + (-1, 0, 0, 1)[k]
            cc = c + (0, -1, 1, 0)[k]
            if rr < 0 or rr >= height or cc < 0 or cc >= width:
                continue
            if not allowed[rr, cc] or labels[rr, cc] != 0:
                continue
            labels[rr, cc] = labels[r, c]
            age += 1
            heapq.heappush(queue, (-smooth[rr, cc], age, rr * width + cc))


def _unsure_areas(basins, centres, mask, origin, depth):
    """The unsure basins of ``basins`` (H, W) int32 with singular points at ``centres``, on
    ``mask`` (H, W), a part of the image starting at pixel ``origin`` ``(row, col)``, with the
    ``depth`` (H, W) there or None.

    Returns
    -------
    unsure : tuple of Unsure
        All of them, the one that matters most (:attr:`Unsure.weight`) first.
    openness : dict of int to int
        Basin number -> how many axes (1 or 2) the outline leaves open, for the unsure ones.
    """
    from shadeform.light.contour import find_boundary

    boundary = find_boundary(mask)
    outline = np.zeros(mask.shape, dtype=bool)
    outline[boundary.rows, boundary.cols] = True
    count = len(centres)
    on_outline = np.bincount(basins[outline], minlength=count + 1)
    sizes = np.bincount(basins[mask], minlength=count + 1)
    # the outline says the surface turns away there: its basin is convex
    settled = int(np.argmax(on_outline[1:])) + 1 if on_outline[1:].any() else None
    total = np.count_nonzero(mask)
    found, openness = [], {}
    for label in range(1, count + 1):
        if label == settled or sizes[label] < MIN_SHARE * total:
            continue
        row, col = centres[label - 1]
        inside = basins == label
        open_x = not _ends_on_outline(inside[row], outline[row], col)
        open_y = not _ends_on_outline(inside[:, col], outline[:, col], row)
        if not (open_x or open_y):
            continue
        axis = "both" if open_x and open_y else ("x" if open_x else "y")
        openness[label] = int(open_x) + int(open_y)
        found.append(
            Unsure(
                polygon=outline_polygon(inside) + (origin[1], origin[0]),
                axis=axis,
                share=float(sizes[label] / total),
                centre=(float(col + origin[1]), float(row + origin[0])),
                relief=float("nan") if depth is None else _relief(depth, inside),
            )
        )
    found.sort(key=lambda area: (-area.weight, -area.share))
    return tuple(found), openness


def _ends_on_outline(inside, outline, start):
    """Whether the run of ``inside`` (n,) bool through ``start`` ends on an ``outline`` (n,) bool
    pixel at both ends."""
    stops = np.flatnonzero(~inside)
    before, after = stops[stops < start], stops[stops > start]
    first = before[-1] + 1 if before.size else 0
    last = after[0] - 1 if after.size else inside.size - 1
    return bool(outline[first] and outline[last])


def _relief(depth, inside):
    """Mean distance of ``depth`` (H, W) over ``inside`` (H, W) bool from the plane fitted to it on
    the area's edge, about which a flip mirrors it (:func:`shadeform.solvers.photo.concave_start`);
    0 with fewer than three known there."""
    from scipy import ndimage as ndi

    box = ndi.find_objects(inside.astype(np.int8))[0]
    area, z = inside[box], depth[box]
    known = area & np.isfinite(z)
    rows, cols = np.nonzero(known & ~ndi.binary_erosion(area))
    if rows.size < 3:
        return 0.0
    terms = np.column_stack([np.ones(rows.size), rows, cols])
    plane = np.linalg.lstsq(terms, z[rows, cols], rcond=None)[0]
    rows, cols = np.nonzero(known)
    return float(np.mean(np.abs(z[rows, cols] - plane[0] - plane[1] * rows - plane[2] * cols)))
