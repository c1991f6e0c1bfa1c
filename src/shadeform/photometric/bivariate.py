"""Photometric stereo with a low-frequency reflectance model: shadows, gloss and non-Lambertian
falloff, fitted per pixel.

Real paints and glazes are not Lambertian: their brightness falls off with ``n . l`` more steeply
or more gently than the cosine, and gloss adds a lobe round the mirror direction, broad on a
metallic paint (DiLiGenT's ``cow``) and sharp on a glaze (``ball``). A Lambertian fit reads both as
shape, however carefully it leaves highlights out. Here each pixel's readings are explained by

    I_j = a (c_j - c_j^2 / 2) + b c_j^2 / 2  +  c_j sum_m s_m h_j^(4^m)
          (c_j = max(0, n . l_j), h_j = n . h_j, m = 1 .. LOBES)

with every coefficient non-negative: the diffuse part is then exactly a quadratic in ``c``
through 0 that does not decrease toward the light (Lambert's cosine and the lowest-order
correction of its falloff), and the gloss only adds light, in lobes round the half vector
``h_j = (l_j + v) / |l_j + v|`` (``v = +z``) each four times narrower than the last (half-widths
of about 34, 17 and 8 degrees: the narrowest near the spacing of a dense light dome). For a
given normal the coefficients are a five-unknown non-negative least squares (Lawson and
Hanson's active set on the normal equations); the normal is the one whose fit leaves the least
weighted residual, found from the robust Lambertian normal by Gauss-Newton steps in its tangent
plane, each from the model linearised in the normal and the non-zero coefficients together (the
variable-projection step of Golub and Pereyra) and halved until the fit improves. Readings the model cannot explain
(cast shadows on a lit surface, interreflections, a highlight sharper than the narrowest lobe)
are weighted down by Tukey's biweight of the residual over the median absolute deviation of the
lit readings' residuals (the textbook 4.685 scale), re-weighted :data:`ROUNDS` times. Readings
the normal puts in shadow count as predicted dark.

The same model checks the given lights for a slant error common to all of them (a chrome sphere
read slightly too large or small), which a Lambertian fit cannot see: :func:`slant_scale`.

Modules: this one (:func:`fit`), :mod:`.bivariate_model` (the model's constants and its slow,
plain-numpy references), :mod:`.bivariate_kernels` (the compiled per-pixel search, tested against
them) and :mod:`.bivariate_slant` (:func:`slant_scale`).

This is a classical bivariate reflectance fit in the family the DiLiGenT benchmark ranks best
among non-learned methods (Shi et al. 2014, Ikehata and Aizawa 2014); the basis here is its own.
Measured on the seven real DiLiGenT objects: ``benchmarks/results/stereo.md``. The basis was
compared on ``ball``, ``cow`` and ``cat`` before the sign constraints (powers 1-3 of ``c`` with
three lobes, two to four lobes with one power): one power loses the ball's falloff (16-bit ball
2.01 against 1.74 degrees), three let the normal trade with the falloff (cow 13.5 against 8.7).
The constraints then took the seven objects' mean from 8.41 to 7.74 degrees (cow 9.34 -> 7.95,
pot1 8.77 -> 7.84; the ball alone lost, 8-bit crop 2.07 -> 2.45, 16-bit 1.75 -> 1.79).

References
----------
.. [1] B. Shi, P. Tan, Y. Matsushita, K. Ikeuchi, "Bi-polynomial modeling of low-frequency
   reflectances", IEEE TPAMI 36(6), 2014.
.. [2] S. Ikehata, K. Aizawa, "Photometric stereo using constrained bivariate regression for
   general isotropic surfaces", CVPR 2014.
.. [3] B. Shi et al., "A benchmark dataset and evaluation for non-Lambertian and uncalibrated
   photometric stereo", IEEE TPAMI 41(2), 2019.
.. [4] P. N. Belhumeur, D. J. Kriegman, A. L. Yuille, "The bas-relief ambiguity", IJCV 35(1),
   1999.
.. [5] G. Golub, V. Pereyra, "Separable nonlinear least squares: the variable projection method
   and its applications", Inverse Problems 19(2), 2003.
"""

from __future__ import annotations

import numpy as np

from shadeform.photometric import lambertian
from shadeform.photometric.bivariate_kernels import _refine
from shadeform.photometric.bivariate_model import (
    HALVINGS,
    LOBES,
    POWERS,
    READINGS_PER_UNKNOWN,
    RIDGE,
    ROUNDS,
    STEPS,
    STOP,
    TUKEY,
    TURN,
    model_fit_reference,
    search_reference,
    slope_reference,
)
from shadeform.photometric.bivariate_slant import (
    SIGN_TEST,
    SLANT_BOUND,
    SLANT_SPREAD,
    SLANT_TOLERANCE,
    slant_scale,
)

__all__ = [
    "HALVINGS",
    "LOBES",
    "POWERS",
    "READINGS_PER_UNKNOWN",
    "RIDGE",
    "ROUNDS",
    "SIGN_TEST",
    "SLANT_BOUND",
    "SLANT_SPREAD",
    "SLANT_TOLERANCE",
    "STEPS",
    "STOP",
    "TUKEY",
    "TURN",
    "fit",
    "model_fit_reference",
    "search_reference",
    "slant_scale",
    "slope_reference",
]


def fit(lights, readings, *, min_shading, highlight_cos, iterations):
    """Per pixel ``g = f(1) n`` (P, 3), ``f(1)`` the diffuse brightness facing the light, and
    the readings the final fit counted (N, P): lit and not weighted out. Pixels the robust
    Lambertian start cannot solve stay NaN; those with too few lit readings for the model
    (:data:`READINGS_PER_UNKNOWN`) keep the start.

    Parameters
    ----------
    lights : (N, 3) float64
        Unit directions toward the lights.
    readings : (N, P) float64
        Each pixel's readings, divided by the lights' strengths.
    min_shading, highlight_cos, iterations
        The robust Lambertian start's options (:func:`shadeform.photometric.lambertian.robust`).
    """
    g, usable = lambertian.robust(
        lights, readings, min_shading=min_shading, highlight_cos=highlight_cos, iterations=iterations
    )
    solved = np.isfinite(g[:, 0]) & (np.linalg.norm(g, axis=1) > 0)
    start = np.zeros_like(g)
    start[solved] = g[solved] / np.linalg.norm(g[solved], axis=1, keepdims=True)
    lit = (lights @ start.T > 0) & (readings > 0)
    modelled = solved & (lit.sum(axis=0) >= READINGS_PER_UNKNOWN * (POWERS + LOBES + 2))
    normals, brightness, weights = _refine(
        start[modelled], np.ascontiguousarray(readings[:, modelled]), lights, lambertian.half_vectors(lights)
    )
    result = g.copy()  # where the model is not fitted: the robust Lambertian g
    # a fit whose diffuse part is not positive keeps the Lambertian albedo
    albedo = np.where(brightness > 0, brightness, np.linalg.norm(g[modelled], axis=1))
    result[modelled] = normals * albedo[:, None]
    usable[:, modelled] = (weights > 0) & (lights @ normals.T > 0)
    return result, usable
