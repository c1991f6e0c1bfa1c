"""The photo solver's energy on one pyramid level (:mod:`shadeform.solvers.photo`'s description):
its weights, the level's difference operators and outline, the compiled kernel of the energy and
its gradient, and the slow numpy reference the kernel is tested against.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

from shadeform.integration.poisson import difference_system
from shadeform.solvers.photo.pyramid import _Basis

#: Smoothness weight per pair of neighbouring pixels, for an object of ``2 COARSEST`` pixels
#: (other sizes: the package's description).
MU = 1e-2
#: Change of the unit normal between neighbours (about 3 degrees) below which smoothness is
#: quadratic; above it grows linearly, so a crease costs its length, not its square (same size).
EPS = 0.05
#: Contour weight per outline pixel (same size).
NU = 1e-2
#: Scale of Cauchy's loss on the shading residual, in units of ``N . L``.
SCALE = 0.1


class _Level:
    """One pyramid level: the object's pixels, its difference operators and hierarchical basis."""

    def __init__(self, image, mask, light, *, spacing=1.0, concave_x=None, concave_y=None, prior=None):
        from shadeform.light.contour import find_boundary

        self.mask = mask
        self.spacing = spacing
        index, rows, cols = _index(mask)
        self.n = rows.size
        self.values = image[mask]
        self.light = light
        self.col_stencil, self.row_stencil = (
            _slope_stencil(index, rows, cols, step) for step in ((0, 1), (1, 0))
        )
        # the 4-neighbouring object pixels p, q of each difference z_q - z_p of Poisson's operator
        _, pairs, _ = difference_system(mask, np.ones(mask.shape))
        ends = pairs.tocoo()
        self.first, self.second = np.empty((2, pairs.shape[0]), dtype=np.int64)
        self.first[ends.row[ends.data < 0]] = ends.col[ends.data < 0]  # p of z_q - z_p
        self.second[ends.row[ends.data > 0]] = ends.col[ends.data > 0]  # q
        boundary = find_boundary(mask)
        # where the outline crosses a region concave along the outline's normal, it is a rim, not
        # an occluding contour (there the surface turns away from the viewer: convex across it)
        contour = np.ones(boundary.rows.size, dtype=bool)
        if concave_x is not None:
            across_x = np.abs(boundary.normals[:, 0]) >= np.abs(boundary.normals[:, 1])
            on_x = concave_x[boundary.rows, boundary.cols]
            on_y = concave_y[boundary.rows, boundary.cols]
            contour = ~((on_x & across_x) | (on_y & ~across_x))
        self.outline = index[boundary.rows[contour], boundary.cols[contour]]
        self.outward = np.ascontiguousarray(boundary.normals[contour], dtype=np.float64)
        # a clipped plateau (two or more pixels at the object's top value) carries no shading
        top = self.values.max()
        at_top = self.values >= top * (1.0 - 1e-3)
        self.data = ~at_top if np.count_nonzero(at_top) > 1 else np.ones(self.n, dtype=bool)
        self.basis = _Basis(mask)
        self.unknowns = self.basis.size
        self.work = np.empty((11, self.n))
        # the prior's normals and weights on the object's pixels; none where marked concave (the
        # user's marks overrule what the prior expects)
        self.prior = None
        if prior is not None:
            weight = prior[1][mask]
            if concave_x is not None:
                weight = np.where((concave_x | concave_y)[mask], 0.0, weight)
            self.prior = (np.ascontiguousarray(prior[0][mask]), weight)

    def weights(self):
        """``(MU, EPS, NU, SCALE)`` at this level's pixel spacing ``h`` (in units of the reference
        resolution): ``MU / h``, ``EPS * h``, ``NU / h``. Read per call: tests and experiments may
        change the module's constants."""
        h = self.spacing
        return np.array([MU / h, EPS * h, NU / h, SCALE])

    def depth(self, coefficients):
        """Depth on the object's pixels from the basis coefficients."""
        return self.basis.expand(coefficients)

    def normals(self, z):
        """(n, 3) unit normals of depth ``z`` on the object's pixels."""
        gx, gy = (
            half * (z[ahead] - z[behind]) for ahead, behind, half in (self.col_stencil, self.row_stencil)
        )
        inverse = 1.0 / np.sqrt(1.0 + gx * gx + gy * gy)
        return np.column_stack([-gx * inverse, gy * inverse, inverse])

    def energy(self, coefficients, curve):
        """The energy and its gradient with respect to the basis coefficients, under the
        reflectance curve ``curve`` ((K, 2) rows ``(n . L, brightness)``): one compiled pass
        (:func:`_energy_kernel`) between the basis and its transpose."""
        z = self.depth(coefficients)
        g_z = np.empty(self.n)
        energy = _energy_kernel(
            z,
            self.values,
            self.data,
            self.light,
            np.ascontiguousarray(curve[:, 0]),
            np.ascontiguousarray(curve[:, 1]),
            *self.col_stencil,
            *self.row_stencil,
            self.first,
            self.second,
            self.outline,
            self.outward,
            self.weights(),
            self.work,
            g_z,
        )
        if self.prior is not None:
            energy += self._prior_term(z, g_z)
        return energy, self.basis.reduce(g_z)

    def _prior_term(self, z, g_z):
        """``sum_p w_p (1 - n_p . m_p)`` for the prior's normals ``m``; its gradient is added to
        ``g_z``. Vectorised numpy (a few array passes; the kernel's loops need no change)."""
        (col_ahead, col_behind, col_half), (row_ahead, row_behind, row_half) = (
            self.col_stencil,
            self.row_stencil,
        )
        a = col_half * (z[col_ahead] - z[col_behind])
        b = row_half * (z[row_ahead] - z[row_behind])
        c = 1.0 / np.sqrt(1.0 + a * a + b * b)
        m, w = self.prior
        dot = (-a * m[:, 0] + b * m[:, 1] + m[:, 2]) * c  # n = (-a, b, 1) c
        # d(dot)/da, d(dot)/db of the energy -w dot
        g_a = -w * (-m[:, 0] * c - dot * a * c * c)
        g_b = -w * (m[:, 1] * c - dot * b * c * c)
        n = z.size
        g_z += np.bincount(col_ahead, col_half * g_a, n) - np.bincount(col_behind, col_half * g_a, n)
        g_z += np.bincount(row_ahead, row_half * g_b, n) - np.bincount(row_behind, row_half * g_b, n)
        return float(np.sum(w * (1.0 - dot)))

    def energy_reference(self, coefficients, curve):
        """:meth:`energy` in plain numpy and sparse products (slow, obviously correct: the
        compiled kernel is tested against it)."""
        d_col, d_row = (_slope_matrix(*stencil) for stencil in (self.col_stencil, self.row_stencil))
        _, pairs, _ = difference_system(self.mask, np.ones(self.mask.shape))
        z = self.depth(coefficients)
        gx, gy = d_col @ z, d_row @ z
        inverse = 1.0 / np.sqrt(1.0 + gx * gx + gy * gy)
        nx, ny, nz = -gx * inverse, gy * inverse, inverse
        lx, ly, lz = self.light
        shading = nx * lx + ny * ly + nz * lz
        # shading: Cauchy loss on (f(n . L) - I) / a, f piecewise linear
        knots, levels = curve[:, 0], curve[:, 1]
        inverse_albedo = 1.0 / levels[-1]
        segment = np.clip(np.searchsorted(knots, shading) - 1, 0, knots.size - 2)
        slope = np.diff(levels) / np.diff(knots)
        inside = (shading > knots[0]) & (shading < knots[-1])  # f is flat beyond its ends
        residual = (np.interp(shading, knots, levels) - self.values) * inverse_albedo
        ratio = residual * residual / (SCALE * SCALE)
        energy = 0.5 * SCALE * SCALE * np.sum(np.log1p(ratio)[self.data])
        d_shading = np.where(
            self.data & inside, residual / (1.0 + ratio) * slope[segment] * inverse_albedo, 0.0
        )
        g_x = d_shading * (-lx * inverse - shading * gx * inverse * inverse)
        g_y = d_shading * (ly * inverse - shading * gy * inverse * inverse)
        # smoothness: robust in the change of the normal between neighbours
        mu, eps, nu, _ = self.weights()
        steps = [pairs @ component for component in (nx, ny, nz)]
        root = np.sqrt(eps * eps + steps[0] ** 2 + steps[1] ** 2 + steps[2] ** 2)
        energy += mu * np.sum(root - eps)
        weight = mu / root
        g_n = [pairs.T @ (weight * step) for step in steps]
        # contour: the normal on the outline is its outward normal
        miss = nx[self.outline] * self.outward[:, 0] + ny[self.outline] * self.outward[:, 1] - 1.0
        energy += nu * np.sum(miss * miss)
        g_n[0][self.outline] += 2.0 * nu * miss * self.outward[:, 0]  # outline pixels are distinct
        g_n[1][self.outline] += 2.0 * nu * miss * self.outward[:, 1]
        if self.prior is not None:  # prior: w (1 - n . m)
            m, w = self.prior
            energy += np.sum(w * (1.0 - (nx * m[:, 0] + ny * m[:, 1] + nz * m[:, 2])))
            for axis in range(3):
                g_n[axis] = g_n[axis] - w * m[:, axis]
        # back through n(gx, gy) to the slopes, the depth and the basis
        cube = inverse**3
        g_x += g_n[0] * (gx * gx * cube - inverse) - g_n[1] * gx * gy * cube - g_n[2] * gx * cube
        g_y += g_n[0] * gx * gy * cube + g_n[1] * (inverse - gy * gy * cube) - g_n[2] * gy * cube
        g_z = d_col.T @ g_x + d_row.T @ g_y
        return energy, self.basis.reduce(g_z)


