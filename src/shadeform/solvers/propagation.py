"""Normal field by convexity-guided propagation: the 2002 ModelBuilder algorithm.

Every normal that explains a pixel's brightness ``I = albedo (N . L)`` (``albedo`` for the
``k * albedo`` of the image model) lies on a cone around the light ``L`` with half-angle
``theta = arccos(I / albedo)``. The report keeps the two cone normals in the plane
spanned by ``L`` and the direction of largest intensity change (the image gradient), and chooses
between them:

* **by convexity**, axis by axis: on a convex surface the normal tilts away from the brighter side,
  i.e. against the intensity gradient; inside a region the user marked concave along ``x``, ``y``
  or both, that choice flips. Each axis counts in proportion to how parallel the gradient is to it
  (``gx**2`` and ``gy**2`` of the unit gradient);
* **by agreement with already-computed neighbours** where the convexity test cannot decide: the
  gradient is too weak to be trusted (flat regions, where the two candidates nearly coincide) or
  points diagonally across an axis-only concave region.

The field grows outward from a reference pixel whose normal is known (breadth first over the
4-connected mask), so every pixel has computed neighbours to agree with.

``propagate_normals`` is the compiled kernel; ``propagate_normals_reference`` is a slow, plain
Python transcription of the same rule kept for the tests.

References
----------
.. [1] ModelBuilder: shape from shading with user-guided convexity, MIT, 2002 (the report
   summarised in ``DESIGN.md``; section 3.5.b is the algorithm implemented here).
"""

from __future__ import annotations

import inspect
from collections import deque

import numba
import numpy as np

from shadeform.errors import InputError
from shadeform.solvers.problem import Problem, Solution

#: The convexity vote must be at least this clear (|2 kappa - 1|) to decide on its own.
AXIS_CLARITY = 0.2


