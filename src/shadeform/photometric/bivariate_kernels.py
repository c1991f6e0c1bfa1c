"""The bivariate fit's compiled kernels (:mod:`shadeform.photometric.bivariate`'s description):
the model's basis and non-negative fit at one normal, the Gauss-Newton step, each pixel's
re-weighted search in parallel over the pixels, and the residuals the slant search compares.
Each is tested against its reference in :mod:`.bivariate_model`.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import prange

from shadeform.photometric.bivariate_model import (
    HALVINGS,
    LOBES,
    POWERS,
    RIDGE,
    ROUNDS,
    STEPS,
    STOP,
    TUKEY,
    TURN,
)


@numba.njit(cache=True, inline="always")
def _basis_kernel(n0, n1, n2, lights, half, j, basis):
    c = n0 * lights[j, 0] + n1 * lights[j, 1] + n2 * lights[j, 2]
    if c <= 0.0:
        return False
    h = max(0.0, n0 * half[j, 0] + n1 * half[j, 1] + n2 * half[j, 2])
    basis[0] = c - 0.5 * c * c
    basis[1] = 0.5 * c * c
    for m in range(LOBES):
        h = h * h
        h = h * h  # h^(4^(m+1))
        basis[POWERS + m] = c * h
    return True


@numba.njit(cache=True)
def _model_fit(n0, n1, n2, lights, half, values, weights, work):
    """The kernel of :func:`model_fit_reference`: the weighted residual sum; the coefficients in
    ``work[3, :size]`` (``work`` is (6, size^2) scratch space: the system, its right-hand side,
    one reading's basis, the coefficients, and the active set's own)."""
    size = POWERS + LOBES
    system = work[0, : size * size].reshape(size, size)
    moment, basis, coefficients = work[1, :size], work[2, :size], work[3, :size]
    system[:, :] = 0.0
    moment[:] = 0.0
    total = 0.0
    for j in range(values.size):
        w = weights[j]
        if w == 0.0:
            continue
        total += w * values[j] * values[j]
        if not _basis_kernel(n0, n1, n2, lights, half, j, basis):
            continue
        for a in range(size):
            moment[a] += w * values[j] * basis[a]
            wa = w * basis[a]
            for b in range(a + 1):
                system[a, b] += wa * basis[b]
    for a in range(size):
        system[a, a] += (RIDGE if a >= POWERS else 0.0) + 1e-12
        for b in range(a):
            system[b, a] = system[a, b]
    _nonnegative_solve(
        system, moment, coefficients, basis, work[4, : size * size].reshape(size, size), work[5, :size]
    )
    # sum w I^2 - 2 x . b + x . A x
    residual = total
    for a in range(size):
        residual -= 2.0 * coefficients[a] * moment[a]
        for b in range(size):
            residual += coefficients[a] * system[a, b] * coefficients[b]
    return residual


@numba.njit(cache=True)
def _nonnegative_solve(system, rhs, x, scratch, sub, z):
    """``x >= 0`` minimising ``x . A x / 2 - b . x`` for a small symmetric positive definite ``A``
    (``system``, kept) by Lawson and Hanson's active set; ``scratch`` (size,), ``sub`` (size,
    size) and ``z`` (size,) are work space."""
    size = rhs.size
    passive = np.zeros(size, dtype=np.bool_)
    x[:] = 0.0
    for _ in range(3 * size):
        # the most promising variable held at zero: the largest gradient b - A x
        best, enter = 1e-14, -1
        for a in range(size):
            if passive[a]:
                continue
            gradient = rhs[a]
            for b in range(size):
                gradient -= system[a, b] * x[b]
            if gradient > best:
                best, enter = gradient, a
        if enter < 0:
            return
        passive[enter] = True
        for _inner in range(size):
            # the unconstrained minimum over the passive variables
            k = 0
            for a in range(size):
                if passive[a]:
                    scratch[k] = rhs[a]
                    m = 0
                    for b in range(size):
                        if passive[b]:
                            sub[k, m] = system[a, b]
                            m += 1
                    k += 1
            _cholesky_solve(sub[:k, :k], scratch[:k], z[:k])
            step, k = 1.0, 0
            for a in range(size):
                if passive[a]:
                    if z[k] <= 0.0:
                        step = min(step, x[a] / (x[a] - z[k]))
                    k += 1
            k = 0
            for a in range(size):
                if passive[a]:
                    x[a] += step * (z[k] - x[a])
                    k += 1
            if step >= 1.0:
                break
            for a in range(size):  # variables the step brought to zero leave
                if passive[a] and x[a] <= 1e-15:
                    passive[a] = False
                    x[a] = 0.0


@numba.njit(cache=True)
def _cholesky_solve(system, rhs, out):
    """Solve ``system @ out = rhs`` for a small symmetric positive definite ``system`` given by its
    lower triangle (overwritten by its Cholesky factor)."""
    size = rhs.size
    for i in range(size):
        for j in range(i + 1):
            s = system[i, j]
            for k in range(j):
                s -= system[i, k] * system[j, k]
            if i == j:
                system[i, i] = np.sqrt(max(s, 1e-300))
            else:
                system[i, j] = s / system[j, j]
    for i in range(size):
        s = rhs[i]
        for k in range(i):
            s -= system[i, k] * out[k]
        out[i] = s / system[i, i]
    for i in range(size - 1, -1, -1):
        s = out[i]
        for k in range(i + 1, size):
            s -= system[k, i] * out[k]
        out[i] = s / system[i, i]


@numba.njit(cache=True)
def _tangents(n0, n1, n2):
    """Two unit vectors spanning the plane perpendicular to the unit ``n``."""
    if abs(n0) < 0.9:  # n x (1, 0, 0)
        a0, a1, a2 = 0.0, n2, -n1
    else:  # n x (0, 1, 0)
        a0, a1, a2 = -n2, 0.0, n0
    length = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    a0, a1, a2 = a0 / length, a1 / length, a2 / length
    return a0, a1, a2, n1 * a2 - n2 * a1, n2 * a0 - n0 * a2, n0 * a1 - n1 * a0


@numba.njit(cache=True)
def _search_pixel(n, lights, half, values, weights, residuals, lit, work):
    """One pixel's re-weighted Gauss-Newton search from the unit normal ``n`` (3,), in place;
    returns ``f(1)``. ``weights`` ends as the final round's; ``work`` is (10, :data:`_WORK`)."""
    size = POWERS + LOBES
    basis, coefficients, kept = work[2, :size], work[3, :size], work[6, :size]
    weights[:] = 1.0
    n0, n1, n2 = n[0], n[1], n[2]
    for _round in range(ROUNDS):
        # Tukey's weights of the current fit's residuals
        _model_fit(n0, n1, n2, lights, half, values, weights, work)
        count = 0  # the residuals' scale from the readings the normal says are lit
        for j in range(values.size):
            predicted = 0.0
            if _basis_kernel(n0, n1, n2, lights, half, j, basis):
                for a in range(size):
                    predicted += coefficients[a] * basis[a]
                lit[count] = abs(values[j] - predicted)
                count += 1
            residuals[j] = abs(values[j] - predicted)
        scale = TUKEY * 1.4826 * (np.median(lit[:count]) if count else np.median(residuals)) + 1e-12
        for j in range(values.size):
            u = residuals[j] / scale
            weights[j] = (1.0 - u * u) ** 2 if u < 1.0 else 0.0
        best = _model_fit(n0, n1, n2, lights, half, values, weights, work)
        kept[:] = coefficients
        for _step in range(STEPS):
            t0, t1, t2, s0, s1, s2 = _tangents(n0, n1, n2)
            du, dv = _step_kernel(
                n0, n1, n2, t0, t1, t2, s0, s1, s2, lights, half, values, weights, kept, work
            )
            length = np.sqrt(du * du + dv * dv)
            if length > TURN:
                du, dv, length = du * TURN / length, dv * TURN / length, TURN
            improved = False
            for _halving in range(HALVINGS):
                m0, m1, m2 = n0 + du * t0 + dv * s0, n1 + du * t1 + dv * s1, n2 + du * t2 + dv * s2
                norm = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
                m0, m1, m2 = m0 / norm, m1 / norm, m2 / norm
                cost = _model_fit(m0, m1, m2, lights, half, values, weights, work)
                if cost < best:
                    best, n0, n1, n2, improved = cost, m0, m1, m2, True
                    kept[:] = coefficients
                    break
                du, dv, length = 0.5 * du, 0.5 * dv, 0.5 * length
            if not improved or length < STOP:
                break
    _model_fit(n0, n1, n2, lights, half, values, weights, work)
    n[0], n[1], n[2] = n0, n1, n2
    return 0.5 * (coefficients[0] + coefficients[1])  # f(1)


