"""Error measures between a reconstruction and its ground truth.

A method that leaves holes must not look better than one that fills them: wherever the
evaluated region contains an estimate that is NaN (or a zero normal), the summary error is
``inf``. The evaluated region defaults to where the ground truth is finite.

References
----------
.. [1] R. Zhang, P.-S. Tsai, J. E. Cryer and M. Shah, "Shape from shading: a survey",
   IEEE Trans. PAMI 21(8), 690-706, 1999 (depth and gradient errors on synthetic scenes).
.. [2] B. Shi, Z. Mo, Z. Wu, D. Duan, S.-K. Yeung and P. Tan, "A benchmark dataset and
   evaluation for non-Lambertian and uncalibrated photometric stereo", IEEE Trans. PAMI
   41(2), 271-284, 2019 (DiLiGenT: mean angular error, and mean absolute depth error).
"""

from __future__ import annotations

import numpy as np

from shadeform.errors import InputError

_REDUCTIONS = ("mean", "median", "none")
_FITS = ("none", "offset", "scale", "scale_offset", "median_scale")


def angular_error(normals, normals_true, mask=None, *, reduce: str = "mean"):
    """Angle between estimated and true normals, in degrees.

    The angle is ``atan2(|a x b|, a . b)``, exact for tiny and near-180 degree angles (no
    ``arccos`` of a dot product that rounding pushed past 1) and independent of the vectors'
    lengths.

    Parameters
    ----------
    normals : (H, W, 3) array_like
        Estimated normals.
    normals_true : (H, W, 3) array_like
        Ground-truth normals; must be finite in ``mask``.
    mask : (H, W) array_like of bool, optional
        Pixels to evaluate. Default: where ``normals_true`` is finite.
    reduce : {"mean", "median", "none"}, optional
        Summary over the mask, or ``"none"`` for the per-pixel map.

    Returns
    -------
    float or (H, W) float64
        Mean (or median) angle in degrees, ``inf`` if an estimate in the mask is NaN, inf or
        zero; with ``reduce="none"`` the map of angles, NaN outside the mask and where the
        estimate is invalid.

    Raises
    ------
    InputError
        Shapes that differ or are not (H, W, 3), an empty mask, NaN ground truth inside the
        mask, or an unknown ``reduce``.

    References
    ----------
    .. [1] B. Shi et al., "A benchmark dataset and evaluation for non-Lambertian and
       uncalibrated photometric stereo", IEEE Trans. PAMI 41(2), 2019.
    """
    if reduce not in _REDUCTIONS:
        raise InputError(f"reduce must be one of {', '.join(_REDUCTIONS)}; got {reduce!r}")
    a = np.asarray(normals, dtype=np.float64)
    b = np.asarray(normals_true, dtype=np.float64)
    if a.ndim != 3 or a.shape[-1] != 3 or a.shape != b.shape:
        raise InputError(f"normals must both have shape (H, W, 3), got {a.shape} and {b.shape}")
    mask = _region(mask, b, a.shape[:2], "normals")
    est, ref = a[mask], b[mask]
    valid = np.isfinite(est).all(axis=-1) & np.any(est != 0, axis=-1)
    with np.errstate(invalid="ignore"):
        cross = np.linalg.norm(np.cross(est, ref), axis=-1)
        dot = np.einsum("ij,ij->i", est, ref)
        angles = np.degrees(np.arctan2(cross, dot))
    if reduce == "none":
        out = np.full(mask.shape, np.nan)
        out[mask] = np.where(valid, angles, np.nan)
        return out
    if not valid.all():
        return float("inf")
    return float(np.mean(angles) if reduce == "mean" else np.median(angles))


def depth_error(depth, depth_true, mask=None, *, fit: str = "offset") -> float:
    """Root-mean-square depth error as a percent of the true depth range.

    Orthographic shape from shading fixes depth only up to an additive constant, so by default
    the estimate is first shifted by the least-squares offset (the mean difference).

    Parameters
    ----------
    depth : (H, W) array_like
        Estimated depth.
    depth_true : (H, W) array_like
        Ground-truth depth; must be finite in ``mask`` and not constant there.
    mask : (H, W) array_like of bool, optional
        Pixels to evaluate. Default: where ``depth_true`` is finite.
    fit : {"offset", "scale_offset", "scale", "median_scale", "none"}, optional
        Free parameters fitted before measuring: by least squares ``depth + b``,
        ``a * depth + b``, ``a * depth``; ``a * depth`` with ``a`` the median of
        ``depth_true / depth``; or nothing.

    Returns
    -------
    float
        ``100 * RMSE / (max - min of depth_true over the mask)``; ``inf`` if an estimated depth
        in the mask is NaN or inf (a method that leaves holes fails).

    Raises
    ------
    InputError
        Shapes that differ or are not (H, W), an empty mask, NaN or constant ground truth in
        the mask, or an unknown ``fit``.

    References
    ----------
    .. [1] R. Zhang et al., "Shape from shading: a survey", IEEE Trans. PAMI 21(8), 1999.
    """
    estimate, truth = _depth_pair(depth, depth_true, mask, fit)
    if estimate is None:
        return float("inf")
    spread = float(truth.max() - truth.min())
    if spread == 0:
        raise InputError(
            "true depth is constant over the mask, so a percent of its range is undefined; "
            "evaluate on a region where it varies"
        )
    residual = _fitted(estimate, truth, fit) - truth
    return float(100.0 * np.sqrt(np.mean(residual * residual)) / spread)


