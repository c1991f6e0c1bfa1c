"""The light from the occluding contour, a tilted rim, or the brightest point.

Where the silhouette of a smooth object is an occluding contour the surface normal is the
silhouette's outward 2-D normal ``b``, so the intensity there is ``k (b . L_xy)``: linear in ``b``
with coefficient ``k L_xy`` (Yang and Yuille 1991; Nillius and Eklundh 2001). With the level at
the top of the object, ``k L_z``, that fixes the light (``evidence="limb"``). The same fit with a
constant term reads the tilted rim of a cap, a bowl or a saddle (``"rim"``). Where the contour
cannot fix the light (only straight sides lit, as on a cylinder) the brightest point is taken to
face it (``"limb-peak"``). This module finds the boundary pixels, drops the straight runs that are
cut ends rather than occluding contours, and makes those three fits;
:func:`shadeform.light.estimate_light` documents the model and its references.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shadeform.light._evidence import Levels, Reading, from_components, slant_from_peak

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
    neither fixes it, the brightest point (``"limb-peak"``).

    ``image`` (H, W) float64 and ``mask`` (H, W) bool are as :func:`shadeform.light.estimate_light`
    checked them, ``levels`` as it measured them; ``boundary`` (:func:`find_boundary`) has at least
    :data:`MIN_BOUNDARY_PIXELS` pixels. The reading's ``info`` holds the cut pixels, the straight
    runs and the limb and rim fits.
    """
    from scipy import ndimage as ndi

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
        normals, values = normals[keep], values[keep]
        reading = _limb_or_rim(normals, np.sqrt(boundary.depth[keep]), values, runs[keep], levels, info)
        if reading is not None:
            return reading
    lit = values > levels.lit
    return _brightest_point(normals[lit], values[lit], levels, info)


def _limb_or_rim(normals, root_depth, values, runs, levels: Levels, info: dict) -> Reading | None:
    """The light from the occluding boundary pixels: a tilted rim if the fit with a constant term
    explains them much better, else the limb if its slant is well determined; None when neither
    (few curved lit pixels, or a slant the contour leaves loose). Fills ``info`` with the fits."""
    limb, limb_rms, limb_cov = _fit_ring(normals, root_depth, values, runs, intercept=False, scale=levels.lit)
    rim, rim_rms, _ = _fit_ring(normals, root_depth, values, None, intercept=True, scale=levels.lit)
    lit = values > levels.lit
    curved_lit = int(np.count_nonzero(lit & (runs < 0)))
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
    if rim[3] > _RIM_INTERCEPT * top and rim_rms < _RIM_GAIN * limb_rms:
        cos_rim = min(rim[3] / top, 0.999)
        info["rim_slant"] = math.degrees(math.acos(cos_rim))
        across = rim[:2] / math.sqrt(1.0 - cos_rim * cos_rim)  # k * L_xy
        return Reading(*from_components(across, top), "rim", info)
    across = limb[:2]
    info["slant_error"] = _slant_error(across, top, limb_cov[:2, :2])
    if info["slant_error"] > _DEGENERATE_SLANT:
        return None
    return Reading(*from_components(across, top), "limb", info)


def _brightest_point(normals, values, levels: Levels, info: dict) -> Reading:
    """The light when the contour cannot fix the slant: the brightest point faces the light, and
    the tilt is the lit contour's mean normal (``normals`` (n, 2)) weighted by intensity."""
    mean = (normals * values[:, None]).sum(axis=0) if values.size else np.zeros(2)
    tilt = math.degrees(math.atan2(mean[1], mean[0])) if np.hypot(*mean) > 0 else 0.0
    slant = slant_from_peak(levels.top, levels.peak)
    return Reading(slant, tilt, max(levels.peak, levels.top), "limb-peak", info)


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
        solution = lsq_linear(
            design[active] * root, values[active] * root[:, 0], bounds=(lower, np.inf), method="bvls"
        )
        change = float(np.abs(solution.x - params).max())
        params = solution.x
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
