"""No holes (:mod:`shadeform.photometric`'s description): pixels that too few lights reached get
the normal their own lit readings allow with their neighbours' as a prior, one sparse solve over
all of them.
"""

from __future__ import annotations

import numpy as np


def _fill(g, mask, where, pixels, outer, moment):
    """``g`` (P, 3) with its non-finite rows (``pixels``, in order) solved from their own lit
    readings (``outer`` (H, 3, 3) = sum l l^T, ``moment`` (H, 3) = sum I l) and their 4-neighbours
    on the object, each neighbour weighing as one photo: one sparse solve over all of them.
    A part with no solved neighbour and no data leans (with a vanishing weight) toward the
    object's median albedo facing the camera."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    h, w = mask.shape
    count = pixels.size
    number = np.full(h * w, -1, dtype=np.int64)  # object pixel -> row of g
    number[where] = np.arange(where.size)
    hole = np.full(where.size, -1, dtype=np.int64)  # row of g -> unknown
    hole[pixels] = np.arange(count)
    known = np.isfinite(g[:, 0])
    rho = np.linalg.norm(g[known], axis=1)
    prior = np.array([0.0, 0.0, float(np.median(rho)) if rho.size else 1.0])
    ridge = 1e-6
    diagonal = outer + ridge * np.eye(3)
    rhs = moment + ridge * prior
    rows, cols = np.divmod(where[pixels], w)
    neighbours_i, neighbours_j = [], []
    for d_row, d_col in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        r, c = rows + d_row, cols + d_col
        inside = (r >= 0) & (r < h) & (c >= 0) & (c < w)
        other = np.full(count, -1, dtype=np.int64)
        other[inside] = number[r[inside] * w + c[inside]]
        on = other >= 0
        diagonal[on] += np.eye(3)
        solved = on & (hole[np.maximum(other, 0)] < 0)
        rhs[solved] += g[other[solved]]
        open_ = on & ~solved
        neighbours_i.append(np.flatnonzero(open_))
        neighbours_j.append(hole[other[open_]])
    i, j = np.concatenate(neighbours_i), np.concatenate(neighbours_j)
    # one 3x3 block per unknown pixel on the diagonal, built at once (no loop over the pixels)
    block = sp.bsr_matrix((diagonal, np.arange(count), np.arange(count + 1)), shape=(3 * count, 3 * count))
    coupling = sp.kron(
        sp.csr_matrix((np.ones(i.size), (i, j)), shape=(count, count)), sp.eye(3), format="csr"
    )
    solution = spla.spsolve((block - coupling).tocsc(), rhs.ravel()).reshape(count, 3)
    g = g.copy()
    g[pixels] = solution
    return g
