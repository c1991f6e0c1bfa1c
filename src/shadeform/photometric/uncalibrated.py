"""Photometric stereo with unknown lights: the lights read from the photos themselves.

Lambertian photos of one object, stacked as a matrix ``M`` (photos x pixels), have rank three:
``M = S B^T`` with ``S`` (N, 3) the lights times their strengths and ``B`` (P, 3) the normals
times the albedo. A factorisation finds them only up to an invertible 3x3 ``Q``; that the normals
come from a surface (integrability) fixes ``Q`` up to the generalised bas-relief transform
(Belhumeur, Kriegman and Yuille 1999): on the pseudo-normals, ``G = [[1, 0, a], [0, 1, b],
[0, 0, c]]``, which no Lambertian photo can tell apart, and which keeps occluding contours as
they are (so the outline cannot settle it). Here:

1. the rank-3 factorisation by alternating weighted least squares, each pixel's darkest 30 %
   and brightest 20 % of readings (shadows, highlights) left out, after each photo is divided
   by its median brightness (so that the unknown strengths do not decide the ranking), started
   from the singular value decomposition of the pixels no photo leaves black;
2. ``Q`` from integrability as Yuille and Snow (1997) solve it: for the pseudo-normals ``b``,
   ``(b x b_y) . (q1 x q3) - (b x b_x) . (q2 x q3) = 0`` at every pixel, linear in the six
   numbers ``q1 x q3`` and ``q2 x q3``: the smallest singular vector;
3. ``a``, ``b``, ``c`` by the albedo's least entropy (Alldrin, Mallick and Kriegman 2007): the
   relief at which the albedo is most uniform, on a grid;
4. convex, not concave: the outline's normals point out of the object;
5. whether the entropy settled the relief (:class:`ReliefCheck`): the albedo's entropy must rise
   when the depth is halved and when it is doubled by more than twice its own sampling spread
   (a bootstrap over the pixels). Where it does not (it keeps falling toward a flat or a deep
   relief), the photos did not fix the relief and the shape is a guess.

The lights (directions and relative strengths) are what :func:`estimate_lights` returns;
:func:`shadeform.photometric_stereo` with ``lights=None`` then solves as with known lights. Its
accuracy on the real DiLiGenT objects is far from the calibrated fit's
(``benchmarks/results/stereo.md``): the factorisation and the contour are corrupted by shadows,
gloss and outlines that are not occluding contours.

References
----------
.. [1] P. N. Belhumeur, D. J. Kriegman, A. L. Yuille, "The bas-relief ambiguity", IJCV 35(1), 1999.
.. [2] A. L. Yuille, D. Snow, "Shape and albedo from multiple images using integrability",
   CVPR 1997.
.. [3] N. G. Alldrin, S. P. Mallick, D. J. Kriegman, "Resolving the generalized bas-relief
   ambiguity by entropy minimization", CVPR 2007.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shadeform.errors import InputError
from shadeform.photometric.lambertian import DROP_BRIGHT, DROP_DARK  # the readings left out

#: Alternating least-squares rounds of the factorisation.
ROUNDS = 10
#: The bas-relief transform's depths (log-spaced) and slopes on the grid the search starts from,
#: and the bins of the log-albedo histogram: set once, not swept.
DEPTHS = np.exp(np.linspace(np.log(0.1), np.log(10.0), 13))
SLOPES = np.linspace(-2.0, 2.0, 21)
BINS = 200
#: Bootstrap draws of the pixels for the entropy's sampling spread (:class:`ReliefCheck`): enough
#: for a spread to a few percent, a choice of cost, not fitted.
DRAWS = 20
#: How many of its bootstrap spreads the entropy must rise by, at half and at twice the depth, for
#: the relief to count as settled: the usual two-sigma significance, not fitted. (Measured after
#: the choice: DiLiGenT's cow and reading, lights read from their photos, rise by -0.8 and -1.4
#: spreads, -0.5 for reading with its light strengths divided out; the other five by 10.7-84.)
SIGNIFICANT = 2.0


@dataclass(frozen=True)
class ReliefCheck:
    """Whether the albedo's entropy settled the bas-relief (step 5 of the module's notes).

    Attributes
    ----------
    depth : float
        The bas-relief transform's depth scale ``c`` the entropy chose.
    rise : float
        The albedo's entropy (nats) at half or at twice that depth, whichever is lower, minus its
        entropy at the depth chosen: positive at a true minimum.
    spread : float
        The standard deviation of ``rise`` over bootstrap draws of the pixels.
    """

    depth: float
    rise: float
    spread: float

    @property
    def resolved(self) -> bool:
        """Whether the rise stands out of its spread by :data:`SIGNIFICANT` times."""
        return bool(self.rise > SIGNIFICANT * self.spread)


def estimate_lights(readings: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, ReliefCheck]:
    """Light directions and relative strengths from photos of one object under unknown lights.

    Parameters
    ----------
    readings : (N, P) float
        The object's readings, one row per photo, pixels in the order of ``np.nonzero(mask)``.
    mask : (H, W) bool
        The object (its outline gives the occluding contour).

    Returns
    -------
    directions : (N, 3) float64
        Unit vectors toward the lights (``docs/conventions.md``).
    strengths : (N,) float64
        Each light's strength over the median photo's.
    check : ReliefCheck
        Whether the photos settled the bas-relief (when not, the depth is a guess).

    Raises
    ------
    InputError
        Fewer than four photos, or photos that do not span three dimensions of shading.
    """
    from shadeform.light.contour import find_boundary

    values = np.asarray(readings, dtype=np.float64)
    if values.shape[0] < 4:
        raise InputError(
            f"unknown lights need at least 4 photos to be read from the photos, got {values.shape[0]}"
        )
    # each photo over its median brightness first: the strengths, unknown, would otherwise decide
    # which of a pixel's readings count as its darkest and brightest
    typical = np.array([np.median(row[row > 0]) if (row > 0).any() else 0.0 for row in values])
    if not (typical > 0).all():
        raise InputError(f"photo {int(np.argmin(typical)) + 1} is black on the object; leave it out")
    lights, pseudo = _factorise(values / typical[:, None])
    lights = lights * typical[:, None]
    image = np.zeros(mask.shape + (3,))
    image[mask] = pseudo
    q = _integrable(image, mask)
    normals = pseudo @ q
    if np.median(normals[:, 2]) < 0:
        q, normals = -q, -normals
    boundary = find_boundary(mask)
    index = np.full(mask.shape, -1, dtype=np.int64)
    index[mask] = np.arange(np.count_nonzero(mask))
    g, check = _bas_relief(normals)
    final = normals @ g.T
    outline = final[index[boundary.rows, boundary.cols]]
    if np.nanmean(np.sum(outline[:, :2] * boundary.normals[:, :2], axis=1)) < 0:
        g = np.diag([-1.0, -1.0, 1.0]) @ g  # concave: mirror to convex
    # M = S B^T = (S Q^-T G^-1) (G Q^T B^T)
    scaled = lights @ np.linalg.inv(q).T @ np.linalg.inv(g)
    strength = np.linalg.norm(scaled, axis=1)
    if not (np.isfinite(strength).all() and (strength > 0).all()):
        raise InputError(
            "the photos' shading does not span three dimensions; give the lights, or more varied photos"
        )
    return scaled / strength[:, None], strength / np.median(strength), check


def _factorise(values):
    """``S`` (N, 3), ``B`` (P, 3) with ``values ~ S B^T`` on each pixel's middle readings."""
    count = values.shape[0]
    full = (values > 0).all(axis=0)
    start = values[:, full] if np.count_nonzero(full) >= 100 else values
    u, s, _ = np.linalg.svd(start, full_matrices=False)
    if s.size < 3 or s[2] <= 1e-9 * s[0]:
        raise InputError(
            "the photos' shading does not span three dimensions; give the lights, or more varied photos"
        )
    lights = u[:, :3] * np.sqrt(s[:3])
    order = np.argsort(values, axis=0)
    weights = np.zeros_like(values)
    np.put_along_axis(weights, order[int(DROP_DARK * count) : count - int(DROP_BRIGHT * count)], 1.0, axis=0)
    weights *= values > 0
    for _ in range(ROUNDS):
        ridge = 1e-6 * np.trace(lights.T @ lights) / count * np.eye(3)
        system = np.einsum("np,ni,nj->pij", weights, lights, lights) + ridge
        pseudo = np.linalg.solve(system, np.einsum("np,ni,np->pi", weights, lights, values)[..., None])[
            ..., 0
        ]
        ridge = 1e-6 * np.trace(pseudo.T @ pseudo) / len(pseudo) * np.eye(3)
        system = np.einsum("np,pi,pj->nij", weights, pseudo, pseudo) + ridge
        lights = np.linalg.solve(system, np.einsum("np,pi,np->ni", weights, pseudo, values)[..., None])[
            ..., 0
        ]
    return lights, pseudo