@numba.njit(cache=True)
def _step_kernel(n0, n1, n2, t0, t1, t2, s0, s1, s2, lights, half, values, weights, coefficients, work):
    """The kernel of :func:`_step_reference`: the Gauss-Newton step ``(du, dv)`` of the unit
    normal along the tangents ``t`` and ``s``, from the weighted normal equations of the model
    linearised in the normal and its non-zero ``coefficients`` together; ``work`` rows 7-9 are
    its scratch space."""
    size = POWERS + LOBES
    dim = size + 2
    system = work[7, : dim * dim].reshape(dim, dim)
    rhs, column, solution = work[8, :dim], work[9, :dim], work[9, dim : 2 * dim]
    system[:, :] = 0.0
    rhs[:] = 0.0
    for j in range(values.size):
        w = weights[j]
        if w == 0.0 or not _basis_kernel(n0, n1, n2, lights, half, j, column):
            continue
        c = n0 * lights[j, 0] + n1 * lights[j, 1] + n2 * lights[j, 2]
        h = max(0.0, n0 * half[j, 0] + n1 * half[j, 1] + n2 * half[j, 2])
        # the prediction's gradient in n: a multiple of the light plus one of the half vector
        along_light = coefficients[0] * (1.0 - c) + coefficients[1] * c
        along_half, exponent = 0.0, 1.0
        for m in range(LOBES):
            exponent *= 4.0
            along_light += coefficients[POWERS + m] * column[POWERS + m] / c  # h^e
            if h > 0.0:
                along_half += coefficients[POWERS + m] * exponent * column[POWERS + m] / h  # c e h^(e-1)
        g0 = along_light * lights[j, 0] + along_half * half[j, 0]
        g1 = along_light * lights[j, 1] + along_half * half[j, 1]
        g2 = along_light * lights[j, 2] + along_half * half[j, 2]
        column[size] = g0 * t0 + g1 * t1 + g2 * t2
        column[size + 1] = g0 * s0 + g1 * s1 + g2 * s2
        residual = values[j]
        for a in range(size):
            residual -= coefficients[a] * column[a]
        for a in range(dim):
            if a < size and coefficients[a] <= 0.0:
                continue  # coefficients at zero stay there
            rhs[a] += w * residual * column[a]
            wa = w * column[a]
            for b in range(a + 1):
                if b >= size or coefficients[b] > 0.0:
                    system[a, b] += wa * column[b]
    for a in range(size):
        if coefficients[a] <= 0.0:  # a fixed coefficient: its row says "no change"
            system[a, a], rhs[a] = 1.0, 0.0
        else:
            ridge = (RIDGE if a >= POWERS else 0.0) + 1e-12
            system[a, a] += ridge
            rhs[a] -= ridge * coefficients[a]
    system[size, size] += 1e-12
    system[size + 1, size + 1] += 1e-12
    _cholesky_solve(system, rhs, solution)
    return solution[size], solution[size + 1]