def image_gradient(image: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Intensity gradient in the camera frame, using object pixels only.

    Central differences where both neighbours are in the mask, one-sided differences where only
    one is, zero where neither is, so the dark background never creates a fake edge gradient.

    Parameters
    ----------
    image : (H, W) float
    mask : (H, W) bool

    Returns
    -------
    gx, gy : (H, W) float64
        ``dI/dx`` (along columns) and ``dI/dy`` (y up, so ``-dI/drow``); 0 outside the mask.
    """
    img = np.where(mask, image, 0.0).astype(np.float64)
    m = mask.astype(bool)

    def axis_derivative(axis: int) -> np.ndarray:
        fwd_ok = np.zeros_like(m)
        bwd_ok = np.zeros_like(m)
        fwd = np.zeros_like(img)
        bwd = np.zeros_like(img)
        lead = [slice(None)] * 2
        trail = [slice(None)] * 2
        lead[axis], trail[axis] = slice(1, None), slice(None, -1)
        lead, trail = tuple(lead), tuple(trail)
        # forward difference I[i+1] - I[i] lives at i; backward difference I[i] - I[i-1] at i
        pair = m[lead] & m[trail]
        diff = img[lead] - img[trail]
        fwd[trail] = np.where(pair, diff, 0.0)
        fwd_ok[trail] = pair
        bwd[lead] = np.where(pair, diff, 0.0)
        bwd_ok[lead] = pair
        count = fwd_ok.astype(np.float64) + bwd_ok
        return np.where(m & (count > 0), (fwd + bwd) / np.maximum(count, 1.0), 0.0)

    gx = axis_derivative(1)
    gy = -axis_derivative(0)
    return gx, gy


# --------------------------------------------------------------------------------------------
# The per-pixel rule, shared by the compiled kernel and the slow reference.
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _choose_normal(cos_t, gx, gy, g_min, cx, cy, lx, ly, lz, mean_x, mean_y, mean_z, out):
    """Write into ``out`` the cone normal chosen for one pixel (see module docstring)."""
    cos_t = min(max(cos_t, 0.0), 1.0)
    sin_t = np.sqrt(1.0 - cos_t * cos_t)
    g_norm = np.sqrt(gx * gx + gy * gy)
    have_mean = mean_x * mean_x + mean_y * mean_y + mean_z * mean_z > 0.0

    # Direction in which the two candidates tilt away from L: the image gradient (x, y, 0) made
    # perpendicular to L. Where the gradient is untrustworthy, use the neighbours' tilt instead.
    use_gradient = g_norm >= g_min and g_norm > 0.0
    if use_gradient:
        dx, dy, dz = gx / g_norm, gy / g_norm, 0.0
    elif have_mean:
        dx, dy, dz = mean_x, mean_y, mean_z
    else:
        out[0], out[1], out[2] = lx, ly, lz
        return
    along = dx * lx + dy * ly + dz * lz
    ux, uy, uz = dx - along * lx, dy - along * ly, dz - along * lz
    u_norm = np.sqrt(ux * ux + uy * uy + uz * uz)
    if u_norm < 1e-12:
        out[0], out[1], out[2] = lx, ly, lz
        return
    ux, uy, uz = ux / u_norm, uy / u_norm, uz / u_norm

    # Candidate "+" tilts along u (toward brighter pixels when u is the gradient), "-" against it.
    sign = -1.0
    if use_gradient:
        # Convex surfaces tilt against the gradient; concave flags flip that per axis, weighted
        # by how parallel the gradient is to each axis.
        wx = (gx / g_norm) ** 2
        kappa = wx * cx + (1.0 - wx) * cy
        if abs(2.0 * kappa - 1.0) >= AXIS_CLARITY or not have_mean:
            sign = 1.0 if kappa > 0.5 else -1.0
        else:
            sign = 1.0 if (ux * mean_x + uy * mean_y + uz * mean_z) > 0.0 else -1.0
    else:
        # u came from the neighbours' own tilt: agreeing with them means tilting along u.
        sign = 1.0
    out[0] = cos_t * lx + sign * sin_t * ux
    out[1] = cos_t * ly + sign * sin_t * uy
    out[2] = cos_t * lz + sign * sin_t * uz


_OFFSETS = np.array([[-1, 0], [1, 0], [0, -1], [0, 1]], dtype=np.int64)


@numba.njit(cache=True)
def _propagate_kernel(
    cos_t, gx, gy, g_min, mask, concave_x, concave_y, light, seed_r, seed_c, seed_normal, normals, done, queue
):
    # work arrays come from the caller so that numpy (and memory profilers) see them
    h, w = mask.shape
    normals[seed_r, seed_c, :] = seed_normal
    done[seed_r, seed_c] = True
    queue[0] = seed_r * w + seed_c
    head, tail = 0, 1
    chosen = np.empty(3)
    while head < tail:
        idx = queue[head]
        head += 1
        r0, c0 = idx // w, idx % w
        for k in range(4):
            r, c = r0 + _OFFSETS[k, 0], c0 + _OFFSETS[k, 1]
            if r < 0 or r >= h or c < 0 or c >= w or done[r, c] or not mask[r, c]:
                continue
            # mean of the computed 8-neighbours: the "agreement" target
            mx, my, mz = 0.0, 0.0, 0.0
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    rr, cc = r + dr, c + dc
                    if 0 <= rr < h and 0 <= cc < w and done[rr, cc]:
                        mx += normals[rr, cc, 0]
                        my += normals[rr, cc, 1]
                        mz += normals[rr, cc, 2]
            _choose_normal(
                cos_t[r, c],
                gx[r, c],
                gy[r, c],
                g_min,
                concave_x[r, c],
                concave_y[r, c],
                light[0],
                light[1],
                light[2],
                mx,
                my,
                mz,
                chosen,
            )
            normals[r, c, 0] = chosen[0]
            normals[r, c, 1] = chosen[1]
            normals[r, c, 2] = chosen[2]
            done[r, c] = True
            queue[tail] = r * w + c
            tail += 1


def _prepare(image, mask, light, reference, reference_normal, albedo, concave_x, concave_y, gradient_floor):
    """The arguments of :func:`propagate_normals`, checked, and what both versions compute first."""
    image = np.asarray(image, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool)
    if image.ndim != 2 or mask.shape != image.shape:
        raise InputError(
            f"image and mask must both be (H, W) of the same shape, got {image.shape} and {mask.shape}"
        )
    light = np.asarray(light, dtype=np.float64)
    r, c = reference
    if not (0 <= r < mask.shape[0] and 0 <= c < mask.shape[1]) or not mask[r, c]:
        raise InputError(
            f"reference pixel (row {r}, col {c}) is not on the object; pick a pixel inside the mask"
        )
    if albedo <= 0:
        raise InputError("the object is black at the reference; pick a lit reference pixel")
    shape = mask.shape
    cx = np.zeros(shape) if concave_x is None else np.asarray(concave_x, dtype=np.float64)
    cy = np.zeros(shape) if concave_y is None else np.asarray(concave_y, dtype=np.float64)
    cos_t = np.clip(np.where(mask, image / albedo, 0.0), 0.0, 1.0)
    gx, gy = image_gradient(image / albedo, mask)
    return (
        image,
        mask,
        light,
        (int(r), int(c)),
        reference_normal,
        cos_t,
        gx,
        gy,
        cx,
        cy,
        float(gradient_floor),
    )


def propagate_normals(
    image,
    mask,
    *,
    light,
    reference,
    reference_normal=None,
    albedo,
    concave_x=None,
    concave_y=None,
    gradient_floor=1e-6,
):
    """Grow a normal field over the mask from one reference pixel (compiled).

    Parameters
    ----------
    image : (H, W) float
        Shading image (one channel, already filtered).
    mask : (H, W) bool
        Object pixels; the field grows over its 4-connected component holding the reference.
    light : (3,) float
        Unit vector toward the light.
    reference : (int, int)
        (row, col) of the reference pixel.
    reference_normal : (3,) float, optional
        Its normal; by default the cone normal the rule itself chooses there (which is ``light``
        at a pixel as bright as ``albedo``).
    albedo : float
        ``k * albedo`` of the image model: the brightness of a pixel facing the light.
    concave_x, concave_y : (H, W) bool, optional
        Where the user marked the surface concave along x / y.
    gradient_floor : float
        Gradient magnitude (in units of ``albedo`` per pixel) below which the gradient's direction is
        not trusted and neighbours decide.

    Returns
    -------
    normals : (H, W, 3) float64
        Unit normals; NaN outside the mask and on mask pixels not connected to the reference.
    """
    image, mask, light, (r, c), reference_normal, cos_t, gx, gy, cx, cy, g_min = _prepare(
        image, mask, light, reference, reference_normal, albedo, concave_x, concave_y, gradient_floor
    )
    seed = np.empty(3)
    if reference_normal is None:
        _choose_normal(
            cos_t[r, c], gx[r, c], gy[r, c], g_min, cx[r, c], cy[r, c], *light, 0.0, 0.0, 0.0, seed
        )
    else:
        seed[:] = reference_normal
    normals = np.full(mask.shape + (3,), np.nan)
    done = np.zeros(mask.shape, dtype=bool)
    queue = np.empty(mask.size, dtype=np.int64)
    _propagate_kernel(cos_t, gx, gy, g_min, mask, cx, cy, light, r, c, seed, normals, done, queue)
    return normals


def propagate_normals_reference(image, mask, **options):
    """Slow, plain-Python version of :func:`propagate_normals` (same arguments and result).

    Written for clarity, to test the compiled kernel against; use only on small images.
    """
    # the compiled version's signature checks the arguments and gives the defaults
    given = inspect.signature(propagate_normals).bind(image, mask, **options)
    given.apply_defaults()
    image, mask, light, (r, c), reference_normal, cos_t, gx, gy, cx, cy, g_min = _prepare(**given.arguments)
    choose = _choose_normal.py_func
    h, w = mask.shape
    normals = np.full((h, w, 3), np.nan)
    done = np.zeros((h, w), dtype=bool)
    if reference_normal is None:
        seed = np.empty(3)
        choose(cos_t[r, c], gx[r, c], gy[r, c], g_min, cx[r, c], cy[r, c], *light, 0.0, 0.0, 0.0, seed)
    else:
        seed = np.asarray(reference_normal, dtype=np.float64)
    normals[r, c] = seed
    done[r, c] = True
    queue = deque([(r, c)])
    while queue:
        r0, c0 = queue.popleft()
        for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            rr, cc = r0 + dr, c0 + dc
            if not (0 <= rr < h and 0 <= cc < w) or done[rr, cc] or not mask[rr, cc]:
                continue
            window = (slice(max(rr - 1, 0), rr + 2), slice(max(cc - 1, 0), cc + 2))
            known = normals[window][done[window]]
            mean = known.sum(axis=0) if len(known) else np.zeros(3)
            out = np.empty(3)
            choose(cos_t[rr, cc], gx[rr, cc], gy[rr, cc], g_min, cx[rr, cc], cy[rr, cc], *light, *mean, out)
            normals[rr, cc] = out
            done[rr, cc] = True
            queue.append((rr, cc))
    return normals


def project_to_cone(normals: np.ndarray, cos_theta: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Closest normals on each pixel's shading cone: keep the tilt direction around ``light``.

    Parameters
    ----------
    normals : (H, W, 3) float
    cos_theta : (H, W) float
        ``N . L`` required by the brightness, in [0, 1].
    light : (3,) float

    Returns
    -------
    (H, W, 3) float64 unit normals with ``N . L == cos_theta``; where a normal is parallel to
    the light its tilt is undefined and the light itself is returned (tilted by theta along x).
    """
    along = normals @ light
    tilt = normals - along[..., None] * light
    norm = np.linalg.norm(tilt, axis=-1, keepdims=True)
    tilt = np.divide(tilt, norm, out=np.zeros_like(tilt), where=norm > 1e-12)
    sin_theta = np.sqrt(np.clip(1.0 - cos_theta**2, 0.0, 1.0))
    return cos_theta[..., None] * light + sin_theta[..., None] * tilt


def refine_by_integrability(
    normals: np.ndarray, cos_theta: np.ndarray, mask: np.ndarray, *, light: np.ndarray, iterations: int = 3
) -> np.ndarray:
    """Correct the tilt directions of a propagated field so that it becomes integrable.

    The 2002 rule takes each normal's tilt from the intensity gradient, which is exact on surfaces
    of revolution but off by a few degrees where the curvature differs between directions
    (the gradient of ``I`` is the Hessian times the slope, not the slope). Each iteration
    integrates the field by least squares (steep pixels weighted down by ``n_z**4``), takes the
    tilt of the integrated surface, and puts it back on the shading cone, which the brightness
    fixes. It alternates projections between the integrable fields and the fields that explain
    the image (in the spirit of Horn & Brooks 1986).

    Parameters
    ----------
    normals : (H, W, 3) float
        Field from :func:`propagate_normals`; NaN outside ``mask``.
    cos_theta : (H, W) float
        ``I / albedo`` clipped to [0, 1].
    mask : (H, W) bool
    light : (3,) float
    iterations : int

    Returns
    -------
    (H, W, 3) float64, NaN outside the mask.
    """
    from shadeform.integration.poisson import poisson_integrator

    mask = mask & np.isfinite(normals[..., 0])
    field = np.where(mask[..., None], normals, np.nan)
    # steep pixels carry the least reliable slopes; the weights stay fixed so the multigrid
    # set-up is done once
    integrate = poisson_integrator(mask, weights=np.clip(np.nan_to_num(field[..., 2]), 0, 1) ** 4)
    for _ in range(iterations):
        d_row, d_col = np.gradient(integrate(field))  # NaN next to the silhouette: those keep theirs
        surface = np.stack([-d_col, d_row, np.ones_like(d_row)], axis=-1)  # (-z_x, -z_y, 1)
        ok = mask & np.isfinite(surface).all(axis=-1)
        field[ok] = project_to_cone(surface[ok], cos_theta[ok], light)
    return field


def solve(problem: Problem) -> Solution:
    """The 2002 route as a registered solver: a field per reference, integrated from it by
    ``problem.integrator``, references combined by the report's eq. 7.

    Each connected part of the mask is solved from its own references; with several references
    per part, reference J's depths are moved into the main reference's frame by ``Z_MJ``, the main
    reference's depth at J's origin, and the fields and depths averaged.
    """
    mask, labels = problem.mask, problem.labels
    cos_theta = problem.cos_theta if problem.refine else None
    normals_sum = np.zeros(mask.shape + (3,))
    depth_sum = np.zeros(mask.shape)
    depth_count = np.zeros(mask.shape)
    for part in range(1, problem.parts + 1):
        part_mask = labels == part
        depth_main = None
        for ref in (ref for ref in problem.references if labels[ref.pixel] == part):
            field = propagate_normals(
                problem.image,
                part_mask,
                light=problem.light,
                reference=ref.pixel,
                reference_normal=ref.normal,
                albedo=problem.albedo,
                concave_x=problem.concave_x,
                concave_y=problem.concave_y,
            )
            problem.lap("normals")
            if problem.refine:
                field = refine_by_integrability(
                    field, cos_theta, part_mask, light=problem.light, iterations=problem.refine
                )
                problem.lap("refine")
            depth = problem.integrate(field, part_mask, origin=ref.pixel)
            problem.lap("depth")
            if depth_main is None:
                depth_main = depth
            depth_sum[part_mask] += depth[part_mask] + depth_main[ref.pixel]
            depth_count[part_mask] += 1
            normals_sum[part_mask] += field[part_mask]
    if len(problem.references) > 1:
        normals_sum /= np.linalg.norm(normals_sum, axis=-1, keepdims=True).clip(1e-300)
        depth_sum /= np.maximum(depth_count, 1)
    return Solution(normals_sum, depth_sum, {"refine": problem.refine})
