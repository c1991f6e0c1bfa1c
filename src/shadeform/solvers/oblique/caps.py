"""Where the marching starts: the brightest caps, and one height datum per cap.

A pixel as bright as ``albedo`` faces the light (``N = L``): a singular point of the shading
equation [1]_, where the normal is known without any neighbour. :func:`march_sources` picks them
(the pixels within ``tol`` of full brightness), plus the brightest pixel of each part of the lit
region that holds none, so that the marching reaches every part.

Within one cap of such pixels the height along ``L`` is constant (``N = L`` all over it), so its
pixels' heights follow from their positions. Two separate caps are at unknown heights along ``L``
from each other, so each starts its own height datum (:func:`cap_datums`), and the marching
fits a pixel to the neighbours of one datum only: where the fronts of two caps meet, neither's
heights nor its drift reach the other's pixels. Noise splits one cap into groups a few pixels
apart, which must share a datum: groups are merged when the brightest path between them keeps
the plateau's height error under a pixel.

References
----------
.. [1] E. Prados and O. Faugeras, "Shape from shading: a well-posed problem?", CVPR 2005.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy import ndimage as ndi

#: Pixels with ``I / albedo >= 1 - TOL`` start the marching (with ``N = L``). Set by hand on the
#: synthetic sphere and vase under the light (5, 5, 7) (``benchmarks/bench_oblique.py``); noisy
#: images want about their noise's relative level.
TOL = 2e-3

#: Groups of sources the merge tree holds (bits 1-62 of an int64).
_MAX_GROUPS = 62


def march_sources(cos_theta: np.ndarray, lit: np.ndarray, tol: float) -> np.ndarray:
    """The pixels that start the marching.

    Parameters
    ----------
    cos_theta : (H, W) float
        ``I / albedo`` in [0, 1].
    lit : (H, W) bool
    tol : float
        Lit pixels with ``cos_theta >= 1 - tol`` are sources.

    Returns
    -------
    (S, 2) int64
        ``(row, col)``: the brightest lit pixel first (the main source, ``z = 0``), then every
        other lit pixel within ``tol`` of full brightness, then the brightest pixel of every part
        of the lit region (8-connected) that has none.
    """
    main = np.unravel_index(np.argmax(np.where(lit, cos_theta, -1.0)), lit.shape)
    bright = np.argwhere(lit & (cos_theta >= 1.0 - tol))
    chosen = np.zeros(lit.shape, dtype=bool)
    chosen[main] = True
    rows = [main]
    for r, c in bright:
        if not chosen[r, c]:
            chosen[r, c] = True
            rows.append((r, c))
    labels, n_parts = ndi.label(lit, structure=np.ones((3, 3), dtype=bool))
    covered = set(np.unique(labels[chosen]))
    for part in range(1, n_parts + 1):
        if part not in covered:
            where = np.where(labels == part, cos_theta, -1.0)
            rows.append(np.unravel_index(np.argmax(where), lit.shape))
    return np.array(rows, dtype=np.int64)


@numba.njit(cache=True)
def _find(parent, a):
    """Root of ``a`` in the union-find forest ``parent``, halving the path on the way."""
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@numba.njit(cache=True)
def _cap_merges(order, values, group, lit, reach):
    """Merge tree of the lit pixels by brightness (brightest first, 8-neighbours): when two
    parts holding groups ``i`` and ``j`` of sources first meet, at a pixel of value ``v``, the
    groups are joined if ``reach[i, j] * sqrt(2 d - d^2) < 1`` with ``d = 1 - v``. ``group``
    is 0 or the group (1-62) of each pixel; ``order`` the lit pixels' flat indices, brightest
    first, and ``values`` their brightness. Returns the group-level parents."""
    height, width = lit.shape
    parent = np.arange(height * width)
    seen = np.zeros(height * width, np.bool_)
    bits = np.zeros(height * width, np.int64)
    groups = reach.shape[0]
    joined = np.arange(groups)
    for k in range(order.shape[0]):
        p = order[k]
        v = values[k]
        r = p // width
        c = p % width
        seen[p] = True
        if group[r, c] > 0:
            bits[p] = np.int64(1) << np.int64(group[r, c])
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                rr = r + dr
                cc = c + dc
                if (
                    (dr == 0 and dc == 0)
                    or rr < 0
                    or rr >= height
                    or cc < 0
                    or cc >= width
                    or not seen[rr * width + cc]
                ):
                    continue
                # a neighbour already visited, so at least as bright as this pixel
                a = _find(parent, p)
                b = _find(parent, rr * width + cc)
                if a == b:
                    continue
                d = min(max(1.0 - v, 0.0), 1.0)
                rise = np.sqrt(2.0 * d - d * d)
                for i in range(1, groups):
                    if (bits[a] >> np.int64(i)) & 1 == 0:
                        continue
                    for j in range(1, groups):
                        if i != j and (bits[b] >> np.int64(j)) & 1 == 1 and reach[i, j] * rise < 1.0:
                            x = _find(joined, i)
                            y = _find(joined, j)
                            if x != y:
                                joined[max(x, y)] = min(x, y)
                parent[b] = a
                bits[a] |= bits[b]
    return joined


def cap_datums(seeds: np.ndarray, cos_theta: np.ndarray, lit: np.ndarray) -> np.ndarray:
    """Label the sources by cap of ``N = L``, one height datum each.

    Connected sources lie on one plateau of the height along ``L``. Two separate groups do too
    when that plateau cannot be wrong by a pixel between them: on a path over which the
    brightness stays above ``1 - d`` the normal stays within ``acos(1 - d)`` of ``L``, so the
    height along ``L`` changes by at most ``D sqrt(2 d - d^2)`` over a distance ``D``. Groups
    split by noise (a few pixels apart, ``d`` about the noise) fall under a pixel and are merged;
    the synthetic vase's neck and belly under slant 30 degrees (53 px apart, ``d = 0.021``: up to
    11 px) keep their own datums.

    Parameters
    ----------
    seeds : (H, W) bool
        The sources.
    cos_theta : (H, W) float
        ``I / albedo``.
    lit : (H, W) bool

    Returns
    -------
    (H, W) int64
        The datum of each source (1, 2, ...; not consecutive), 0 elsewhere. More than
        ``_MAX_GROUPS`` separate groups share one datum, as for a single cap.
    """
    from scipy.spatial import cKDTree

    labels, count = ndi.label(seeds, structure=np.ones((3, 3), dtype=bool))
    if count > _MAX_GROUPS:
        return seeds.astype(np.int64)
    if count < 2:
        return labels.astype(np.int64)
    where = [np.argwhere(labels == i) for i in range(1, count + 1)]
    reach = np.zeros((count + 1, count + 1))
    for i in range(count):
        tree = cKDTree(where[i])
        for j in range(i + 1, count):
            reach[i + 1, j + 1] = reach[j + 1, i + 1] = tree.query(where[j])[0].min()
    flat = np.flatnonzero(lit.ravel())
    values = cos_theta.ravel()[flat]
    rank = np.argsort(-values, kind="stable")
    joined = _cap_merges(
        flat[rank].astype(np.int64), values[rank], labels.astype(np.int64), np.ascontiguousarray(lit), reach
    )
    roots = np.array([0] + [_find(joined, i) for i in range(1, count + 1)], dtype=np.int64)
    return roots[labels]
