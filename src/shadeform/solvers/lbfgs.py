"""L-BFGS without bounds, for the photo solver's energy over depth (and any smooth energy).

:func:`descend` takes the steps; :func:`two_loop` is its compiled two-loop recursion (Nocedal
1980), which ``tests/test_photo.py`` holds to the textbook's.

References
----------
.. [1] J. Nocedal, "Updating quasi-Newton matrices with limited storage", Mathematics of
   Computation 35(151), 773-782, 1980.
.. [2] J. Nocedal and S. J. Wright, "Numerical optimization", 2nd ed., Springer, 2006, ch. 7.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["ARMIJO", "MEMORY", "descend", "two_loop"]

#: Curvature pairs L-BFGS keeps (the textbook value; Nocedal & Wright suggest 3 to 20).
MEMORY = 10
#: Armijo's sufficient decrease: a step must lower the energy by this share of what the slope
#: promises (the textbook value).
ARMIJO = 1e-4


def descend(energy, start, *, iterations):
    """Minimise ``energy(x) -> (value, gradient)`` from ``start`` by L-BFGS: ``iterations``
    steps, each along the two-loop direction of the last :data:`MEMORY` steps (Nocedal 1980),
    its length found by backtracking from 1 (the first step moves by at most 1 pixel) until
    Armijo's condition holds.

    Plain L-BFGS, because the problem has no bounds: SciPy's L-BFGS-B spends 26 ms per
    iteration on its bound machinery at 0.4 M unknowns, against 9-11 ms here for the whole
    step outside the energy (a diagonal quadratic of 0.4 M unknowns, 50 steps, one thread). A
    step whose curvature ``s . y`` is not positive (the energy is not convex) is not
    remembered; a direction that does not descend restarts from the gradient.

    Returns
    -------
    x : (N,) float64
    steps : int
        Steps taken (fewer than ``iterations`` where no step lowers the energy).
    """
    x = np.array(start, dtype=np.float64)
    value, gradient = energy(x)
    # the remembered pairs (s, y) in the rows of two arrays (one row spare for the next pair),
    # and their rows oldest first
    steps_s, steps_y = np.empty((2, MEMORY + 1, x.size))
    rho = np.empty(MEMORY + 1)
    order = []
    direction = np.empty(x.size)
    for step_number in range(iterations):
        two_loop(gradient, steps_s, steps_y, rho, np.array(order, dtype=np.int64), direction)
        np.negative(direction, out=direction)
        slope = float(gradient @ direction)
        if slope >= 0.0:
            order.clear()
            np.negative(gradient, out=direction)
            slope = -float(gradient @ gradient)
        if slope == 0.0:
            return x, step_number
        length = 1.0 if order else min(1.0, 1.0 / np.sqrt(-slope))
        for _ in range(30):
            trial = x + length * direction
            trial_value, trial_gradient = energy(trial)
            if trial_value <= value + ARMIJO * length * slope:
                break
            # the minimum of the parabola through the value, the slope and the trial, kept
            # within a tenth and a half of the step
            bend = trial_value - value - slope * length
            length *= min(0.5, max(0.1, -slope * length / (2.0 * bend)))
        else:
            return x, step_number
        row = min(set(range(MEMORY + 1)) - set(order))
        np.subtract(trial, x, out=steps_s[row])
        np.subtract(trial_gradient, gradient, out=steps_y[row])
        curvature = float(steps_s[row] @ steps_y[row])
        if curvature > 1e-12 * float(steps_y[row] @ steps_y[row]):
            rho[row] = 1.0 / curvature
            order = (order + [row])[-MEMORY:]
        x, value, gradient = trial, trial_value, trial_gradient
    return x, iterations


@numba.njit(cache=True)
def two_loop(gradient, steps_s, steps_y, rho, order, q):
    """The L-BFGS product of the inverse Hessian's estimate with ``gradient`` (Nocedal and
    Wright, Algorithm 7.4) into ``q``, scaled by the newest pair's ``s . y / y . y``; the pairs
    are the rows ``order`` (oldest first) of ``steps_s`` and ``steps_y``, ``rho = 1 / s . y``.
    Each pass over memory updates ``q`` and takes the next pair's product with it at once: at a
    few hundred thousand unknowns the pairs fill more than the cache, and this loop, not the
    arithmetic, is what costs."""
    m, n = order.size, q.size
    q[:] = gradient
    if m == 0:
        return
    alphas = np.empty(m)
    dot = 0.0
    newest = order[m - 1]
    for p in range(n):
        dot += steps_s[newest, p] * q[p]
    for j in range(m - 1, -1, -1):
        i = order[j]
        alphas[j] = rho[i] * dot
        dot = 0.0
        if j > 0:
            below = order[j - 1]
            for p in range(n):
                q[p] -= alphas[j] * steps_y[i, p]
                dot += steps_s[below, p] * q[p]
        else:
            for p in range(n):
                q[p] -= alphas[j] * steps_y[i, p]
    yy = 0.0
    for p in range(n):
        yy += steps_y[newest, p] * steps_y[newest, p]
    scale = 1.0 / (rho[newest] * yy)
    dot = 0.0
    oldest = order[0]
    for p in range(n):
        q[p] *= scale
        dot += steps_y[oldest, p] * q[p]
    for j in range(m):
        i = order[j]
        step = alphas[j] - rho[i] * dot
        dot = 0.0
        if j < m - 1:
            above = order[j + 1]
            for p in range(n):
                q[p] += step * steps_s[i, p]
                dot += steps_y[above, p] * q[p]
        else:
            for p in range(n):
                q[p] += step * steps_s[i, p]
