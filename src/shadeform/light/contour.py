"""The light from the occluding contour, a tilted rim, or the brightest point.

Where the silhouette of a smooth object is an occluding contour the surface normal is the
silhouette's outward 2-D normal ``b``, so the intensity there is ``k (b . L_xy)``: linear in ``b``
with coefficient ``k L_xy`` (Yang and Yuille 1991; Nillius and Eklundh 2001). With the level at
the top of the object, ``k L_z``, that fixes the light (``evidence="limb"``); where the mask stops
at the edge of the attached shadow instead of the outline (a thresholded mask under an oblique
light), or the top is too dark to face the viewer, the brightest level fixes ``k`` instead
(``"limb-brightest"``). The same fit with a constant term reads the tilted rim of a cap, a bowl
or a saddle (``"rim"``). Where the contour cannot fix the light (only straight sides lit, as on a
cylinder) the brightest point is taken to face it (``"limb-peak"``). This module finds the
boundary pixels, drops the straight runs that are cut ends rather than occluding contours, tells
the shadow's edge from the outline, makes those fits and measures each reading's spread (a
jackknife over sectors of the outline); :func:`shadeform.light.estimate_light` documents the
model and its references.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from shadeform.light._evidence import (
    Levels,
    Reading,
    angle_between,
    bound_spread,
    from_components,
    jackknife_spread,
    slant_from_peak,
    unit_light,
)

# Fewest boundary pixels the contour fits need.
MIN_BOUNDARY_PIXELS = 20
# Gaussian smoothing (pixels) of the mask for the boundary's normals and sub-pixel distances.
_MASK_SIGMA = 2.0
# Neighbouring boundary pixels whose normals turn less than this belong to one straight run
# (chosen on the synthetic cylinder and vase of bench_light, whose cut ends it must find).
_RUN_TURN = math.radians(3.0)
_RUN_MIN_PIXELS = 8
# A run is a cut when its intensity spread exceeds what its normals' turn allows by this fraction
# of the peak (plus noise): the sub-pixel jitter of the outermost pixels alone moves a limb's
# intensity by up to ~0.1 (measured on the synthetic sphere and ellipsoid of bench_light).
_CUT_SPREAD = 0.1
# A run whose normals turn less than this in all is straight (same scenes as _RUN_TURN).
_STRAIGHT_TURN = math.radians(4.0)
# A boundary ring whose fitted constant term exceeds this fraction of the top level, and whose
# fit it improves this much, is a tilted rim (a cap's edge), not an occluding contour (chosen on
# the synthetic bowl and saddle against the sphere, ellipsoid and vase of bench_light).
_RIM_INTERCEPT = 0.2
_RIM_GAIN = 0.6
# Above this standard error (degrees) the contour alone cannot fix the slant (chosen on the
# synthetic cylinder of bench_light: lit along its axis it must fall back to the brightest point).
_DEGENERATE_SLANT = 1.5
# The limb fit of the lit side alone predicts attached-shadow bands on the far side up to this
# many times deeper than they are (its inset term is a compromise over the outline: 2.3x on the
# synthetic ellipsoid of bench_light), so the shadow-edge test reads the image within the band
# this factor shallower.
_BAND_SLACK = 2.5
# The shadow-edge test decides when this share of the tested pixels agrees, and leaves the far
# side undecided otherwise (chosen on the synthetic sphere and ellipsoid of bench_light: threshold
# masks give 85% and more lit inside noise-free and 66% and more with 2% noise at slants 40-60,
# masks drawn on the outline 3% and less; real outlines, which the lit side's fit describes less
# well, can split in between: 84 / 78 on a held-out MIT-Berkeley photo, benchmarks/results).
_EDGE_MAJORITY = 0.75
# Sectors of the outline (by the angle of its normal) the jackknife of a reading's spread leaves
# out in turn: a sector is then 45 degrees of normal, narrow enough that the rest still holds the
# light.
_JACKKNIFE_SECTORS = 8
# Most reweighted passes of the robust boundary fit.
_FIT_ITERATIONS = 30


@dataclass(frozen=True, eq=False)
class Boundary:
    """Outermost object pixels away from the image frame (n of them).

    Attributes
    ----------
    rows, cols : (n,) int64
        Their positions.
    normals : (n, 2) float64
        Outward unit normals of the silhouette, in ``(x, y)`` (x right, y up).
    depth : (n,) float64
        Sub-pixel distance (pixels, 0 to 1.5) of each pixel centre inside the silhouette.
    """

    rows: np.ndarray
    cols: np.ndarray
    normals: np.ndarray
    depth: np.ndarray


def find_boundary(mask) -> Boundary:
    """The :class:`Boundary` of ``mask`` (H, W) bool, read from the mask smoothed by
    :data:`_MASK_SIGMA`; pixels near where the object meets the image frame are left out."""
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
    return Boundary(rows=rows, cols=cols, normals=normals, depth=depth)


def read_contour(image, mask, levels: Levels, boundary: Boundary) -> Reading:
    """The light from the occluding contour (``"limb"``), a tilted rim (``"rim"``) or, when
    neither fixes it, the brightest point (``"limb-peak"``); where the contour read a light but
    left its slant loose, the surer (smaller spread) of that light and the brightest point's.

    ``image`` (H, W) float64 and ``mask`` (H, W) bool are as :func:`shadeform.light.estimate_light`
    checked them, ``levels`` as it measured them; ``boundary`` (:func:`find_boundary`) has at least
    :data:`MIN_BOUNDARY_PIXELS` pixels. The reading's ``info`` holds the cut pixels, the straight
    runs and the limb and rim fits.
    """
    from scipy import ndimage as ndi
    from threadpoolctl import threadpool_limits

    rows, cols, normals = boundary.rows, boundary.cols, boundary.normals
    values = image[rows, cols]
    cut, runs = _boundary_runs(boundary, values, mask.shape, levels.peak, levels.noise)
    keep = ~cut
    if cut.any():
        # where a cut meets the contour the silhouette has a corner: neither model holds there
        cuts = np.zeros(mask.shape, dtype=bool)
        cuts[rows[cut], cols[cut]] = True
        keep &= ndi.distance_transform_edt(~cuts)[rows, cols] > 3.0 * _MASK_SIGMA
    info: dict = {"cut_pixels": int(cut.sum()), "straight_runs": int(runs.max() + 1)}
    if keep.sum() >= MIN_BOUNDARY_PIXELS:
        ring = _Ring(
            rows[keep], cols[keep], normals[keep], np.sqrt(boundary.depth[keep]), values[keep], runs[keep]
        )
        # many small least-squares fits: BLAS threads cost more than they give, and on a busy
        # machine they spin against each other (as in relief.read_relief)
        with threadpool_limits(1, user_api="blas"):
            reading = _limb_or_rim(image, ring, levels, info)
            if reading is not None:
                return _with_spread(reading, image, ring, levels)
        normals, values = ring.normals, ring.values
    lit = values > levels.lit
    peak = _brightest_point(normals[lit], values[lit], levels, info)
    if "loose_limb" in info:
        # the outline's loose light, its spread its own slant error and the top's disagreement
        # with the brightest point: kept where it is the surer of the two
        cues = info.get("cue_angle_limb", 0.0)
        loose = Reading(
            *info["loose_limb"],
            "limb",
            {**info, "cue_angle": cues},  # its own cue, not the brightest point's
            spread=math.hypot(info["slant_error"], cues),
        )
        if loose.spread < peak.spread:
            return loose
    return peak


def _with_spread(reading: Reading, image, ring: _Ring, levels: Levels) -> Reading:
    """``reading`` with its ``spread``: the jackknife over :data:`_JACKKNIFE_SECTORS` sectors of
    the outline (each left out in turn, the whole reading made again, so that a decision one
    sector tips counts too), and the angle between the lights the two readings of ``k L_z`` give
    (the top and the brightest point, :func:`_limb_or_rim`), added in quadrature."""
    angle = np.arctan2(ring.normals[:, 1], ring.normals[:, 0])
    sector = np.floor((angle + math.pi) / (2.0 * math.pi) * _JACKKNIFE_SECTORS).astype(np.int64)
    lights = []
    for j in range(_JACKKNIFE_SECTORS):
        rest = sector % _JACKKNIFE_SECTORS != j
        if np.count_nonzero(rest) < MIN_BOUNDARY_PIXELS:
            continue
        again = _limb_or_rim(image, ring.part(rest), levels, {})
        if again is not None:
            lights.append(again.light)
    # a reading that half the left-out sectors cannot make again is not one the outline holds
    jackknife = jackknife_spread(lights) if 2 * len(lights) >= _JACKKNIFE_SECTORS else math.inf
    cues = reading.info.get("cue_angle", 0.0)
    reading.info.update(jackknife_angle=jackknife)
    return replace(reading, spread=math.hypot(jackknife, cues))


@dataclass(frozen=True, eq=False)
class _Ring:
    """The outline pixels the contour fits read (n of them).

    Attributes
    ----------
    rows, cols : (n,) int64
        Their positions.
    normals : (n, 2) float64
        Outward unit normals ``b`` in ``(x, y)``.
    root_depth : (n,) float64
        Square root of each pixel centre's sub-pixel distance inside the silhouette.
    values : (n,) float64
        Intensities.
    runs : (n,) int
        Straight, evenly lit run of each pixel, -1 on curved parts (:func:`_boundary_runs`).
    """

    rows: np.ndarray
    cols: np.ndarray
    normals: np.ndarray
    root_depth: np.ndarray
    values: np.ndarray
    runs: np.ndarray

    def part(self, keep) -> _Ring:
        """The pixels where ``keep`` (n,) bool is true."""
        return _Ring(*(getattr(self, name)[keep] for name in self.__dataclass_fields__))

    def fit(self, *, intercept: bool, scale: float, runs: bool = True):
        """:func:`_fit_ring` of these pixels (straight runs with their own offsets if ``runs``)."""
        return _fit_ring(
            self.normals,
            self.root_depth,
            self.values,
            self.runs if runs else None,
            intercept=intercept,
            scale=scale,
        )


def _limb_or_rim(image, ring: _Ring, levels: Levels, info: dict) -> Reading | None:
    """The light from the occluding boundary pixels of ``ring``: a tilted rim if the fit with a
    constant term explains them much better, else the limb if its slant is well determined; None
    when neither (few curved lit pixels, or a slant the contour leaves loose). Fills ``info`` with
    the fits.

    Where the mask stops at the edge of the attached shadow rather than at the outline
    (:func:`_shadow_edge`), the far side is no outline: only the lit side is read, and the mask's
    deepest point is not the top of the object, so the brightest level fixes ``k`` instead of the
    top (``evidence="limb-brightest"``). So it does when the top is darker than the light it gives
    allows (:func:`_top_too_dark`).
    """
    limb, limb_rms, limb_cov = ring.fit(intercept=False, scale=levels.lit)
    rim, rim_rms, _ = ring.fit(intercept=True, scale=levels.lit, runs=False)
    lit = ring.values > levels.lit
    curved_lit = int(np.count_nonzero(lit & (ring.runs < 0)))
    info.update(
        limb_fit=tuple(map(float, limb[:3])),
        limb_rms=limb_rms,
        rim_fit=tuple(map(float, rim)),
        rim_rms=rim_rms,
        curved_lit_pixels=curved_lit,
    )
    if curved_lit < max(MIN_BOUNDARY_PIXELS, 0.1 * np.count_nonzero(lit)):
        return None  # only straight sides lit: they leave the light along them free
    top = levels.top
    across, covariance = limb[:2], limb_cov[:2, :2]
    # the side of the outline facing the light, read alone: a shadow's edge on the far side does
    # not bias it, so it is what tells how deep the attached shadow reaches
    near = ring.normals @ across > 0
    edge = False
    if np.count_nonzero(near & lit) >= MIN_BOUNDARY_PIXELS:
        fit, fit_rms, fit_cov = ring.part(near).fit(intercept=False, scale=levels.lit)
        info.update(lit_side_fit=tuple(map(float, fit[:3])), lit_side_rms=fit_rms)
        # outline pixels the lit side's fit puts in attached shadow that are dim but not dark
        # (lit, yet darker than the inset term alone, the level where b . L_xy = 0): where a
        # threshold mask stops at the shadow's edge, its edge pixels are just that
        inset = fit[2] * ring.root_depth
        shadowed = (ring.normals @ fit[:2] + inset < 0) & (ring.values < inset) & lit
        edge = _shadow_edge(image, ring, fit, levels, info)
        if edge:
            across, covariance = fit[:2], fit_cov[:2, :2]
        elif edge is None and shadowed.any():
            # a band too thin to test: its pixels may be the outline or the shadow's edge
            rest, _, rest_cov = ring.part(~shadowed).fit(intercept=False, scale=levels.lit)
            across, covariance = rest[:2], rest_cov[:2, :2]
            info["untested_shadow"] = int(np.count_nonzero(shadowed))
    if not edge and rim[3] > _RIM_INTERCEPT * top and rim_rms < _RIM_GAIN * limb_rms:
        cos_rim = min(rim[3] / top, 0.999)
        info["rim_slant"] = math.degrees(math.acos(cos_rim))
        across = rim[:2] / math.sqrt(1.0 - cos_rim * cos_rim)  # k * L_xy
        return Reading(*from_components(across, top), "rim", info)
    along_view, evidence = top, "limb"
    brightest = math.sqrt(max(levels.brightest**2 - float(across @ across), 0.0))
    if edge or _top_too_dark(across, top, levels):
        along_view, evidence = brightest, "limb-brightest"
    # the other reading of k L_z, for the spread: the top, or the brightest point if it allows one
    other = top if evidence == "limb-brightest" else brightest
    if other > 0:
        info["cue_angle"] = info["cue_angle_limb"] = angle_between(
            unit_light(*from_components(across, along_view)[:2]),
            unit_light(*from_components(across, other)[:2]),
        )
    info["slant_error"] = _slant_error(across, along_view, covariance)
    if info["slant_error"] > _DEGENERATE_SLANT and evidence == "limb":
        # the brightest point and the top may read the slant (when the top can be); the limb's
        # own light, too loose to answer alone, is weighed against theirs (read_contour)
        info["loose_limb"] = from_components(across, along_view)
        return None
    return Reading(*from_components(across, along_view), evidence, info)


def _shadow_edge(image, ring: _Ring, fit, levels: Levels, info: dict) -> bool | None:
    """Whether the mask stops at the edge of the attached shadow on the outline's far side.

    On the far side of the outline from the light, the limb fit ``I = b . A + kappa sqrt(d)``
    (``fit``, of the lit side) falls to zero at the depth ``d = (b . A / kappa)^2``: a band that
    deep inside the outline is in attached shadow. Where the mask holds the shadow (a mask drawn
    on the outline), the image is dark inside that band; where the mask stops where the shading
    fades out (a threshold mask), its edge is the shadow's edge and the image is lit just inside.
    The image is read halfway through the shallowest band the fit allows (:data:`_BAND_SLACK`),
    and at least a pixel inside, where that band is a pixel deep or more.

    Returns
    -------
    bool or None
        True for a shadow's edge, False for the shadowed outline (or no shadow on the outline),
        None when the far side's shadow is too thin to tell, or when the tested pixels split
        (:data:`_EDGE_MAJORITY`). ``info`` gets the counts.
    """
    from scipy import ndimage as ndi

    facing = ring.normals @ fit[:2]
    kappa = float(fit[2])
    with np.errstate(divide="ignore"):
        depth = np.where(facing < 0, (facing / kappa) ** 2 if kappa > 0 else np.inf, 0.0)
    if not np.any(depth > float(np.mean(ring.root_depth)) ** 2):
        return False  # the shadow does not reach as far out as the outline's pixels
    band = depth / _BAND_SLACK  # the shallowest band the fit allows
    tested = (band >= 1.0) & (ring.values <= levels.lit)
    if np.count_nonzero(tested) < MIN_BOUNDARY_PIXELS:
        return None
    # halfway through the band, at least a pixel in, and not past half the object's own depth
    reach = np.minimum(np.maximum(0.5 * band[tested], 1.0), 0.5 * float(levels.inside.max()))
    normals = ring.normals[tested]
    inward = ndi.map_coordinates(
        image, [ring.rows[tested] + reach * normals[:, 1], ring.cols[tested] - reach * normals[:, 0]], order=1
    )
    dark = int(np.count_nonzero(inward <= levels.lit))
    info.update(shadowed_outline=dark, shadow_edge=int(inward.size - dark))
    if inward.size - dark >= _EDGE_MAJORITY * inward.size:
        return True
    return False if dark >= _EDGE_MAJORITY * inward.size else None


def _top_too_dark(across, top, levels: Levels) -> bool:
    """Whether the top is too dark to be ``k L_z``: the light it gives, ``k = |(k L_xy, top)|``,
    would leave three quarters of the object's lit pixels brighter than a Lambertian surface can
    be under it. No highlight covers that much; dark paint or a shadow at the top does (DiLiGenT
    ``reading``). Half the pixels would also set aside the right top of a grazing light (a
    held-out MIT-Berkeley photo, ``benchmarks/results/light.md``)."""
    return math.hypot(float(across[0]), float(across[1]), top) < levels.quartile


def _brightest_point(normals, values, levels: Levels, info: dict) -> Reading:
    """The light when the contour cannot fix the slant: the brightest point faces the light, and
    the tilt is the lit contour's mean normal (``normals`` (n, 2)) weighted by intensity. The
    slant is only bounded from below (:func:`bound_spread`), and left unknown (an infinite spread)
    where the top is too dark to be ``k L_z`` (darker than a quarter of the lit pixels). Where
    the outline gave a light too loose to answer with (``info["loose_limb"]``), the angle to it
    joins the spread in quadrature."""
    mean = (normals * values[:, None]).sum(axis=0) if values.size else np.zeros(2)
    tilt = math.degrees(math.atan2(mean[1], mean[0])) if np.hypot(*mean) > 0 else 0.0
    slant = slant_from_peak(levels.top, levels.peak)
    # the slant is only bounded, and not even that where the top is too dark to be k L_z
    spread = bound_spread(slant) if levels.top >= levels.quartile else math.inf
    if "loose_limb" in info:
        # the outline's own light, in quadrature: where it disagrees (a dark-painted top and a
        # bright-painted foot read as a grazing light, MIT-Berkeley's raw frog1: 83 degrees
        # against the outline's 18), one of the two premises fails
        info["cue_angle"] = angle_between(unit_light(slant, tilt), unit_light(*info["loose_limb"][:2]))
        spread = math.hypot(spread, info["cue_angle"])
    return Reading(slant, tilt, max(levels.peak, levels.top), "limb-peak", info, spread=spread)


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


def _boundary_runs(boundary: Boundary, values, shape, peak, noise):
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

    rows, cols = boundary.rows, boundary.cols
    n = rows.size
    index = -np.ones(shape, dtype=np.int64)
    index[rows, cols] = np.arange(n)
    angle = np.arctan2(boundary.normals[:, 1], boundary.normals[:, 0])
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
    mask cannot tell. The outermost pixel centres lie a sub-pixel distance ``d`` inside the
    silhouette, where the normal has already turned toward the viewer by about ``sqrt(2 d / rho)``
    (Koenderink 1984): ``kappa sqrt(d)`` takes that up.

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
        system, target = design[active] * root, values[active] * root[:, 0]
        # the bounds (offsets >= 0) rarely bind: the unbounded solution first
        solution = np.linalg.lstsq(system, target, rcond=None)[0]
        if (solution < lower).any():
            solution = lsq_linear(system, target, bounds=(lower, np.inf), method="bvls").x
        change = float(np.abs(solution - params).max())
        params = solution
        predicted = design @ params
        residual = np.maximum(predicted, 0.0) - values
        weight = 1.0 / np.sqrt(1.0 + (residual / scale) ** 2)  # soft-L1 (pseudo-Huber) weights
        active = lit | (predicted > 0)
        if change < 1e-7 * max(float(np.abs(values).max()), 1e-300):
            break
    rms = float(np.sqrt(np.mean(residual * residual)))
    return params, rms, _covariance(design, params, max(rms, scale / 3.0) ** 2)


def _covariance(design, params, sigma2):
    """Covariance ``sigma2 (J^T J)^+`` of a clipped linear fit's parameters, where ``J`` is the
    ``design`` with the rows the fit clips to 0 zeroed; ``inf`` in the rows and columns of the
    parameters the data do not constrain."""
    jac = design.copy()
    jac[design @ params <= 0] = 0.0
    eigenvalues, vectors = np.linalg.eigh(jac.T @ jac)
    with np.errstate(divide="ignore"):
        inverse = np.where(eigenvalues > 1e-9 * max(eigenvalues.max(), 1e-300), 1.0 / eigenvalues, np.inf)
    weights = vectors * vectors  # variance of p_i = sum_j V_ij^2 / lambda_j (inf if unconstrained)
    covariance = sigma2 * (vectors * np.where(np.isfinite(inverse), inverse, 0.0)) @ vectors.T
    unconstrained = (weights[:, ~np.isfinite(inverse)] > 1e-6).any(axis=1)
    covariance[unconstrained, :] = np.inf
    covariance[:, unconstrained] = np.inf
    return covariance