def _index(mask):
    """Object pixel numbers (-1 off it) and the pixels' rows and columns."""
    rows, cols = np.nonzero(mask)
    index = np.full(mask.shape, -1, dtype=np.int64)
    index[rows, cols] = np.arange(rows.size)
    return index, rows, cols


def _neighbour(index, rows, cols):
    """Pixel numbers at (rows, cols) (-1 off the object or the frame) and whether in the frame."""
    height, width = index.shape
    inside = (rows >= 0) & (rows < height) & (cols >= 0) & (cols < width)
    other = np.full(rows.size, -1, dtype=np.int64)
    other[inside] = index[rows[inside], cols[inside]]
    return other, inside


def _slope_stencil(index, rows, cols, step):
    """d/dcol (step (0, 1)) or d/drow (step (1, 0)) on the object's pixels as
    ``half * (z[ahead] - z[behind])``: central differences where both neighbours are on it,
    one-sided where one is, zero where none is (both are the pixel itself). Rows point down
    (``y = -row``), so a normal is ``(-dz/dcol, +dz/drow, 1)`` normalised.

    Returns
    -------
    ahead, behind : (n,) int64
    half : (n,) float64
    """
    forward, _ = _neighbour(index, rows + step[0], cols + step[1])
    backward, _ = _neighbour(index, rows - step[0], cols - step[1])
    me = np.arange(rows.size)
    has_f, has_b = forward >= 0, backward >= 0
    half = np.where(has_f & has_b, 0.5, 1.0)
    return np.where(has_f, forward, me), np.where(has_b, backward, me), half


