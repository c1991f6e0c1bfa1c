"""Bas-relief compression of a depth map (:func:`compress_depth`): steep slopes and depth jumps
flattened in the gradient domain, fine detail kept."""

from __future__ import annotations

import numpy as np

from shadeform._checks import finite

__all__ = ["compress_depth"]

# relative residual at which the compressed depth's least-squares solve stops: the relief is
# printed to ~1e-3 of its height, and 1e-6 moved no bump share of tests/test_relief.py in its 4th digit
_COMPRESS_TOLERANCE = 1e-6


def compress_depth(depth: np.ndarray, mask: np.ndarray, *, compress: float) -> np.ndarray:
    """Bas-relief compression: steep slopes and depth jumps flattened, fine detail kept.

    The depth differences between 4-neighbour pixels are scaled down where the gradient is steep
    and integrated back by least squares (the project's multigrid Poisson solver,
    :class:`shadeform.integration._multigrid.PairHierarchy`), as in the gradient-domain
    bas-relief methods of Weyrich et al. (2007) and Kerber et al. (2009). The attenuation is
    Fattal et al.'s (2002) power law: a pixel whose gradient magnitude ``g`` exceeds ``alpha``
    has its slopes multiplied by ``(g / alpha) ** -compress``; gentler slopes are left as they
    are (not amplified: noise stays noise). ``alpha`` is the mean magnitude over the object (a
    depth jump adds its height spread over the object, not its one-pixel slope), so only slopes
    steeper than the object's typical one shrink, the more the steeper they are: a jump's slope
    ``g`` becomes ``alpha ** c * g ** (1 - c)``, while a small bump whose slopes stay near the
    mean keeps its relief. Each pair of pixels gets the mean of the two pixels' factors. A plane
    is left as it is (every slope is the mean); ``tests/test_relief.py`` and
    ``benchmarks/results/relief.md`` show a jump with bumps: at ``compress=0.5`` the bumps take
    3.6 times the share of the height that linear scaling leaves them.

    Parameters
    ----------
    depth : (H, W) float
        Height, finite on the mask.
    mask : (H, W) bool
        Where the depth is defined.
    compress : float, keyword-only
        Exponent ``c`` in ``[0, 1]``: 0 returns the depth unchanged, 1 clamps every slope above
        ``alpha`` to ``alpha``.

    Returns
    -------
    (H, W) float64
        The compressed height, NaN off the mask. Each connected part keeps its mean scaled by
        the factor the largest part's depth range was compressed by.

    References
    ----------
    Weyrich et al. 2007, Kerber et al. 2009, Fattal et al. 2002: see :mod:`shadeform.solid`'s references.
    """
    from shadeform.integration._multigrid import PairHierarchy

    mask = np.asarray(mask, dtype=bool)
    depth = np.asarray(depth, dtype=np.float64)
    out = np.where(mask, depth, np.nan)
    compress = finite(compress, "compress")
    if not mask.any() or compress == 0:
        return out
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    box = np.s_[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
    m = np.ascontiguousarray(mask[box])
    z = np.where(m, depth[box], 0.0)
    h, w = m.shape
    # pairs (r, c)-(r, c + 1) and (r, c)-(r + 1, c) on the object; differences along them
    across = m[:, :-1] & m[:, 1:]
    down = m[:-1] & m[1:]
    dx = np.where(across, z[:, 1:] - z[:, :-1], 0.0)
    dy = np.where(down, z[1:] - z[:-1], 0.0)
    # the pixel's gradient: the mean of the differences on its sides that exist
    magnitude = _side_mean(dx, across, axis=1) ** 2
    magnitude += _side_mean(dy, down, axis=0) ** 2
    np.sqrt(magnitude, out=magnitude)
    alpha = float(magnitude[m].mean())
    if not alpha > 0:
        return out
    # the attenuation factor of each pixel (in place of its magnitude), each pair the mean of two
    factor = magnitude
    factor /= alpha
    np.maximum(factor, 1.0, out=factor)
    np.power(factor, -compress, out=factor)
    dx *= 0.5 * (factor[:, :-1] + factor[:, 1:])
    dy *= 0.5 * (factor[:-1] + factor[1:])
    del factor, magnitude
    # normal equations of min sum (z_j - z_i - t_ij)^2: L z = D^T t
    b = np.zeros((h, w))
    b[:, :-1] -= dx
    b[:, 1:] += dx
    b[:-1] -= dy
    b[1:] += dy
    del dx, dy
    px = np.zeros((h, w))
    px[:, :-1] = across
    py = np.zeros((h, w))
    py[:-1] = down
    hierarchy = PairHierarchy(m, px, py)
    solved, _, _ = hierarchy.solve_pairs(b, np.zeros((h, w)), tol=_COMPRESS_TOLERANCE, maxiter=500)
    # each part's offset: its mean, scaled as the largest part's range was
    labels = hierarchy.labels
    on = labels >= 0
    counts = np.bincount(labels[on], minlength=hierarchy.n_parts)
    old_mean = np.bincount(labels[on], weights=z[on], minlength=hierarchy.n_parts) / np.maximum(counts, 1)
    new_mean = np.bincount(labels[on], weights=solved[on], minlength=hierarchy.n_parts) / np.maximum(
        counts, 1
    )
    largest = labels == np.argmax(counts)
    old_range = np.ptp(z[largest])
    ratio = np.ptp(solved[largest]) / old_range if old_range > 0 else 1.0
    solved[on] += (old_mean * ratio - new_mean)[labels[on]]
    out[box] = np.where(m, solved, np.nan)
    return out


def _side_mean(differences: np.ndarray, exists: np.ndarray, *, axis: int) -> np.ndarray:
    """Per pixel, the mean of the pair differences on its two sides along ``axis`` that exist
    (``differences``, ``exists``: one shorter than the image along ``axis``)."""
    shape = list(differences.shape)
    shape[axis] += 1
    total = np.zeros(shape)
    count = np.zeros(shape)
    first = [slice(None), slice(None)]
    last = [slice(None), slice(None)]
    first[axis] = slice(None, -1)
    last[axis] = slice(1, None)
    for part in (tuple(first), tuple(last)):
        total[part] += differences
        count[part] += exists
    return total / np.maximum(count, 1.0)
