"""DiLiGenT normal-integration benchmark: bilateral vs BiNI vs uniform least squares (perspective).

For each object of ``../shared/data/diligent-normals`` (ground-truth normals, 3x3 ``K``,
ground-truth depth in mm) integrates the normals with
:func:`shadeform.integration.bilateral.integrate_bilateral` (``sharpness = 2``, BiNI's ``k``)
under its default slope cap (the geometric rule of
:func:`shadeform.integration.bilateral.contour_scale`) and under the constant cap it replaced
(``min_scale=0.12``, tuned on these six objects), with the uniform least-squares solution of the
same log-depth equations (``iterations=0``) and with a re-run of BiNI's published algorithm
(:func:`bini_rerun`, a plain scipy re-implementation written from the paper, as its evaluation
runs it), and reports MADE in mm and wall times.

Besides the objects as published, every method sees perturbed variants of each
(:func:`variant`): Gaussian noise on the normals (2 degrees RMS, seeded), 2x downsampling
(normals averaged over 2x2 blocks, mask and ground truth likewise, ``K`` scaled), the mask
eroded by 3 pixels, and a window (the middle 60 % of the bounding box's rows and columns); and
a second, held-out set of perturbations that no choice of the integrator was made on
(``EXTRA_VARIANTS``: two more noise seeds, windows of 50 % and 70 %, the 2x2 blocks shifted by
one pixel). For the cases where the integrator is behind the re-run it reports the figure at
0.9 and 1.1 times the floor, and for the objects as published the jumps of the ground truth
across interior occluding contours against the capped step (:func:`contour_jumps`).

MADE is measured under two ways of fitting the unknown scale (:func:`shadeform.metrics.made`):
``median_scale`` (the median of the depth ratios, the protocol of BiNI's DiLiGenT evaluation script
and so of its published figures; the bar is judged under it) and ``scale`` (least squares).
Writes ``benchmarks/results/diligent.md``.

Run: ``python benchmarks/bench_diligent.py [--repeats N] [--no-sweep] [--no-rerun] [--no-variants]
[--no-extra]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from functools import partial
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy import ndimage

from shadeform.integration.bilateral import contour_scale, integrate_bilateral
from shadeform.io.atomic import atomic_write
from shadeform.io.images import load_mask
from shadeform.io.maps import load_normal_map
from shadeform.metrics import made

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "diligent-normals"
OBJECTS = ("bear", "buddha", "cat", "cow", "pot1", "reading")
#: The constant slope cap the geometric rule replaced (``MIN_SCALE``), kept for comparison.
OLD_MIN_SCALE = 0.12
#: Perturbed variants of every object (:func:`variant`).
VARIANTS = ("original", "noise", "down2", "eroded", "window")
#: Held-out perturbations (issue 12): added after the rule and every candidate of its follow-up
#: had been judged on ``VARIANTS``, to see which of them carry over to cases not looked at.
EXTRA_VARIANTS = ("noise-s1", "noise-s2", "window50", "window70", "down2-shift")
#: Why the old ``MIN_SCALE`` was what it was (it moved here from the integrator's docstring).
MIN_SCALE_NOTE = (
    "How the old constant `MIN_SCALE = 0.12` was chosen: the result is sensitive to it; 0.1 favours buddha, 0.15 bear, cat and "
    "pot1, and 0.12 is the compromise at or below BiNI's published MADE on all six objects. Without the "
    "clamp these are BiNI's own equations, and their IRLS fixed point (each step solved exactly) is worse "
    "than BiNI's published figures on four of the six objects; BiNI's loose CG (Jacobi, 1e-3 per step) "
    "stops short of that point. The errors left sit in the offsets of whole parts across occluding "
    "contours (bear's head against its body, reading's book), which the normals there, nearly grazing, "
    "barely determine. Chosen on these six objects only."
)
#: How the geometric rule replaced it (issue 12); the figures are in the tables above it.
RULE_NOTE = (
    "Issue 12 replaced the constant by a geometric rule (`contour_scale`): the floor is the mean "
    "n_z of a smooth body's outermost pixel centres, which lie anywhere from 0 to 1 pixel inside "
    "its silhouette of radius R pixels: the mean of sqrt(1 - (1 - t/R)^2) over t uniform in (0, 1), "
    "~ (2/3) sqrt(2/R), with R the largest inscribed radius of the mask's part (its largest "
    "distance to the silhouette). Across an occluding contour inside the mask nothing but the "
    "occluder's last, nearly grazing normals ties the two surfaces, so the gap the solution leaves "
    "there is about the capped slope times one pixel. No constant of it was fitted, but it was "
    "picked among candidates after looking at the six objects, so the choice is not blind to them. "
    "First round (objects as published): (1) a per-pixel floor equal to the normal's angle to its "
    "neighbours: bear 0.04-0.58, buddha 1.99-2.52, cow 0.16-0.26, reading 0.41-0.85, far behind, "
    "since it caps the steep but honest normals of folds and creases; (2) R from the mask's area "
    "(equivalent disc): bear 0.357, cat 0.083, behind; (3) the one-pixel chord from the rim, "
    "1/sqrt(2R): bear 0.376, cat 0.088, behind; (4) a floor read from the outer rim's own normals, "
    "not pursued (their median d is 0.25-0.42, where the sweep above shows buddha and pot1 "
    "degrading); (5) n_z at the median position, half a pixel inside the rim, "
    "sqrt(1 - (1 - 1/(2R))^2) ~ 1/sqrt(R) (6 % above the mean), kept at first. Second round, "
    "judged on all 30 cases against the BiNI re-run (cases at or below it; mean of the ratios "
    "rule / re-run): the median position (5) 21 of 30, mean ratio 0.916; a soft floor in "
    "quadrature, a = sqrt(d^2 + s^2) with s from (5), 4 of 30, 2.85; the hard floor for the "
    "equation's scale but the step bounded smoothly, p = n / sqrt(d^2 + s^2), 4 of 30, 3.56; the "
    "regularised inverse p = n d / (d^2 + s^2), 0 of 30, 5.95; a quartic soft floor "
    "(d^4 + s^4)^(1/4), 18 of 30, 1.18; a C1 join (d above s, s (1 + (d/s)^2) / 2 below), 19 of "
    "30, 0.98; R per pixel from the mask's local thickness (the largest inscribed disc containing "
    "the pixel), 18 of 30, 0.93; (5) with the 8-bit quantisation of the normal map (1/255 on n_z) "
    "added in quadrature, 21 of 30, 0.914 (the quantisation is 30-50x below the footprint's "
    "floor); the mean position (this rule), 24 of 30, 0.917, kept. Every soft floor biases the "
    "slopes of all moderately steep normals (quadrature: 6 % at d = 0.3), which costs far more "
    "than the caps gain; the hard floor leaves them exact. The constant 0.12 reaches 26 of 30 "
    "(mean ratio 0.873). As a diagnostic only (not how the rule was picked), scaling the median "
    "rule's floor by 0.88, 0.91, 0.94, 0.97, 1.00, 1.03, 1.06 gives 24, 24, 24, 23, 21, 21, 21 of "
    "30: the mean sits in a plateau, not on a spike. The figures respond erratically to the floor "
    "(down2 bear: 0.129, 0.066, 0.151, 0.064, 0.252 mm at 0.10, 0.12, 0.14, 0.16, 0.18; with every "
    "IRLS step solved to 1e-4: 0.138, 0.074, 0.065, 0.063, 0.251, and 0.280 at 0.17, so it is "
    "the reweighting's fixed points, not only the solver's path), because they are set by the gaps across interior occluding contours, which "
    "the normals do not determine; differences of a few per cent between two floors are of that "
    "kind. Buddha's window is behind the re-run at every floor from 0.10 up (0.59-0.68 mm against "
    "0.523): its folds want steeper slopes than any floor near 0.1 allows."
)

#: Why the rule is behind where it is, and the changes tried for issue 12's follow-up (figures
#: measured once with scripts outside the repository on the same cases; the tables above are live).
ISSUE12_NOTE = (
    "Issue 12, follow-up: why the rule loses where it loses. (1) Where the error sits: in the cases "
    "behind (and most ahead) the difference from the truth is mostly piecewise constant: whole parts "
    "(bear's head, cat's front paw and head, buddha's sleeves and base, pot1's handle) sit at the wrong depth against the part the median "
    "scale is "
    "fitted to, across interior occluding contours; inside each part the error is small and alike for "
    "the rule and the re-run. (2) What sets it: at such a contour the background pixel's equation "
    "towards the occluder is let go by its bilateral weight (its one-sided difference is many times "
    "the other), so the jump is carried by the occluder's last, grazing pixels alone, whose capped step "
    "is about 1 / floor pixels. The normals hold nothing else about the jump. (The other regime, "
    "where the reweighting never opens a contour because the uniform start spreads the jump over many "
    "pixels and neither side's one-sided difference stands out, is not what loses here; it is what "
    "happens to a hemisphere of radius 25 pixels floating 5 height units above a plane (orthographic, "
    "as in tests/test_bilateral.py): at the default floor the rim pixel keeps its link to the plane with "
    "weight 0.73 and the plane's pixel its link back with 0.47, the solution's jump there is 0.2 against "
    "8.9 true, and the sphere sits 8.0-8.3 too low at every floor from 0.05 to 0.2.) The cap is a fair guess "
    "(the table above: the true jumps' median is 0.8-1.5 times 1 / floor on five objects, 2.9 times "
    "on cat) but the figures need far more: on down2 bear the mean jump across the neck is 5.30 pixel "
    "units at the floor and 4.82 at 1.1 times it (truth 6.26), which moves the head by half a mm and "
    "the MADE from 0.069 to 0.281 mm. (3) The same jumps drift slowly during the reweighting, so the "
    "stopping step matters as much as the floor: MADE after 5 / 10 / 20 / 30 / 100 steps (energy "
    "tolerance off) is 0.060 / 0.180 / 0.282 / 0.297 / 0.301 on noise bear (re-run 0.256), 1.180 / "
    "0.915 / 0.808 / 0.722 / 0.599 on window buddha (0.523), 0.834 / 0.719 / 0.632 / 0.605 / 0.682 on "
    "down2 pot1 (0.603), 0.111 / 0.077 / 0.079 / 0.078 / 0.078 on cat (0.074). The re-run's figures "
    "are points on such paths too (its loose Jacobi CG stops the drift early), and they move as much "
    "with the noise seed: noise bear, seeds 0-3, re-run 0.256 / 0.238 / 0.223 / 0.245, rule 0.295 / "
    "0.202 / 0.318 / 0.186; noise cat, re-run 0.078 / 0.076 / 0.073 / 0.062, rule 0.071 / 0.068 / "
    "0.074 / 0.065; noise buddha, re-run 1.604 / 1.512 / 1.345 / 1.602, rule 1.000 / 1.003 / 1.021 / "
    "0.990. A case a few per cent behind is one draw of that spread, not a bias of the rule. (4) "
    "Changes tried, each on the 30 cases and, where it was worth it, on the 30 held-out ones (count at "
    "or below the re-run; mean ratio rule / re-run), against the rule's 24 (0.917) and 23 (0.913): "
    "the floor scaled by 0.8 / 0.9 / 1.1 / 1.25: 22 / 25 / 22 / 22 of 30 (0.948 / 0.935 / 0.999 / "
    "1.102); every reweighting step solved to CG 1e-3: 25 (0.915); the IRLS run to its fixed point "
    "(energy tolerance 1e-6, 400 steps): 24 (0.902), held-out 23 (0.904); at most 10 / 20 / 40 steps: "
    "9 / 21 / 23; BiNI's energy (with the updated weights) as the stopping test: 24 (0.916), held-out "
    "23 (0.913); continuation of the sharpness, k doubling from 1 (resp. 0.5, 0.25) to 2: 26 (0.908) "
    "(resp. 26, 25) but held-out 22 (0.910) (resp. 21), so its gain on the 30 was chance, not kept; "
    "k halving from 32 to 2: 19 (1.068); k = 1 or 4 throughout: 1 and 9 of 30; the weights' "
    "threshold scaled by a robust (MAD) scale of the one-sided differences: 1 of 30 (their MAD is "
    "about 0.02, i.e. an effective k near 100: the bulk of the pixels is smooth, so a robust scale "
    "of the bulk says nothing about the jumps; the differences are already in units of the normal's "
    "components, scale-free); the cap only at pixels whose normal turns by more than sqrt(2/R) "
    "towards a neighbour (a discontinuity test): 24 (0.934); R from the local profile of the "
    "normals (n_z^2 grows by 2 / rho per pixel inwards from a rim of radius rho): 8 (1.547), its "
    "minimum with the rule 21 (0.975); R as the largest distance to the mask's boundary pixels "
    "whose normals lean outwards (so that a crop through a surface is not taken for a silhouette): "
    "24 (0.916), held-out 23 (0.913); the weights compared on the uncapped scales: 8 (3.31), "
    "held-out 8 (2.70). None is better than the rule on both sets, so the rule is unchanged. The "
    "constant 0.12 (tuned on the six) reaches 26 (0.873) and held-out 24 (0.892)."
    " (5) Ten noise seeds per object (`bench_diligent_spread.py`, `results/diligent-spread.md`): "
    "the rule is at or below the re-run in 53 of 60 cases (sign test p = 8e-10; per object 7-10 of "
    "10, the losses on bear, cat and reading, where the seed flips the order), and BiNI's own "
    "equations solved to CG 1e-5 are at or below the re-run in 36 of 60 and on 2 of the 6 objects "
    "as published: the bar 'at or below BiNI on every case' is one BiNI itself fails when solved "
    "more accurately."
)

#: Published BiNI (k = 2) MADE in mm (shared/data/README.md).
BINI = {"bear": 0.334, "buddha": 1.098, "cat": 0.074, "cow": 0.058, "pot1": 0.635, "reading": 0.257}
#: Published uniform least-squares MADE in mm (same source).
PLAIN = {"bear": 1.20, "buddha": 3.72, "cat": 1.61, "cow": 0.89, "pot1": 1.51, "reading": 6.62}


def load(name: str, data: Path = DATA):
    """(normals (H, W, 3), mask (H, W), K (3, 3), depth_gt (H, W)) of one object."""
    folder = data / name
    mask = load_mask(folder / "mask.png")
    normals = load_normal_map(folder / "normal_map.png", mask=mask)
    K = np.loadtxt(folder / "K.txt")
    depth = np.load(folder / "depth_gt.npz")["depth_gt"].astype(np.float64)
    return normals, mask, K, depth


def timed(fn, repeats: int):
    """``fn()`` and its shortest wall time of ``repeats`` runs (the least disturbed by other
    work on a shared machine)."""
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return out, float(np.min(times))


def bini_rerun(normals, mask, K, *, sharpness=2.0, max_iter=100, tol=1e-4, cg_tol=1e-3):
    """BiNI as published (Cao et al. 2022): four one-sided log-depth equations per pixel, no
    slope clamp, sigmoid weights from the one-sided differences, each IRLS step solved by
    Jacobi-preconditioned CG to ``cg_tol`` warm-started from the last; the settings of its
    DiLiGenT evaluation (``k = 2``, 100 steps, energy tolerance 1e-4). A baseline for the table
    only: slow (scipy, assembled matrices) and, as BiNI's own notes say, dependent on the loose CG.
    Returns depth (H, W), NaN off the mask."""
    h, w = mask.shape
    index = np.full((h, w), -1)
    index[mask] = np.arange(mask.sum())
    n = int(mask.sum())
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    xb = (np.arange(w) - cx) / fx
    yb = (np.arange(h) - cy) / fy
    nx, ny, nz = normals[..., 0], normals[..., 1], normals[..., 2]
    dd = nz + ny * yb[:, None] - nx * xb[None, :]
    rows, cols = np.nonzero(mask)

    def one_sided(dr, dc):
        """Rows ``a_i (u_neighbour - u_i)`` (sign flipped for a backward side), zero where the
        neighbour is off the mask."""
        r2, c2 = rows + dr, cols + dc
        ok = (r2 >= 0) & (r2 < h) & (c2 >= 0) & (c2 < w)
        ok[ok] = mask[r2[ok], c2[ok]]
        a = (fx if dc else fy) * dd[rows, cols] * (1.0 if dr + dc > 0 else -1.0)
        i = np.flatnonzero(ok)
        return sp.csr_matrix(
            (np.r_[-a[ok], a[ok]], (np.r_[i, i], np.r_[i, index[r2[ok], c2[ok]]])), shape=(n, n)
        )

    right, left, down, up = one_sided(0, 1), one_sided(0, -1), one_sided(1, 0), one_sided(-1, 0)
    A = sp.vstack([right, left, down, up]).tocsr()
    bx, by = nx[mask], -ny[mask]
    b = np.r_[bx, bx, by, by]
    weights = np.full(4 * n, 0.5)
    u = np.zeros(n)
    residual = A @ u - b
    energy = residual @ (weights * residual)
    for _ in range(max_iter):
        M = (A.T @ sp.diags(weights) @ A).tocsr()
        jacobi = sp.diags(1.0 / np.clip(M.diagonal(), 1e-5, None))
        u, _ = spla.cg(M, A.T @ (weights * b), x0=u, M=jacobi, rtol=cg_tol, maxiter=5000)
        wx = 0.5 * (1 + np.tanh(0.5 * sharpness * ((left @ u) ** 2 - (right @ u) ** 2)))
        wy = 0.5 * (1 + np.tanh(0.5 * sharpness * ((up @ u) ** 2 - (down @ u) ** 2)))
        weights = np.r_[wx, 1 - wx, wy, 1 - wy]
        residual = A @ u - b
        previous, energy = energy, residual @ (weights * residual)
        if abs(energy - previous) / previous < tol:
            break
    out = np.full(mask.shape, np.nan)
    out[mask] = np.exp(u - u.mean())
    return out


def noisy(normals, mask, *, degrees=2.0, seed=0):
    """Normals turned by Gaussian noise in their tangent plane, ``degrees`` RMS in angle (two
    tangent components of ``degrees / sqrt(2)`` each), seeded."""
    rng = np.random.default_rng(seed)
    n = np.where(mask[..., None], normals, 0.0)
    g = rng.normal(0.0, np.radians(degrees) / np.sqrt(2.0), n.shape)
    g -= n * np.sum(g * n, axis=-1, keepdims=True)
    out = n + g
    out /= np.maximum(np.linalg.norm(out, axis=-1, keepdims=True), 1e-300)
    out[~mask] = np.nan
    return out


def downsample2(normals, mask, K, depth):
    """The scene seen by a camera of half the resolution: a pixel of it covers a 2x2 block, is
    on the mask where all four are, and has their mean normal (renormalised) and mean depth;
    ``f`` halves and the principal point moves to the blocks' grid (``c' = (c - 1/2) / 2``)."""
    h, w = (mask.shape[0] // 2) * 2, (mask.shape[1] // 2) * 2

    def blocks(a):
        return a[:h, :w].reshape(h // 2, 2, w // 2, 2, *a.shape[2:])

    m = blocks(mask).all(axis=(1, 3))
    n = blocks(np.where(mask[..., None], normals, 0.0)).sum(axis=(1, 3))
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
    n[~m] = np.nan
    z = blocks(np.where(mask, depth, 0.0)).mean(axis=(1, 3))
    z[~m] = np.nan
    K2 = K.copy()
    K2[0, 0], K2[1, 1] = K[0, 0] / 2, K[1, 1] / 2
    K2[0, 2], K2[1, 2] = (K[0, 2] - 0.5) / 2, (K[1, 2] - 0.5) / 2
    return n, m, K2, z


def window(mask: np.ndarray, percent: int) -> np.ndarray:
    """The largest 4-connected part of ``mask`` within the middle ``percent`` % of its bounding
    box's rows and columns (integer arithmetic: 60 % leaves out a fifth on each side)."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    h, w = rows[-1] + 1 - rows[0], cols[-1] + 1 - cols[0]
    dr, dc = h * (100 - percent) // 200, w * (100 - percent) // 200
    win = np.zeros_like(mask)
    win[rows[0] + dr : rows[-1] + 1 - dr, cols[0] + dc : cols[-1] + 1 - dc] = True
    labels, _ = ndimage.label(mask & win)
    return labels == np.argmax(np.bincount(labels[labels > 0]))