def _slope_matrix(ahead, behind, half):
    """A slope stencil (:func:`_slope_stencil`) as an (n, n) sparse matrix."""
    n = ahead.size
    me = np.arange(n)
    some = ahead != behind
    i = np.r_[me[some], me[some]]
    j = np.r_[ahead[some], behind[some]]
    v = np.r_[half[some], -half[some]]
    return sp.csr_matrix((v, (i, j)), shape=(n, n))


@numba.njit(cache=True)
def _energy_kernel(
    z, values, data, light, knots, levels,
    col_ahead, col_behind, col_half, row_ahead, row_behind, row_half,
    first, second, outline, outward, weights, work, g_z,
):  # fmt: skip
    """The energy of the package's description at depth ``z`` (n,) and its gradient, written into
    ``g_z`` (n,); ``weights`` is :meth:`_Level.weights`, ``work`` (11, n) scratch space (kept by
    the caller: fresh arrays on every call cost a fifth of the time). Same terms, in the same
    order, as :meth:`_Level.energy_reference`."""
    mu, eps, nu, scale = weights[0], weights[1], weights[2], weights[3]
    n = z.size
    lx, ly, lz = light[0], light[1], light[2]
    k = knots.size
    inverse_albedo = 1.0 / levels[k - 1]
    gx, gy, inv, nx, ny, nz = work[0], work[1], work[2], work[3], work[4], work[5]
    g_x, g_y, g_nx, g_ny, g_nz = work[6], work[7], work[8], work[9], work[10]
    g_x[:], g_y[:], g_nx[:], g_ny[:], g_nz[:] = 0.0, 0.0, 0.0, 0.0, 0.0
    energy = 0.0
    # the sum of the Cauchy terms' logarithms is taken as the logarithm of their product, one
    # logarithm per 1e50 of product instead of one per pixel (a third of the kernel's time)
    product, logs = 1.0, 0.0
    for p in range(n):  # shading: Cauchy loss on (f(n . L) - I) / a
        a = col_half[p] * (z[col_ahead[p]] - z[col_behind[p]])
        b = row_half[p] * (z[row_ahead[p]] - z[row_behind[p]])
        c = 1.0 / np.sqrt(1.0 + a * a + b * b)
        gx[p], gy[p], inv[p] = a, b, c
        nx[p], ny[p], nz[p] = -a * c, b * c, c
        if not data[p]:
            continue
        shading = nx[p] * lx + ny[p] * ly + nz[p] * lz
        below = 0  # knots below shading: np.searchsorted(knots, shading)
        while below < k and knots[below] < shading:
            below += 1
        segment = min(max(below - 1, 0), k - 2)
        slope = (levels[segment + 1] - levels[segment]) / (knots[segment + 1] - knots[segment])
        if shading <= knots[0]:
            value = levels[0]
        elif shading >= knots[k - 1]:
            value = levels[k - 1]
        else:
            value = levels[segment] + slope * (shading - knots[segment])
        residual = (value - values[p]) * inverse_albedo
        ratio = residual * residual / (scale * scale)
        if ratio > 1e200:  # a product could not hold it
            logs += np.log1p(ratio)
        else:
            product *= 1.0 + ratio
            if product > 1e50:
                logs += np.log(product)
                product = 1.0
        if knots[0] < shading < knots[k - 1]:  # f is flat beyond its ends
            d = residual / (1.0 + ratio) * slope * inverse_albedo
            g_x[p] = d * (-lx * c - shading * a * c * c)
            g_y[p] = d * (ly * c - shading * b * c * c)
    energy += 0.5 * scale * scale * (logs + np.log(product))
    for e in range(first.size):  # smoothness: robust in the change of the normal
        p, q = first[e], second[e]
        sx, sy, sz = nx[q] - nx[p], ny[q] - ny[p], nz[q] - nz[p]
        root = np.sqrt(eps * eps + sx * sx + sy * sy + sz * sz)
        energy += mu * (root - eps)
        w = mu / root
        g_nx[q] += w * sx
        g_nx[p] -= w * sx
        g_ny[q] += w * sy
        g_ny[p] -= w * sy
        g_nz[q] += w * sz
        g_nz[p] -= w * sz
    for i in range(outline.size):  # contour: the normal on the outline is its outward normal
        o = outline[i]
        miss = nx[o] * outward[i, 0] + ny[o] * outward[i, 1] - 1.0
        energy += nu * miss * miss
        g_nx[o] += 2.0 * nu * miss * outward[i, 0]
        g_ny[o] += 2.0 * nu * miss * outward[i, 1]
    for p in range(n):  # back through n(gx, gy) to the slopes and the depth
        a, b, c = gx[p], gy[p], inv[p]
        cube = c * c * c
        g_x[p] += g_nx[p] * (a * a * cube - c) - g_ny[p] * a * b * cube - g_nz[p] * a * cube
        g_y[p] += g_nx[p] * a * b * cube + g_ny[p] * (c - b * b * cube) - g_nz[p] * b * cube
    g_z[:] = 0.0
    for p in range(n):
        g_z[col_ahead[p]] += col_half[p] * g_x[p]
        g_z[col_behind[p]] -= col_half[p] * g_x[p]
        g_z[row_ahead[p]] += row_half[p] * g_y[p]
        g_z[row_behind[p]] -= row_half[p] * g_y[p]
    return energy