def _integrable(image, mask):
    """``Q`` (3, 3) making the pseudo-normals ``image`` (H, W, 3) integrable, up to a bas-relief
    transform: Yuille and Snow's linear condition with central differences (x to the right, y
    up) of the pseudo-normals smoothed by a Gaussian of one pixel within the mask (derivatives of
    noisy data), away from the outline (two pixels in)."""
    from scipy import ndimage as ndi

    inner = ndi.binary_erosion(mask, iterations=2)
    inner[[0, -1], :] = False
    inner[:, [0, -1]] = False
    if np.count_nonzero(inner) < 50:
        inner = mask.copy()
        inner[[0, -1], :] = False
        inner[:, [0, -1]] = False
    weight = ndi.gaussian_filter(mask.astype(np.float64), 1.0)
    image = np.stack([ndi.gaussian_filter(image[..., k], 1.0) for k in range(3)], axis=-1)
    image /= np.maximum(weight, 1e-12)[..., None]
    b = image[inner]
    right = 0.5 * (np.roll(image, -1, axis=1) - np.roll(image, 1, axis=1))[inner]
    up = -0.5 * (np.roll(image, -1, axis=0) - np.roll(image, 1, axis=0))[inner]  # a row down is y - 1
    system = np.hstack([np.cross(b, up), -np.cross(b, right)])
    _, _, vt = np.linalg.svd(system, full_matrices=False)
    cross_13, cross_23 = vt[-1, :3], vt[-1, 3:]  # q1 x q3 and q2 x q3
    q3 = np.cross(cross_13, cross_23)
    norm = q3 @ q3
    if not norm > 0:
        raise InputError(
            "the photos' shading does not span three dimensions; give the lights, or more varied photos"
        )
    return np.column_stack([np.cross(q3, cross_13) / norm, np.cross(q3, cross_23) / norm, q3])