#: Scratch space per row of a pixel's ``work`` (the Gauss-Newton system's entries).
_WORK = (POWERS + LOBES + 2) ** 2


#: Pixels a thread takes at once in :func:`_refine_kernel`.
_BLOCK = 256


@numba.njit(cache=True, parallel=True)
def _refine_kernel(normals, readings, lights, half, brightness, weights):
    """:func:`_search_pixel` over the pixels (columns of ``readings``), each independent of the
    others (the result does not depend on the number of threads)."""
    count, pixels = readings.shape
    blocks = (pixels + _BLOCK - 1) // _BLOCK
    for block in prange(blocks):
        # scratch space once per block of pixels, not once per pixel
        work = np.empty((10, _WORK))
        residuals, lit, values, column = np.empty(count), np.empty(count), np.empty(count), np.empty(count)
        n = np.empty(3)
        for p in range(block * _BLOCK, min(pixels, (block + 1) * _BLOCK)):
            values[:] = readings[:, p]
            n[:] = normals[p]
            brightness[p] = _search_pixel(n, lights, half, values, column, residuals, lit, work)
            normals[p] = n
            weights[:, p] = column


def _refine(start, readings, lights, half):
    """Normals (P, 3), ``f(1)`` (P,) and final weights (N, P) from unit ``start`` normals."""
    normals = np.ascontiguousarray(start, dtype=np.float64).copy()
    brightness = np.empty(len(normals))
    weights = np.empty(readings.shape)
    _refine_kernel(
        normals, readings, np.ascontiguousarray(lights, dtype=np.float64), half, brightness, weights
    )
    return normals, brightness, weights


@numba.njit(cache=True, parallel=True)
def _costs(normals, readings, lights, half):
    """Per pixel (columns of ``readings``), the model's unweighted residual sum at its unit normal
    (P,): every reading counted, unlit ones as predicted dark."""
    count, pixels = readings.shape
    size = POWERS + LOBES
    out = np.empty(pixels)
    blocks = (pixels + _BLOCK - 1) // _BLOCK
    for block in prange(blocks):
        work = np.empty((6, size * size))
        values, weights = np.empty(count), np.ones(count)
        for p in range(block * _BLOCK, min(pixels, (block + 1) * _BLOCK)):
            values[:] = readings[:, p]
            out[p] = _model_fit(
                normals[p, 0], normals[p, 1], normals[p, 2], lights, half, values, weights, work
            )
    return out