def variant(name: str, kind: str, data: Path = DATA):
    """(normals, mask, K, depth_gt) of one object as published (``"original"``) or perturbed:
    ``"noise"`` (:func:`noisy`, seed 0; ``"noise-s1"``, ``"noise-s2"``: seeds 1, 2),
    ``"down2"`` (:func:`downsample2`; ``"down2-shift"``: the blocks start one pixel down and
    right), ``"eroded"`` (the mask eroded by 3 pixels, 4-connected steps) or ``"window"``
    (:func:`window`, the middle 60 %; ``"window50"``, ``"window70"``: 50 %, 70 %)."""
    normals, mask, K, depth = load(name, data)
    if kind == "original":
        return normals, mask, K, depth
    if kind in ("noise", "noise-s1", "noise-s2"):
        return noisy(normals, mask, seed=0 if kind == "noise" else int(kind[-1])), mask, K, depth
    if kind == "down2":
        return downsample2(normals, mask, K, depth)
    if kind == "down2-shift":
        # cropping one row and column moves the principal point by -1 before the halving
        K1 = K.copy()
        K1[0, 2], K1[1, 2] = K[0, 2] - 1, K[1, 2] - 1
        return downsample2(normals[1:, 1:], mask[1:, 1:], K1, depth[1:, 1:])
    if kind == "eroded":
        sub = ndimage.binary_erosion(mask, iterations=3)
    elif kind in ("window", "window50", "window70"):
        sub = window(mask, 60 if kind == "window" else int(kind[-2:]))
    else:
        raise ValueError(f"unknown variant {kind!r}; one of {', '.join(VARIANTS + EXTRA_VARIANTS)}")
    normals = normals.copy()
    normals[~sub] = np.nan
    return normals, sub, K, depth


