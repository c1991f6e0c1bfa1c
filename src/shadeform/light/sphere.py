"""Lights from a shiny sphere in the photos, as reflectance-transformation-imaging users calibrate.

A chrome (or black glossy) sphere beside the object mirrors each light as a small highlight. With
an orthographic camera looking down ``-z`` (``v = (0, 0, 1)`` toward the viewer), the highlight
sits where the sphere's normal ``n`` halves the angle between the viewer and the light, so the
light is ``l = 2 (n . v) n - v``; ``n`` comes from the highlight's offset from the sphere's centre
over its radius (rows point down: ``n_y = -(row - row_0) / r``). A light of fixed angular size is
mirrored onto the same image area wherever on the sphere (the mirror doubles angles and the
projection foreshortens by the same cosine), so the highlight's summed brightness above the
sphere's own is proportional to the light's strength: the strengths come out relative to the
median photo's.

The sphere is given as its circle, or found (:func:`find_sphere`): of the circles with the most
edge support in the photos' mean (scikit-image's Canny edges and circular Hough transform, on a
copy at most :data:`SEARCH_SIZE` pixels across), the one that looks most like a mirror (dark
but for a bright highlight), refined at full size over a few pixels round it, to a fraction of a
pixel (the parabola through the accumulator's peak); a round object beside the sphere is not
taken for it.

The highlight: within the sphere (less a rim of :data:`RIM` of its radius, where the mirror image
is squeezed and the outline's edge lies), the pixels within :data:`PEAK` of the brightest one's
value, connected to it; their brightness-weighted centre. On a glossy sphere with diffuse paint
(DiLiGenT's ball) the specular peak is far above the diffuse shading, so the same rule holds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shadeform.errors import InputError

#: The constants below were set once (round values), not swept; the rendered spheres of the tests
#: and DiLiGenT's ball are what they were checked on.
#: The sphere search runs on a copy of the photos' mean at most this many pixels across.
SEARCH_SIZE = 512
#: Share of the radius left out at the sphere's rim when looking for the highlight.
RIM = 0.05
#: A highlight is the pixels within this share of the brightest one's value, connected to it.
PEAK = 0.5
#: Smallest and largest sphere radius searched, as shares of the photo's shorter side.
RADII = (0.03, 0.5)
#: Circles of the Hough transform considered for the sphere, best supported first.
CANDIDATES = 5


@dataclass(frozen=True)
class LightCalibration:
    """What :func:`calibrate_lights` found.

    Attributes
    ----------
    directions : (N, 3) float64
        Unit vectors toward each photo's light (``docs/conventions.md``).
    strengths : (N,) float64
        Each light's strength relative to the median photo's (1.0).
    sphere : (3,) float64
        The sphere's circle: centre column, centre row, radius (pixels).
    highlights : (N, 2) float64
        Each highlight's centre (column, row).
    saturated : (N,) bool
        Photos whose highlight reaches the brightest value the photo holds anywhere: its
        strength is then a lower bound.
    """

    directions: np.ndarray
    strengths: np.ndarray
    sphere: np.ndarray
    highlights: np.ndarray
    saturated: np.ndarray


def calibrate_lights(photos, *, sphere=None) -> LightCalibration:
    """Light directions and relative strengths from a shiny sphere seen in every photo.

    Parameters
    ----------
    photos : (N, H, W) or (N, H, W, C) array_like
        The photos, linear or not (only where the highlight is and how bright it is matter).
    sphere : (3,) array_like, optional
        The sphere's circle ``(column, row, radius)`` in pixels; found in the photos if not given.

    Returns
    -------
    LightCalibration

    Raises
    ------
    InputError
        Fewer than one photo, photos that are not numeric images, a circle off the photos, no
        sphere found, or a photo whose highlight is not on the sphere or puts its light behind the
        object (more than 45 degrees from the sphere's centre: usually a circle that is no sphere).

    Examples
    --------
    >>> from shadeform import synth
    >>> lights = [[0.3, 0.2, 0.93], [-0.4, 0.1, 0.91], [0.0, -0.5, 0.87]]
    >>> photos = [synth.chrome_sphere(light, size=200)[0] for light in lights]
    >>> found = calibrate_lights(photos)
    >>> bool(np.allclose(found.directions, lights / np.linalg.norm(lights, axis=1)[:, None], atol=0.02))
    True
    """
    stack = _gray_stack(photos)
    height, width = stack.shape[1:]
    if sphere is None:
        circle = find_sphere(stack)
    else:
        try:
            circle = np.asarray(sphere, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            circle = np.zeros(0)
        if circle.shape != (3,) or not np.isfinite(circle).all() or circle[2] <= 1:
            raise InputError(
                "the sphere must be given as X,Y,R: its centre column and row and its radius in pixels"
            )
        column, row, radius = circle
        if column - radius < -1 or row - radius < -1 or column + radius > width or row + radius > height:
            raise InputError(
                f"the sphere ({column:g}, {row:g}, radius {radius:g}) reaches beyond the {width}x{height} "
                "photos; give X,Y,R of the sphere as seen, in pixels from the top left"
            )
    column, row, radius = circle
    # only the sphere's bounding box is read from here on
    top, left = max(0, int(row - radius) - 1), max(0, int(column - radius) - 1)
    stack = stack[:, top : int(row + radius) + 2, left : int(column + radius) + 2]
    rows, cols = np.mgrid[0 : stack.shape[1], 0 : stack.shape[2]]
    distance = np.hypot(cols + left - column, rows + top - row)
    inner = distance <= radius * (1.0 - RIM)
    if np.count_nonzero(inner) < 9:
        raise InputError(
            f"the sphere (radius {radius:.1f} px) is too small to read highlights on; give a larger one"
        )
    directions = np.empty((len(stack), 3))
    centres = np.empty((len(stack), 2))
    energy = np.empty(len(stack))
    saturated = np.zeros(len(stack), dtype=bool)
    for i, photo in enumerate(stack):
        centre, total, clipped = _highlight(photo, inner)
        if centre is None:
            raise InputError(
                f"photo {i + 1} shows no highlight on the sphere (its light may be behind it); "
                "leave that photo out or check the sphere's circle"
            )
        centre = centre + (left, top)
        centres[i] = centre
        saturated[i] = clipped
        nx = (centre[0] - column) / radius
        ny = -(centre[1] - row) / radius
        nz = np.sqrt(max(0.0, 1.0 - nx * nx - ny * ny))
        normal = np.array([nx, ny, nz]) / max(np.hypot(np.hypot(nx, ny), nz), 1e-12)
        energy[i] = total
        light = 2.0 * normal[2] * normal - np.array([0.0, 0.0, 1.0])
        directions[i] = light / np.linalg.norm(light)
    behind = np.flatnonzero(directions[:, 2] <= 0)
    if behind.size:
        # a highlight more than 45 degrees from the centre puts the light behind the object: not
        # a light that photometric stereo can use, and most often a circle that is not the sphere
        listed = ", ".join(str(i + 1) for i in behind[:8]) + (", ..." if behind.size > 8 else "")
        raise InputError(
            f"the highlights in the circle at column {column:.0f}, row {row:.0f} (radius {radius:.1f} px) put "
            f"the light behind the object in photo(s) {listed}: it is likely not a shiny sphere; give the "
            "sphere's circle as X,Y,R, or leave those photos out"
        )
    return LightCalibration(
        directions=directions,
        strengths=energy / np.median(energy),
        sphere=np.array([column, row, radius]),
        highlights=centres,
        saturated=saturated,
    )


def find_sphere(photos: np.ndarray) -> np.ndarray:
    """The circle ``(column, row, radius)`` of the shiny sphere in ``photos`` (N, H, W): of the
    :data:`CANDIDATES` circles with the most edge support in the photos' mean (Canny edges and a
    circular Hough transform on a reduced copy) whose outline is at least half edge, the one whose
    inside is most like a mirror's (the highest median contrast of its brightest pixel against
    its median, :func:`_shine`), refined at full size.

    Raises
    ------
    InputError
        No circle stands out.
    """
    from skimage.feature import canny
    from skimage.transform import hough_circle, rescale

    photos = np.asarray(photos)
    image = photos.mean(axis=0, dtype=np.float64)
    span = float(image.max() - image.min())
    if not np.isfinite(span) or span <= 0:
        raise InputError("the photos are blank; no sphere can be found in them")
    image = (image - image.min()) / span
    factor = min(1.0, SEARCH_SIZE / max(image.shape))
    small = rescale(image, factor, anti_aliasing=True) if factor < 1 else image
    side = min(small.shape)
    radii = np.arange(max(4, int(RADII[0] * side)), max(6, int(RADII[1] * side)) + 1)
    edges = canny(small, sigma=1.5)
    if edges.sum() < 20:
        raise InputError("no shiny sphere found in the photos; give its circle with --sphere X,Y,R")
    votes = hough_circle(edges, radii)
    best = None
    for radius, row, column in _candidates(votes, radii, CANDIDATES):
        # the share of the circle's outline that is edge: a real sphere's outline is mostly edge
        support = _support(edges, column, row, radius)
        if support < 0.5:
            continue
        shine = _shine(photos, column / factor, row / factor, radius / factor)
        if best is None or shine > best[0]:
            best = (shine, column, row, radius)
    if best is None:
        raise InputError(
            "no shiny sphere found in the photos (no circle has edges on half its outline); "
            "give its circle with --sphere X,Y,R"
        )
    _, column, row, radius = best
    if factor < 1:  # at full size round the reduced answer
        reach = int(np.ceil(2 / factor)) + 1
        column, row, radius = _refine(
            canny(image, sigma=1.5 / factor), *np.array([column, row, radius]) / factor, reach
        )
    return np.array([column, row, radius], dtype=np.float64)


def _refine(edges, column, row, radius, reach):
    """The Hough circle within ``reach`` pixels of a circle found on a reduced copy."""
    from skimage.transform import hough_circle

    centre = np.array([column, row])
    top, left = (max(0, int(c - radius - reach - 2)) for c in centre[::-1])
    window = edges[top : int(centre[1] + radius + reach + 3), left : int(centre[0] + radius + reach + 3)]
    radii = np.arange(max(2, int(radius) - reach), int(radius) + reach + 1)
    radius, row, column = _best_circle(hough_circle(window, radii), radii)
    return column + left, row + top, radius


def _candidates(votes, radii, count):
    """Up to ``count`` circles (radius, row, column) of Hough's accumulator (R, H, W), best
    first, each centre at least its radius away from the ones before."""
    votes = votes.copy()
    rows, cols = np.ogrid[0 : votes.shape[1], 0 : votes.shape[2]]
    found = []
    for _ in range(count):
        radius, row, column = _best_circle(votes, radii)
        if votes.max() <= 0:
            break
        found.append((radius, row, column))
        votes[:, (rows - row) ** 2 + (cols - column) ** 2 < radius * radius] = 0
    return found


def _shine(photos, column, row, radius):
    """How much the disc looks like a mirror in the photos (N, H, W): the median over (up to 16
    evenly spaced) photos of ``(peak - median) / (peak + median)`` inside it, 1 for a dark
    mirror with a highlight, near 0 for an evenly lit matte disc."""
    top, left = max(0, int(row - radius)), max(0, int(column - radius))
    window = photos[:, top : int(row + radius) + 1, left : int(column + radius) + 1]
    rows, cols = np.ogrid[0 : window.shape[1], 0 : window.shape[2]]
    inside = (rows + top - row) ** 2 + (cols + left - column) ** 2 <= (0.9 * radius) ** 2
    if not inside.any():
        return 0.0
    picked = window[np.linspace(0, len(window) - 1, min(len(window), 16)).astype(int)][:, inside]
    peak, middle = picked.max(axis=1), np.median(picked, axis=1)
    return float(np.median((peak - middle) / np.maximum(peak + middle, 1e-12)))


def _best_circle(votes, radii):
    """The (radius, row, column) with the most votes in Hough's accumulator (R, H, W), to a
    fraction of a pixel: the vertex of the parabola through the peak and its two neighbours,
    along each axis."""
    peak = np.unravel_index(np.argmax(votes), votes.shape)
    where = []
    for axis, index in enumerate(peak):
        offset = 0.0
        if 0 < index < votes.shape[axis] - 1:
            before, after = list(peak), list(peak)
            before[axis], after[axis] = index - 1, index + 1
            low, middle, high = votes[tuple(before)], votes[peak], votes[tuple(after)]
            bend = low - 2.0 * middle + high
            if bend < 0:
                offset = float(np.clip(0.5 * (low - high) / bend, -0.5, 0.5))
        where.append(index + offset)
    which, row, column = where
    radius = float(np.interp(which, np.arange(len(radii)), radii))
    return radius, float(row), float(column)


def _support(edges, column, row, radius):
    """The share of the circle's outline (sampled every pixel of arc) that lies on an edge pixel
    or next to one."""
    from scipy import ndimage as ndi

    near = ndi.binary_dilation(edges, iterations=1)
    angles = np.linspace(0, 2 * np.pi, max(16, int(2 * np.pi * radius)), endpoint=False)
    cols = np.rint(column + radius * np.cos(angles)).astype(int)
    rows = np.rint(row + radius * np.sin(angles)).astype(int)
    inside = (rows >= 0) & (rows < edges.shape[0]) & (cols >= 0) & (cols < edges.shape[1])
    if not inside.any():
        return 0.0
    return float(near[rows[inside], cols[inside]].mean())


def _highlight(photo, inner):
    """The highlight's brightness-weighted centre (column, row), its summed brightness and
    whether it is clipped, or (None, 0, False) when the sphere shows none."""
    from scipy import ndimage as ndi

    values = np.where(inner, photo, -np.inf)
    peak_index = np.unravel_index(np.argmax(values), values.shape)
    peak = values[peak_index]
    floor = np.median(photo[inner])
    if not np.isfinite(peak) or peak <= floor:
        return None, 0.0, False
    # the highlight stands above the sphere's own shading: pixels within PEAK of the peak's height
    # over the sphere's median, connected to the peak
    bright = inner & (photo >= floor + (1.0 - PEAK) * (peak - floor))
    labels, _ = ndi.label(bright)
    blob = labels == labels[peak_index]
    weights = photo[blob] - floor
    rows, cols = np.nonzero(blob)
    centre = np.array([np.sum(cols * weights), np.sum(rows * weights)]) / np.sum(weights)
    clipped = np.count_nonzero(photo[blob] >= peak) > 1  # a plateau at the top: the sensor's limit
    # the summed brightness over the highlight and its tail: a disc three times the blob's reach
    reach = 3.0 * np.sqrt(np.count_nonzero(blob) / np.pi) + 2.0
    grid_rows, grid_cols = np.ogrid[0 : photo.shape[0], 0 : photo.shape[1]]
    around = inner & ((grid_cols - centre[0]) ** 2 + (grid_rows - centre[1]) ** 2 <= reach * reach)
    # above the mean of the rest of the sphere (not its median: a camera clips the noise of a
    # dark mirror at black, which lifts the mean), signed, so that the noise averages out
    rest = inner & ~around
    level = float(photo[rest].mean()) if rest.any() else floor
    return centre, float(np.sum(photo[around] - level)), clipped


def _gray_stack(photos):
    """(N, H, W) float32 gray photos (the mean of the colour channels), checked."""
    try:
        stack = np.asarray(photos)
    except (TypeError, ValueError):
        stack = None
    if stack is None or not (
        np.issubdtype(stack.dtype, np.floating) or np.issubdtype(stack.dtype, np.integer)
    ):
        raise InputError("the photos must be numeric images of one size: (N, H, W) or (N, H, W, C)")
    if stack.ndim == 4:
        stack = np.stack([photo[..., :3].mean(axis=2, dtype=np.float32) for photo in stack])
    if stack.ndim != 3 or stack.shape[0] < 1 or min(stack.shape[1:]) < 8:
        raise InputError(f"the photos must be (N, H, W) or (N, H, W, C) images, got shape {stack.shape}")
    stack = stack.astype(np.float32, copy=False)
    if not np.isfinite(stack).all():
        raise InputError("the photos contain NaN or inf; give finite intensities")
    return stack
