"""Distances from a height field's pixels to a triangulated surface (numba kernels of
:func:`shadeform.solid.build._deviation`, imported on first use so that importing
:mod:`shadeform.solid` stays cheap)."""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["BOUND_SHARES", "BUCKET_PIXELS", "buckets", "covering_distances", "largest_distance"]

#: Side, pixels, of the buckets that find the triangles near a pixel. Only the speed depends on
#: it, not the result; set by hand (a 200,000-triangle relief of 12 Mpx: triangles of about 60
#: pixels, a few per bucket).
BUCKET_PIXELS = 16
#: Shares of the pixels, largest bounds first, whose nearest triangle is searched for in turn (the
#: last, 1, is all of them). Only the speed depends on them, not the result; set by hand.
BOUND_SHARES = (1e-4, 1e-3, 1e-2, 1e-1, 1.0)


@numba.njit(cache=True)
def covering_distances(tri, surface, bounds):  # pragma: no cover - compiled
    """``bounds[r, c]``: distance from ``(c, r, surface[r, c])`` to the triangle of ``tri`` ((T, 3,
    3): column, row, z) over or under that pixel centre; finite surface pixels only."""
    n_rows, n_cols = surface.shape
    eps = 1e-9
    for t in range(tri.shape[0]):
        x0, x1, x2 = tri[t, 0, 0], tri[t, 1, 0], tri[t, 2, 0]
        y0, y1, y2 = tri[t, 0, 1], tri[t, 1, 1], tri[t, 2, 1]
        det = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if det == 0.0:
            continue
        c_lo = max(0, int(math.ceil(min(x0, x1, x2) - eps)))
        c_hi = min(n_cols - 1, int(math.floor(max(x0, x1, x2) + eps)))
        r_lo = max(0, int(math.ceil(min(y0, y1, y2) - eps)))
        r_hi = min(n_rows - 1, int(math.floor(max(y0, y1, y2) + eps)))
        for r in range(r_lo, r_hi + 1):
            for c in range(c_lo, c_hi + 1):
                l1 = ((c - x0) * (y2 - y0) - (x2 - x0) * (r - y0)) / det
                l2 = ((x1 - x0) * (r - y0) - (c - x0) * (y1 - y0)) / det
                if l1 < -eps or l2 < -eps or l1 + l2 > 1.0 + eps:
                    continue
                h = surface[r, c]
                if h == h:
                    bounds[r, c] = point_triangle(float(c), float(r), h, tri, t)


@numba.njit(cache=True)
def buckets(tri, shape, bucket):  # pragma: no cover - compiled
    """The triangles whose bounding box meets each ``bucket`` x ``bucket`` square of pixels:
    bucket ``b = (row // bucket) * n_bucket_cols + col // bucket`` holds
    ``members[starts[b]:starts[b + 1]]``."""
    n_br = shape[0] // bucket + 1
    n_bc = shape[1] // bucket + 1
    counts = np.zeros(n_br * n_bc + 1, dtype=np.int64)
    for t in range(tri.shape[0]):
        r0, r1, c0, c1 = bucket_box(tri, t, bucket, n_br, n_bc)
        for br in range(r0, r1 + 1):
            for bc in range(c0, c1 + 1):
                counts[br * n_bc + bc + 1] += 1
    starts = np.cumsum(counts)
    fill = starts[:-1].copy()
    members = np.empty(starts[-1], dtype=np.int64)
    for t in range(tri.shape[0]):
        r0, r1, c0, c1 = bucket_box(tri, t, bucket, n_br, n_bc)
        for br in range(r0, r1 + 1):
            for bc in range(c0, c1 + 1):
                b = br * n_bc + bc
                members[fill[b]] = t
                fill[b] += 1
    return starts, members