def contour_jumps(normals, mask, K, depth, *, excess=3.0, grazing=0.3):
    """The ground truth's one-pixel jumps across interior occluding contours, in pixel units.

    A diagnostic of what the slope cap has to guess: a pair of neighbours inside the mask counts
    as a discontinuity where the true step of ``log Z`` times ``f`` (pixel units, as the capped
    step ``1 / floor``) differs by more than ``excess`` from the step the less grazing of the two
    normals predicts, and the more grazing one has ``|d| < grazing``. Both thresholds are
    diagnostic only (they pick the pairs; nothing is fitted to them).

    Returns
    -------
    (int, float, float, float)
        Number of pairs; median, lower and upper quartile of the absolute jumps.
    """
    h, w = mask.shape
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    xb = (np.arange(w) - cx) / fx
    yb = (np.arange(h) - cy) / fy
    d = normals[..., 2] + normals[..., 1] * yb[:, None] - normals[..., 0] * xb[None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        steps = (normals[..., 0] / d, -normals[..., 1] / d)
        log_z = np.log(np.where(mask, depth, np.nan))
    jumps = []
    for axis, f, step in ((1, fx, steps[0]), (0, fy, steps[1])):
        true = np.diff(log_z, axis=axis) * f
        first = (slice(None), slice(None, -1)) if axis else (slice(None, -1), slice(None))
        second = (slice(None), slice(1, None)) if axis else (slice(1, None), slice(None))
        d1, d2 = np.abs(d[first]), np.abs(d[second])
        near = np.where(d1 > d2, step[first], step[second])
        with np.errstate(invalid="ignore"):
            pick = (
                mask[first] & mask[second] & (np.abs(true - near) > excess) & (np.minimum(d1, d2) < grazing)
            )
        jumps.append(np.abs(true[pick & np.isfinite(true)]))
    j = np.concatenate(jumps)
    if not j.size:
        return 0, np.nan, np.nan, np.nan
    return int(j.size), float(np.median(j)), float(np.percentile(j, 25)), float(np.percentile(j, 75))


def _summary(title: str, rows: list) -> str:
    """One line: in how many of ``rows`` the rule is at or below the re-run, which are behind
    and by how much, the constant 0.12's count and the times (of the timed cases: not the
    held-out ones, run once each for their figures)."""
    behind = [r for r in rows if r["new"][0] > r["rerun"][0]]
    ratios = [r["new"][0] / r["rerun"][0] for r in rows]
    timed_rows = [r for r in rows if r["kind"] in VARIANTS]
    return (
        f"**{title[0].upper() + title[1:]}**: rule at or below the re-run in {len(rows) - len(behind)} of "
        f"{len(rows)} (mean ratio rule / re-run {np.mean(ratios):.3f}); behind in "
        + (
            ", ".join(
                f"{r['name']} {r['kind']} ({100 * (r['new'][0] / r['rerun'][0] - 1):+.0f} %)" for r in behind
            )
            or "none"
        )
        + f". 0.12 at or below the re-run in {sum(r['old'][0] <= r['rerun'][0] for r in rows)} of "
        f"{len(rows)} (mean ratio {np.mean([r['old'][0] / r['rerun'][0] for r in rows]):.3f})."
        + ("" if not timed_rows else " ")
        + _times(timed_rows)
    )


def _times(rows: list) -> str:
    """Total times and speed-ups of ``rows`` (empty if none)."""
    if not rows:
        return ""
    t_new = sum(r["t_new"] for r in rows)
    t_re = sum(r["t_rerun"] for r in rows)
    return (
        f"Total time: rule {t_new:.1f} s, re-run {t_re:.1f} s (speed-up {t_re / t_new:.1f}x; per case "
        f"{min(r['t_rerun'] / r['t_new'] for r in rows):.1f}-"
        f"{max(r['t_rerun'] / r['t_new'] for r in rows):.1f}x)."
    )


def _made2(z, gt, mask):
    return made(z, gt, mask, fit="median_scale"), made(z, gt, mask)


def main(argv=None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-sweep", action="store_true", help="skip the min_scale sensitivity table")
    parser.add_argument("--no-rerun", action="store_true", help="skip the BiNI re-runs (a few minutes)")
    parser.add_argument("--no-variants", action="store_true", help="only the objects as published")
    parser.add_argument("--no-extra", action="store_true", help="without the held-out variants")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "diligent.md")
    args = parser.parse_args(argv)
    if not DATA.is_dir():
        raise SystemExit(f"DiLiGenT data not found at {DATA}")
    # compile the numba kernels once
    n, m, K, _ = load("cow")
    integrate_bilateral(n, m, K=K)
    kinds = VARIANTS[:1] if args.no_variants else VARIANTS + (() if args.no_extra else EXTRA_VARIANTS)
    rows = []
    inputs = []
    for kind in kinds:
        for name in OBJECTS:
            normals, mask, K, gt = variant(name, kind)
            inputs.append((normals, mask, K))
            result, t_new = timed(partial(integrate_bilateral, normals, mask, K=K, sharpness=2.0), 1)
            old = integrate_bilateral(normals, mask, K=K, sharpness=2.0, min_scale=OLD_MIN_SCALE)
            row = dict(
                name=name,
                kind=kind,
                pixels=int(mask.sum()),
                floor=float(contour_scale(mask)[mask].min()),
                new=_made2(result.depth, gt, mask),
                old=_made2(old.depth, gt, mask),
                t_new=t_new,
                steps=result.iterations,
                cg=result.cg_iterations,
            )
            if kind == "original":
                ls, row["t_ls"] = timed(partial(integrate_bilateral, normals, mask, K=K, iterations=0), 1)
                row["ls"] = _made2(ls.depth, gt, mask)
                row["jumps"] = contour_jumps(normals, mask, K, gt)
            if args.no_rerun:
                row["rerun"], row["t_rerun"] = (np.nan, np.nan), np.nan
            else:
                z_re, row["t_rerun"] = timed(partial(bini_rerun, normals, mask, K), 1)
                row["rerun"] = _made2(z_re, gt, mask)
            if row["new"][0] > row["rerun"][0]:
                # how the figure responds to the floor where the rule is behind (issue 12)
                row["near"] = [
                    made(
                        integrate_bilateral(normals, mask, K=K, min_scale=min(1.0, f * row["floor"])).depth,
                        gt,
                        mask,
                        fit="median_scale",
                    )
                    for f in (0.9, 1.1)
                ]
            rows.append(row)
            print(
                f"{kind:8s} {name:8s} floor {row['floor']:.3f}  rule {row['new'][0]:.3f}  "
                f"0.12 {row['old'][0]:.3f}  BiNI re-run {row['rerun'][0]:.3f}",
                flush=True,
            )
    # the other timed runs in passes over all cases, so that a burst of other work on a shared
    # machine spoils at most one run of a case, not all of them
    for _ in range(args.repeats - 1):
        for row, (normals, mask, K) in zip(rows, inputs):
            if row["kind"] not in VARIANTS:
                continue  # the held-out cases are not timed (the benchmark's length)
            row["t_new"] = min(row["t_new"], timed(partial(integrate_bilateral, normals, mask, K=K), 1)[1])
            if not args.no_rerun:
                row["t_rerun"] = min(row["t_rerun"], timed(partial(bini_rerun, normals, mask, K), 1)[1])
    for row in rows:
        print(f"{row['kind']:8s} {row['name']:8s} {row['t_new']:.2f} s vs {row['t_rerun']:.2f} s")
    lines = [
        "# DiLiGenT normal integration (perspective, ground-truth normals)",
        "",
        "MADE in mm under two fits of the unknown scale (`shadeform.metrics.made`): **median** "
        '(`fit="median_scale"`, the median of the depth ratios: the protocol of BiNI\'s DiLiGenT '
        "evaluation script, which its published figures use) and **LS** (least-squares scale). "
        "The bar is judged under BiNI's own protocol: bilateral MADE (median) <= BiNI's.",
        "BiNI re-run: `bini_rerun` in this script, a scipy re-implementation of the published "
        "algorithm (no slope clamp, Jacobi CG to 1e-3 per step, k = 2, 100 steps, energy "
        "tolerance 1e-4); under the median protocol it reproduces the published figures on five "
        "objects to the third decimal, which is how the protocol was confirmed. The uniform least "
        "squares agrees likewise: under the median protocol it is within 2 % of the published "
        "plain least-squares figures on five objects (bear 9 %).",
        "**rule**: `integrate_bilateral(normals, mask, K=K, sharpness=2)` with its default slope "
        "cap, the geometric floor of `contour_scale` (the mean n_z of the outermost pixel centres of "
        "a body of the mask's largest inscribed radius R, ~ (2/3) sqrt(2/R); column *floor*). **0.12**: the same "
        "with `min_scale=0.12`, the constant it replaced. Uniform LS: the same log-depth equations "
        "with `iterations=0`.",
        f"Times: shortest of {args.repeats} runs each (in {args.repeats} passes over all cases; the held-out "
        "variants are not timed), wall clock, "
        f"{os.cpu_count()} CPUs shared with other work, {platform.processor() or platform.machine()}; "
        "*speed-up* = re-run time / rule time.",
        "",
        "## The objects as published",
        "",
        "| object | pixels | floor | rule (median / LS) | 0.12 (median / LS) | BiNI (published) "
        "| BiNI re-run (median / LS) | rule <= BiNI | uniform LS (median / LS) | plain LS (published) "
        "| rule time (s) | re-run time (s) | speed-up | IRLS steps | CG iterations |",
        "|---|---:|---:|---:|---:|---:|---:|:---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        if r["kind"] != "original":
            continue
        ref = BINI[r["name"]]
        ok = "yes" if r["new"][0] <= min(ref, r["rerun"][0]) else "no"
        lines.append(
            f"| {r['name']} | {r['pixels']} | {r['floor']:.3f} | {r['new'][0]:.3f} / {r['new'][1]:.3f} "
            f"| {r['old'][0]:.3f} / {r['old'][1]:.3f} | {ref:.3f} "
            f"| {r['rerun'][0]:.3f} / {r['rerun'][1]:.3f} | {ok} "
            f"| {r['ls'][0]:.3f} / {r['ls'][1]:.3f} | {PLAIN[r['name']]:.2f} "
            f"| {r['t_new']:.2f} | {r['t_rerun']:.1f} | {r['t_rerun'] / r['t_new']:.1f} "
            f"| {r['steps']} | {r['cg']} |"
        )
    if not args.no_variants:
        lines += [
            "",
            "## Perturbed variants (MADE in mm, median protocol)",
            "",
            "*noise*: every normal turned by Gaussian noise in its tangent plane, 2 degrees RMS "
            "(seed 0); *down2*: a camera of half the resolution (2x2 blocks on the mask where all "
            "four pixels are, their mean normal renormalised and mean ground-truth depth; f / 2, "
            "c' = (c - 1/2) / 2); *eroded*: the mask eroded by 3 pixels; *window*: the mask within "
            "the middle 60 % of its bounding box's rows and columns (largest part). Held-out (after "
            "the table's first 30 rows): *noise-s1*, *noise-s2* (seeds 1, 2), *window50*, *window70* "
            "(50 %, 70 %), *down2-shift* (the blocks one pixel down and right). *vs re-run*: "
            "rule / re-run - 1 (negative: the rule is ahead).",
            "",
            "| variant | object | pixels | floor | rule | 0.12 | BiNI re-run | vs re-run "
            "| rule LS | re-run LS | rule time (s) | re-run time (s) | speed-up |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for r in rows:
            lines.append(
                f"| {r['kind']} | {r['name']} | {r['pixels']} | {r['floor']:.3f} | {r['new'][0]:.3f} "
                f"| {r['old'][0]:.3f} | {r['rerun'][0]:.3f} | {100 * (r['new'][0] / r['rerun'][0] - 1):+.0f} % "
                f"| {r['new'][1]:.3f} | {r['rerun'][1]:.3f} "
                + (
                    f"| {r['t_new']:.2f} | {r['t_rerun']:.2f} | {r['t_rerun'] / r['t_new']:.1f} |"
                    if r["kind"] in VARIANTS
                    else "| - | - | - |"
                )
            )
        for title, group in (("the 30 cases", VARIANTS), ("the held-out cases", EXTRA_VARIANTS)):
            sel = [r for r in rows if r["kind"] in group]
            if sel:
                lines += ["", _summary(title, sel)]
        behind = [r for r in rows if "near" in r]
        if behind:
            lines += [
                "",
                "## Where the rule is behind: the figure at 0.9 and 1.1 times the floor (median protocol)",
                "",
                "| variant | object | BiNI re-run | rule x0.9 | rule | rule x1.1 |",
                "|---|---|---:|---:|---:|---:|",
            ]
            for r in behind:
                lines.append(
                    f"| {r['kind']} | {r['name']} | {r['rerun'][0]:.3f} | {r['near'][0]:.3f} "
                    f"| {r['new'][0]:.3f} "
                    f"| {r['near'][1]:.3f} |"
                )
    lines += [
        "",
        "## What the slope cap has to guess: jumps across interior occluding contours",
        "",
        "The ground truth's one-pixel jumps of f log Z (pixel units) where it departs by more than 3 "
        "from the "
        "step the less grazing normal of the pair predicts and the other is grazing (|d| < 0.3; "
        "`contour_jumps`, a diagnostic), against the step the cap allows, 1 / floor.",
        "",
        "| object | pairs | true jump median (quartiles) | capped step 1 / floor |",
        "|---|---:|---:|---:|",
    ]
    for r in rows:
        if r["kind"] == "original":
            k, med, q1, q3 = r["jumps"]
            lines.append(f"| {r['name']} | {k} | {med:.1f} ({q1:.1f}-{q3:.1f}) | {1 / r['floor']:.1f} |")
    if not args.no_sweep:
        scales = (0.01, 0.05, 0.1, 0.12, 0.15)
        lines += [
            "",
            "## Sensitivity to `min_scale` (bilateral MADE in mm, median / LS; objects as published)",
            "",
            "| object | BiNI | rule | " + " | ".join(f"{v:g}" for v in scales) + " |",
            "|---|---:|---:|" + "---:|" * len(scales),
        ]
        for name in OBJECTS:
            normals, mask, K, gt = load(name)
            rule = next(r for r in rows if r["name"] == name and r["kind"] == "original")
            cells = [f"{rule['new'][0]:.3f} / {rule['new'][1]:.3f} (floor {rule['floor']:.3f})"]
            for v in scales:
                z = integrate_bilateral(normals, mask, K=K, min_scale=v).depth
                cells.append("{:.3f} / {:.3f}".format(*_made2(z, gt, mask)))
            lines.append(f"| {name} | {BINI[name]:.3f} | " + " | ".join(cells) + " |")
    lines += ["", "## History of the slope cap", "", MIN_SCALE_NOTE, "", RULE_NOTE, "", ISSUE12_NOTE]
    text = "\n".join(lines) + "\n"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, mode="w") as handle:
        handle.write(text)
    print(text)
    return text


if __name__ == "__main__":
    main()
