"""A slant error common to the given lights, read from the gloss and the falloff the bivariate
model explains (:func:`slant_scale`; :mod:`shadeform.photometric.bivariate`).
"""

from __future__ import annotations

import numpy as np

from shadeform.photometric import lambertian
from shadeform.photometric.bivariate_kernels import _costs, _refine
from shadeform.photometric.bivariate_model import LOBES, POWERS, READINGS_PER_UNKNOWN

#: The lights' slant refinement (:func:`slant_scale`) searches scales of ``tan(slant)`` within
#: this factor either way: a calibration off by more is not a small error to refine. A bound on
#: the search, not swept; a minimum on it means the photos cannot tell, and the given lights stay.
SLANT_BOUND = 1.25
#: Degrees: the lights' slants must spread by this much (standard deviation) for a common slant
#: error to be looked for. With every light at one slant the error is only a uniform change of
#: strength, which the albedo absorbs: the photos say nothing about it, and the search would read
#: the noise (a ring of 12 lights at 45 degrees gave 0.85). Half the spread of DiLiGenT's dome
#: (9.7); not swept.
SLANT_SPREAD = 5.0
#: Standard deviations by which the pixels a refined slant explains better must outnumber half
#: of them (one-sided p = 0.0005): the usual significance of a sign test.
SIGN_TEST = 3.29
#: The search stops when the bracket of ``log`` scale is narrower than this (a 1 % slant scale).
SLANT_TOLERANCE = 0.01


def slant_scale(lights, readings, start):
    """The scale of the lights' ``tan(slant)`` that the model explains the readings best with: 1
    where the photos cannot tell.

    A chrome sphere whose outline is read a little too large or small gives every light's slant
    too small or large by nearly one factor; so does a dome whose lamps sit higher or lower than
    its drawing says. A Lambertian surface cannot reveal it: the normals tilt to match (the
    depth scale of the bas-relief ambiguity, ``g -> diag(s, s, 1) g``). Gloss and the falloff
    can: a highlight sits where the normal meets a half vector, which tilts the other way. So
    the scale is the one whose per-pixel fits (:func:`_refine`, from the Lambertian ``start``
    turned by the ambiguity) leave the least median residual, a golden-section search on its
    logarithm within :data:`SLANT_BOUND`; a pixel lit too rarely for the model
    (:data:`READINGS_PER_UNKNOWN`) is judged by the Lambertian fit the fit itself keeps there
    (where the lights' strengths are known, a wrong slant leaves it a residual too). It gives 1 where the photos cannot tell: lights all at
    nearly one slant (:data:`SLANT_SPREAD`), a minimum on the bound, or a scale that explains
    no more pixels better than chance would (a sign test, :data:`SIGN_TEST`).

    Parameters
    ----------
    lights : (N, 3) float64
        The given unit lights.
    readings : (N, P) float64
        A sample of the object's readings, divided by the lights' strengths.
    start : (P, 3) float64
        The robust Lambertian ``g`` of those pixels with the given lights (finite, non-zero).

    References
    ----------
    .. [1] P. N. Belhumeur, D. J. Kriegman, A. L. Yuille, "The bas-relief ambiguity", IJCV 35(1),
       1999.
    .. [2] O. Drbohlav, R. Sara, "Specularities reduce ambiguity of uncalibrated photometric
       stereo", ECCV 2002.
    """
    if np.std(np.degrees(np.arccos(np.clip(lights[:, 2], -1.0, 1.0)))) < SLANT_SPREAD:
        return 1.0
    albedo = np.linalg.norm(start, axis=1)
    # each pixel judged by the model the fit gives it (:func:`fit`): this one where it is lit
    # often enough, the Lambertian one where it is lit in more photos than g has unknowns
    lit = (lights @ (start / albedo[:, None]).T > 0) & (readings > 0)
    count = lit.sum(axis=0)
    modelled = count >= READINGS_PER_UNKNOWN * (POWERS + LOBES + 2)
    plain = ~modelled & (count > 3)
    if np.count_nonzero(modelled | plain) <= SIGN_TEST**2:
        return 1.0  # too few for the sign test below ever to pass
    albedo = np.concatenate([albedo[modelled], albedo[plain]])
    model_start = start[modelled]
    model_readings = np.ascontiguousarray(readings[:, modelled], dtype=np.float64)
    plain_readings, plain_lit = readings[:, plain], lit[:, plain].astype(np.float64)

    def costs(log_scale):
        scale = np.exp(log_scale)
        tilted = lambertian.scaled_lights(lights, scale)
        normals = model_start / np.array([scale, scale, 1.0])  # the ambiguity's normals for these lights
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        half = lambertian.half_vectors(tilted)
        normals, _, _ = _refine(normals, model_readings, tilted, half)
        g = np.nan_to_num(lambertian.fit(tilted, plain_readings, plain_lit)[0])
        residuals = plain_readings - np.maximum(tilted @ g.T, 0.0)  # every reading, unlit as dark
        both = np.concatenate([_costs(normals, model_readings, tilted, half), np.sum(residuals**2, axis=0)])
        return both / albedo**2

    def loss(log_scale):
        return float(np.median(costs(log_scale)))

    low, high = -np.log(SLANT_BOUND), np.log(SLANT_BOUND)
    golden = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = high - golden * (high - low), low + golden * (high - low)
    loss_a, loss_b = loss(a), loss(b)
    while high - low > SLANT_TOLERANCE:
        if loss_a < loss_b:
            high, b, loss_b = b, a, loss_a
            a = high - golden * (high - low)
            loss_a = loss(a)
        else:
            low, a, loss_a = a, b, loss_b
            b = low + golden * (high - low)
            loss_b = loss(b)
    found = (low + high) / 2.0
    if np.log(SLANT_BOUND) - abs(found) < SLANT_TOLERANCE:
        return 1.0
    # a sign test: more pixels must be explained better than chance would give (one-sided
    # p = 0.0005), or the scale found only rode the noise along the ambiguity
    better = np.count_nonzero(costs(found) < costs(0.0) * (1.0 - 1e-9))
    if better <= albedo.size / 2 + SIGN_TEST * np.sqrt(albedo.size) / 2:
        return 1.0
    return float(np.exp(found))