@numba.njit(cache=True)
def bucket_box(tri, t, bucket, n_br, n_bc):  # pragma: no cover - compiled
    c_lo = min(tri[t, 0, 0], tri[t, 1, 0], tri[t, 2, 0])
    c_hi = max(tri[t, 0, 0], tri[t, 1, 0], tri[t, 2, 0])
    r_lo = min(tri[t, 0, 1], tri[t, 1, 1], tri[t, 2, 1])
    r_hi = max(tri[t, 0, 1], tri[t, 1, 1], tri[t, 2, 1])
    return (
        min(max(int(r_lo) // bucket, 0), n_br - 1),
        min(max(int(r_hi) // bucket, 0), n_br - 1),
        min(max(int(c_lo) // bucket, 0), n_bc - 1),
        min(max(int(c_hi) // bucket, 0), n_bc - 1),
    )


@numba.njit(cache=True)
def largest_distance(rows, cols, surface, tri, starts, members, bucket):  # pragma: no cover
    """Max over the pixels of the distance from ``(c, r, surface[r, c])`` to the nearest triangle,
    searched in rings of buckets until the rest lie farther than the nearest found."""
    n_br = surface.shape[0] // bucket + 1
    n_bc = surface.shape[1] // bucket + 1
    worst = 0.0
    for k in range(rows.shape[0]):
        r, c = rows[k], cols[k]
        h = surface[r, c]
        br, bc = r // bucket, c // bucket
        best = np.inf
        ring = 0
        while True:
            for i in range(max(br - ring, 0), min(br + ring, n_br - 1) + 1):
                for j in range(max(bc - ring, 0), min(bc + ring, n_bc - 1) + 1):
                    if abs(i - br) != ring and abs(j - bc) != ring:
                        continue  # an inner bucket: searched in an earlier ring
                    b = i * n_bc + j
                    for m in range(starts[b], starts[b + 1]):
                        d = point_triangle(float(c), float(r), h, tri, members[m])
                        if d < best:
                            best = d
            # triangles in no bucket searched yet lie at least this far away, sideways
            margin = min(
                c - (bc - ring) * bucket,
                (bc + ring + 1) * bucket - c,
                r - (br - ring) * bucket,
                (br + ring + 1) * bucket - r,
            )
            if best <= margin or (ring >= n_br and ring >= n_bc):
                break
            ring += 1
        if best > worst:
            worst = best
    return worst


@numba.njit(cache=True)
def point_triangle(px, py, pz, tri, t):  # pragma: no cover - compiled
    """Distance from ``(px, py, pz)`` to triangle ``tri[t]`` ((3, 3) corners), by the closest
    point's Voronoi region (C. Ericson, Real-Time Collision Detection, 2005, section 5.1.5)."""
    ax, ay, az = tri[t, 0, 0], tri[t, 0, 1], tri[t, 0, 2]
    abx, aby, abz = tri[t, 1, 0] - ax, tri[t, 1, 1] - ay, tri[t, 1, 2] - az
    acx, acy, acz = tri[t, 2, 0] - ax, tri[t, 2, 1] - ay, tri[t, 2, 2] - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    # the closest point a + v ab + w ac
    if d1 <= 0.0 and d2 <= 0.0:
        v, w = 0.0, 0.0
    else:
        bpx, bpy, bpz = apx - abx, apy - aby, apz - abz
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        cpx, cpy, cpz = apx - acx, apy - acy, apz - acz
        d5 = abx * cpx + aby * cpy + abz * cpz
        d6 = acx * cpx + acy * cpy + acz * cpz
        vc = d1 * d4 - d3 * d2
        vb = d5 * d2 - d1 * d6
        va = d3 * d6 - d5 * d4
        if d3 >= 0.0 and d4 <= d3:
            v, w = 1.0, 0.0
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            v, w = d1 / (d1 - d3), 0.0
        elif d6 >= 0.0 and d5 <= d6:
            v, w = 0.0, 1.0
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
            v, w = 0.0, d2 / (d2 - d6)
        elif va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
            w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
            v = 1.0 - w
        else:
            denom = 1.0 / (va + vb + vc)
            v, w = vb * denom, vc * denom
    ex = apx - v * abx - w * acx
    ey = apy - v * aby - w * acy
    ez = apz - v * abz - w * acz
    return math.sqrt(ex * ex + ey * ey + ez * ez)
