"""The grids every kernel of the multigrid solver runs on, and the red-black order they are kept in.

Every grid, the finest and each multigrid level, is a dense grid over the mask's bounding box with
a border of inactive cells, so that no kernel needs a bounds check: interior rows ``1..h``, columns
``1..w``, padded to ``hp = h + 2`` rows and ``wp = 2 (w // 2 + 2)`` columns (:func:`padded`). An
operator on such a grid is given by its pair weights: ``wx[i, j]`` weighs the pair
``(i, j)-(i, j + 1)`` and ``wy[i, j]`` the pair ``(i, j)-(i + 1, j)``, 0 where a pair is missing.

Every grid is kept in *red-black order*: an array ``a[c, i, k]`` of shape ``(2, hp, wp / 2)``
holds the cells of colour ``c = (i + j) % 2``, cell ``(i, j)`` at ``k = j // 2``. A cell's four
neighbours all have the other colour; in that array they sit at ``[i, k + s - 1]`` (left),
``[i, k + s]`` (right), ``[i - 1, k]`` and ``[i + 1, k]`` (up, down), with ``s = (i + c) % 2``.
Every loop of a Gauss-Seidel half-sweep is then contiguous, which the compiler vectorises. Loops
run over the fixed range ``k = 1 .. m-2`` (``m = wp / 2``; a variable start defeats the
vectoriser), which covers the interior but for column 1, done on its own, and otherwise only border
cells, which stay 0.

Vectors that no kernel reads by neighbour (the CG's) are handled flat, in :data:`CHUNKS` blocks.
"""

from __future__ import annotations

import numba
from numba import prange

#: Blocks of the flat vector kernels (not a tuned value: more blocks than threads).
CHUNKS = 64
#: Fast-math flags of the arithmetic kernels: reassociation (vectorised sums) but not ``nnan`` or
#: ``ninf``, so that guards such as ``not pq > 0.0`` still see a NaN.
FAST = {"contract", "reassoc", "nsz", "arcp"}


def padded(h: int, w: int) -> tuple[int, int]:
    """Padded grid shape: a border of at least one cell, an even number of columns, and in
    red-black order ``k = 1 .. m-2`` (``m = wp / 2``) reaching the last interior column."""
    return h + 2, 2 * (w // 2 + 2)


@numba.njit(cache=True)
def split(nat, out):
    """Natural ``(hp, wp)`` grid -> red-black ``(2, hp, wp / 2)``."""
    for c in range(2):
        for i in range(nat.shape[0]):
            s = (i + c) & 1
            for k in range(out.shape[2]):
                out[c, i, k] = nat[i, 2 * k + s]


@numba.njit(cache=True, parallel=True)
def to_rb(nat, out):
    """Natural ``(h, w)`` values -> red-black cells ``(i, j) = (r + 1, c + 1)``, 0 elsewhere."""
    h, w = nat.shape
    out[:] = 0.0
    for r in prange(h):
        i = r + 1
        for c in range(w):
            j = c + 1
            out[(i + j) & 1, i, j >> 1] = nat[r, c]


@numba.njit(cache=True)
def from_rb(rb, out):
    """Red-black cells -> natural ``(h, w)`` values (inverse of :func:`to_rb`)."""
    h, w = out.shape
    for r in range(h):
        i = r + 1
        for c in range(w):
            j = c + 1
            out[r, c] = rb[(i + j) & 1, i, j >> 1]


@numba.njit(cache=True)
def level(buf, offsets, dims, lev):
    """Level ``lev``'s red-black view ``(2, hp, wp / 2)`` of a flat per-level buffer."""
    return buf[offsets[lev] : offsets[lev + 1]].reshape(2, dims[lev, 2], dims[lev, 3] // 2)


@numba.njit(cache=True, inline="always")
def around(a, c, i):
    """The cells of colour ``c`` in row ``i`` of red-black array ``a`` and the rows that hold their
    neighbours: ``a[c, i]``, then of the other colour ``o`` the same row (left neighbour at
    ``k + s - 1``, right at ``k + s``), the row above and the row below (both at ``k``)."""
    o = 1 - c
    return a[c, i], a[o, i], a[o, i - 1], a[o, i + 1]


@numba.njit(cache=True, inline="always")
def pair_rows(wx, wy, c, i):
    """The pair weights of the cells of colour ``c`` in row ``i``: to the right (at ``k``), to the
    left (at ``k + s - 1``), below and above (at ``k``)."""
    o = 1 - c
    return wx[c, i], wx[o, i], wy[c, i], wy[o, i - 1]


@numba.njit(cache=True, inline="always")
def chunk(n, t, blocks):
    """Bounds of block ``t`` of ``blocks`` over ``range(n)``."""
    return n * t // blocks, n * (t + 1) // blocks


@numba.njit(cache=True, parallel=True)
def copy_flat(src, dst):
    """``dst = src`` (flat arrays, with a cast)."""
    for t in prange(CHUNKS):
        a0, a1 = chunk(src.shape[0], t, CHUNKS)
        dst[a0:a1] = src[a0:a1]