def _bas_relief(normals):
    """The bas-relief transform ``G`` (3, 3) of the pseudo-normals (rows of ``normals``, made
    integrable): ``G = [[1, 0, a], [0, 1, b], [0, 0, c]]`` (a surface's ``z -> c' z + mu x + nu y``
    seen on its normals) with the least entropy of the albedo ``|G n|``: the best of a grid of
    ``a``, ``b`` (:data:`SLOPES`) and ``c`` (:data:`DEPTHS`), refined by Nelder and Mead's
    simplex; and its :class:`ReliefCheck`."""
    from scipy.optimize import minimize

    sample = normals[np.linspace(0, len(normals) - 1, min(len(normals), 5000)).astype(np.int64)]

    def entropy(params):
        a, b, log_c = params
        x, y = sample[:, 0] + a * sample[:, 2], sample[:, 1] + b * sample[:, 2]
        return _entropy(np.sqrt(x * x + y * y + (np.exp(log_c) * sample[:, 2]) ** 2))

    grid = [(a, b, np.log(c)) for a in SLOPES for b in SLOPES for c in DEPTHS]
    start = min(grid, key=entropy)
    a, b, log_c = minimize(entropy, start, method="Nelder-Mead", options={"xatol": 1e-3, "fatol": 1e-6}).x
    transform = np.array([[1.0, 0.0, a], [0.0, 1.0, b], [0.0, 0.0, np.exp(log_c)]])
    return transform, _check(sample, transform)


def _check(sample, transform) -> ReliefCheck:
    """How much the albedo's entropy rises at half and at twice the chosen depth, and the
    spread of that rise over bootstrap draws of the pixels (seeded: the same photos, the same
    answer)."""
    a, b, c = transform[0, 2], transform[1, 2], transform[2, 2]

    def rise(pixels):
        x, y = pixels[:, 0] + a * pixels[:, 2], pixels[:, 1] + b * pixels[:, 2]
        at = [_entropy(np.sqrt(x * x + y * y + (k * c * pixels[:, 2]) ** 2)) for k in (1.0, 0.5, 2.0)]
        return min(at[1], at[2]) - at[0]

    rng = np.random.default_rng(0)
    draws = [rise(sample[rng.integers(0, len(sample), len(sample))]) for _ in range(DRAWS)]
    return ReliefCheck(float(c), float(rise(sample)), float(np.std(draws)))


def _entropy(albedo):
    """Shannon entropy of the albedo's distribution: a histogram of ``log(albedo / median)`` in
    :data:`BINS` bins over [-1, 1], smoothed by a Gaussian of two bins (so that it changes
    smoothly with the transform)."""
    from scipy import ndimage as ndi

    albedo = albedo[np.isfinite(albedo) & (albedo > 0)]
    if albedo.size == 0:
        return np.inf
    counts, _ = np.histogram(np.clip(np.log(albedo / np.median(albedo)), -1, 1), bins=BINS, range=(-1, 1))
    share = ndi.gaussian_filter1d(counts.astype(np.float64), 2.0, mode="constant")
    share = share[share > 0] / share.sum()
    return float(-(share * np.log(share)).sum())