def made(depth, depth_true, mask=None, *, fit: str = "scale") -> float:
    """Mean absolute depth error, in the units of ``depth_true``.

    Used for perspective benchmarks such as DiLiGenT, whose depths are known up to a scale.

    Parameters
    ----------
    depth : (H, W) array_like
        Estimated depth.
    depth_true : (H, W) array_like
        Ground-truth depth; must be finite in ``mask``.
    mask : (H, W) array_like of bool, optional
        Pixels to evaluate. Default: where ``depth_true`` is finite.
    fit : {"scale", "median_scale", "offset", "scale_offset", "none"}, optional
        Free parameters fitted before measuring: by least squares ``a * depth``,
        ``depth + b``, ``a * depth + b``; ``a * depth`` with ``a`` the median of
        ``depth_true / depth`` (the protocol of BiNI's DiLiGenT evaluation [2]_, which its
        published figures use); or nothing.

    Returns
    -------
    float
        ``mean |fitted depth - depth_true|`` over the mask; ``inf`` if an estimated depth in
        the mask is NaN or inf.

    Raises
    ------
    InputError
        Shapes that differ or are not (H, W), an empty mask, NaN ground truth in the mask, or
        an unknown ``fit``.

    References
    ----------
    .. [1] B. Shi et al., "A benchmark dataset and evaluation for non-Lambertian and
       uncalibrated photometric stereo", IEEE Trans. PAMI 41(2), 2019.
    .. [2] X. Cao, H. Santo, B. Shi, F. Okura, Y. Matsushita, "Bilateral Normal Integration",
       ECCV 2022 (its evaluation script scales the estimate by the median depth ratio).
    """
    estimate, truth = _depth_pair(depth, depth_true, mask, fit)
    if estimate is None:
        return float("inf")
    return float(np.mean(np.abs(_fitted(estimate, truth, fit) - truth)))


def _region(mask, truth, shape, what: str) -> np.ndarray:
    """The evaluated pixels: ``mask`` checked against the ground truth, or its finite part."""
    if truth.ndim == 3:  # normals: a zero vector has no direction either
        finite = np.isfinite(truth).all(axis=-1) & np.any(truth != 0, axis=-1)
        bad = "NaN, inf or zero"
    else:
        finite = np.isfinite(truth)
        bad = "NaN or inf"
    if mask is None:
        region = finite
    else:
        region = np.asarray(mask)
        if region.shape != shape:
            raise InputError(f"mask shape {region.shape} does not match {what} shape {shape}")
        region = region.astype(bool)
        if not finite[region].all():
            raise InputError(f"true {what} are {bad} inside the mask; pass a mask within the ground truth")
    if not region.any():
        raise InputError(f"no pixels to evaluate: the mask or the true {what} selects none")
    return region


def _depth_pair(depth, depth_true, mask, fit):
    """Validated ``(estimate, truth)`` values inside the region, estimate None if not finite."""
    if fit not in _FITS:
        raise InputError(f"fit must be one of {', '.join(_FITS)}; got {fit!r}")
    d = np.asarray(depth, dtype=np.float64)
    t = np.asarray(depth_true, dtype=np.float64)
    if d.ndim != 2 or d.shape != t.shape:
        raise InputError(f"depths must both have shape (H, W), got {d.shape} and {t.shape}")
    region = _region(mask, t, d.shape, "depth")
    estimate = d[region]
    if not np.isfinite(estimate).all():
        return None, t[region]
    return estimate, t[region]


def _fitted(estimate, truth, fit):
    """``estimate`` after the fit of its free parameters to ``truth``."""
    if fit == "offset":
        return estimate + np.mean(truth - estimate)
    if fit == "scale":
        energy = float(np.dot(estimate, estimate))
        # An all-zero estimate has no scale to fit; it stays zero.
        return estimate * (np.dot(estimate, truth) / energy if energy > 0 else 0.0)
    if fit == "median_scale":
        nonzero = estimate != 0
        # Only the pixels with a defined ratio vote; an all-zero estimate stays zero.
        return estimate * (np.median(truth[nonzero] / estimate[nonzero]) if nonzero.any() else 0.0)
    if fit == "scale_offset":
        design = np.column_stack([estimate, np.ones_like(estimate)])
        coef, *_ = np.linalg.lstsq(design, truth, rcond=None)
        return design @ coef
    return estimate
