"""Error measures between a reconstruction and its ground truth.

A method that leaves holes must not look better than one that fills them: wherever the
evaluated region contains an estimate that is NaN (or a zero normal), the summary error is
``inf``. The evaluated region defaults to where the ground truth is finite.

References
----------
.. [1] R. Zhang, P.-S. Tsai, J. E. Cryer and M. Shah, "Shape from shading: a survey",
   IEEE Trans. PAMI 21(8), 690-706, 1999 (depth and gradient errors on synthetic scenes).
.. [2] B. Shi, Z. Mo, Z. Wu, D. Duan, S.-K. Yeung and P. Tan, "A benchmark dataset and
   evaluation for non-Lambertian and uncalibrated photometric stereo", IEEE Trans. PAMI
   41(2), 271-284, 2019 (DiLiGenT: mean angular error, and mean absolute depth error).
.. [3] A. Knapitsch, J. Park, Q.-Y. Zhou and V. Koltun, "Tanks and Temples: benchmarking
   large-scale scene reconstruction", ACM Trans. Graphics 36(4), 2017 (F-score of surfaces).

Surfaces (complete models fused from several views) are compared as point sets sampled on them:
:func:`chamfer` and :func:`f_score` in percent of the true bounding-box diagonal, after the
translation a reconstruction cannot fix; :func:`volume_error` for closed meshes.
"""

from __future__ import annotations

import numbers

import numpy as np

from shadeform.errors import InputError

_REDUCTIONS = ("mean", "median", "none")
_FITS = ("none", "offset", "scale", "scale_offset", "median_scale")


def normals_of_height(depth: np.ndarray) -> np.ndarray:
    """Unit normals of a height map by central differences (one-sided at the frame, ``np.gradient``).

    ``n ~ (-dz/dcol, +dz/drow, 1)`` (``docs/conventions.md``: x = column, y = -row): how ground
    truths given as depth (MIT-Berkeley's ``Z.mat``, generated objects) are compared as normals.

    Parameters
    ----------
    depth : (H, W) float
        Height in pixels; NaN where unknown (its neighbours' normals are NaN too).

    Returns
    -------
    (H, W, 3) float64
    """
    d_row, d_col = np.gradient(np.asarray(depth, dtype=np.float64))
    normals = np.dstack([-d_col, d_row, np.ones_like(d_row)])
    return normals / np.linalg.norm(normals, axis=-1, keepdims=True)


def angular_error(normals, normals_true, mask=None, *, reduce: str = "mean"):
    """Angle between estimated and true normals, in degrees.

    The angle is ``atan2(|a x b|, a . b)``, exact for tiny and near-180 degree angles (no
    ``arccos`` of a dot product that rounding pushed past 1) and independent of the vectors'
    lengths.

    Parameters
    ----------
    normals : (H, W, 3) array_like
        Estimated normals.
    normals_true : (H, W, 3) array_like
        Ground-truth normals; must be finite in ``mask``.
    mask : (H, W) array_like of bool, optional
        Pixels to evaluate. Default: where ``normals_true`` is finite.
    reduce : {"mean", "median", "none"}, optional
        Summary over the mask, or ``"none"`` for the per-pixel map.

    Returns
    -------
    float or (H, W) float64
        Mean (or median) angle in degrees, ``inf`` if an estimate in the mask is NaN, inf or
        zero; with ``reduce="none"`` the map of angles, NaN outside the mask and where the
        estimate is invalid.

    Raises
    ------
    InputError
        Shapes that differ or are not (H, W, 3), an empty mask, NaN ground truth inside the
        mask, or an unknown ``reduce``.

    References
    ----------
    .. [1] B. Shi et al., "A benchmark dataset and evaluation for non-Lambertian and
       uncalibrated photometric stereo", IEEE Trans. PAMI 41(2), 2019.
    """
    if reduce not in _REDUCTIONS:
        raise InputError(f"reduce must be one of {', '.join(_REDUCTIONS)}; got {reduce!r}")
    a = np.asarray(normals, dtype=np.float64)
    b = np.asarray(normals_true, dtype=np.float64)
    if a.ndim != 3 or a.shape[-1] != 3 or a.shape != b.shape:
        raise InputError(f"normals must both have shape (H, W, 3), got {a.shape} and {b.shape}")
    mask = _region(mask, b, a.shape[:2], "normals")
    est, ref = a[mask], b[mask]
    valid = np.isfinite(est).all(axis=-1) & np.any(est != 0, axis=-1)
    with np.errstate(invalid="ignore"):
        cross = np.linalg.norm(np.cross(est, ref), axis=-1)
        dot = np.einsum("ij,ij->i", est, ref)
        angles = np.degrees(np.arctan2(cross, dot))
    if reduce == "none":
        out = np.full(mask.shape, np.nan)
        out[mask] = np.where(valid, angles, np.nan)
        return out
    if not valid.all():
        return float("inf")
    return float(np.mean(angles) if reduce == "mean" else np.median(angles))


def depth_error(depth, depth_true, mask=None, *, fit: str = "offset") -> float:
    """Root-mean-square depth error as a percent of the true depth range.

    Orthographic shape from shading fixes depth only up to an additive constant, so by default
    the estimate is first shifted by the least-squares offset (the mean difference).

    Parameters
    ----------
    depth : (H, W) array_like
        Estimated depth.
    depth_true : (H, W) array_like
        Ground-truth depth; must be finite in ``mask`` and not constant there.
    mask : (H, W) array_like of bool, optional
        Pixels to evaluate. Default: where ``depth_true`` is finite.
    fit : {"offset", "scale_offset", "scale", "median_scale", "none"}, optional
        Free parameters fitted before measuring: by least squares ``depth + b``,
        ``a * depth + b``, ``a * depth``; ``a * depth`` with ``a`` the median of
        ``depth_true / depth``; or nothing.

    Returns
    -------
    float
        ``100 * RMSE / (max - min of depth_true over the mask)``; ``inf`` if an estimated depth
        in the mask is NaN or inf (a method that leaves holes fails).

    Raises
    ------
    InputError
        Shapes that differ or are not (H, W), an empty mask, NaN or constant ground truth in
        the mask, or an unknown ``fit``.

    References
    ----------
    .. [1] R. Zhang et al., "Shape from shading: a survey", IEEE Trans. PAMI 21(8), 1999.
    """
    estimate, truth = _depth_pair(depth, depth_true, mask, fit)
    if estimate is None:
        return float("inf")
    spread = float(truth.max() - truth.min())
    if spread == 0:
        raise InputError(
            "true depth is constant over the mask, so a percent of its range is undefined; "
            "evaluate on a region where it varies"
        )
    residual = _fitted(estimate, truth, fit) - truth
    return float(100.0 * np.sqrt(np.mean(residual * residual)) / spread)


def made(depth, depth_true, mask=None, *, fit: str = "scale") -> float:
    """Mean absolute depth error, in the units of ``depth_true``.

    Used for perspective benchmarks such as DiLiGenT, whose depths are known up to a scale.

    Parameters
    ----------
    depth : (H, W) array_like
        Estimated depth.
    depth_true : (H, W) array_like
        Ground-truth depth; must be finite in ``mask``.
    mask : (H, W) array_like of bool, optional
        Pixels to evaluate. Default: where ``depth_true`` is finite.
    fit : {"scale", "median_scale", "offset", "scale_offset", "none"}, optional
        Free parameters fitted before measuring: by least squares ``a * depth``,
        ``depth + b``, ``a * depth + b``; ``a * depth`` with ``a`` the median of
        ``depth_true / depth`` (the protocol of BiNI's DiLiGenT evaluation [2]_, which its
        published figures use); or nothing.

    Returns
    -------
    float
        ``mean |fitted depth - depth_true|`` over the mask; ``inf`` if an estimated depth in
        the mask is NaN or inf.

    Raises
    ------
    InputError
        Shapes that differ or are not (H, W), an empty mask, NaN ground truth in the mask, or
        an unknown ``fit``.

    References
    ----------
    .. [1] B. Shi et al., "A benchmark dataset and evaluation for non-Lambertian and
       uncalibrated photometric stereo", IEEE Trans. PAMI 41(2), 2019.
    .. [2] X. Cao, H. Santo, B. Shi, F. Okura, Y. Matsushita, "Bilateral Normal Integration",
       ECCV 2022 (its evaluation script scales the estimate by the median depth ratio).
    """
    estimate, truth = _depth_pair(depth, depth_true, mask, fit)
    if estimate is None:
        return float("inf")
    return float(np.mean(np.abs(_fitted(estimate, truth, fit) - truth)))


def _region(mask, truth, shape, what: str) -> np.ndarray:
    """The evaluated pixels: ``mask`` checked against the ground truth, or its finite part."""
    if truth.ndim == 3:  # normals: a zero vector has no direction either
        finite = np.isfinite(truth).all(axis=-1) & np.any(truth != 0, axis=-1)
        bad = "NaN, inf or zero"
    else:
        finite = np.isfinite(truth)
        bad = "NaN or inf"
    if mask is None:
        region = finite
    else:
        region = np.asarray(mask)
        if region.shape != shape:
            raise InputError(f"mask shape {region.shape} does not match {what} shape {shape}")
        region = region.astype(bool)
        if not finite[region].all():
            raise InputError(f"true {what} are {bad} inside the mask; pass a mask within the ground truth")
    if not region.any():
        raise InputError(f"no pixels to evaluate: the mask or the true {what} selects none")
    return region


def _depth_pair(depth, depth_true, mask, fit):
    """Validated ``(estimate, truth)`` values inside the region, estimate None if not finite."""
    if fit not in _FITS:
        raise InputError(f"fit must be one of {', '.join(_FITS)}; got {fit!r}")
    d = np.asarray(depth, dtype=np.float64)
    t = np.asarray(depth_true, dtype=np.float64)
    if d.ndim != 2 or d.shape != t.shape:
        raise InputError(f"depths must both have shape (H, W), got {d.shape} and {t.shape}")
    region = _region(mask, t, d.shape, "depth")
    estimate = d[region]
    if not np.isfinite(estimate).all():
        return None, t[region]
    return estimate, t[region]


def _fitted(estimate, truth, fit):
    """``estimate`` after the fit of its free parameters to ``truth``."""
    if fit == "offset":
        return estimate + np.mean(truth - estimate)
    if fit == "scale":
        energy = float(np.dot(estimate, estimate))
        # An all-zero estimate has no scale to fit; it stays zero.
        return estimate * (np.dot(estimate, truth) / energy if energy > 0 else 0.0)
    if fit == "median_scale":
        nonzero = estimate != 0
        # Only the pixels with a defined ratio vote; an all-zero estimate stays zero.
        return estimate * (np.median(truth[nonzero] / estimate[nonzero]) if nonzero.any() else 0.0)
    if fit == "scale_offset":
        design = np.column_stack([estimate, np.ones_like(estimate)])
        coef, *_ = np.linalg.lstsq(design, truth, rcond=None)
        return design @ coef
    return estimate


#: The F-score's default distance threshold, a fraction of the true diagonal (Tanks and Temples' 1 %).
F_SCORE_THRESHOLD = 0.01


def chamfer(points, points_true, *, translate: bool = True) -> float:
    """Symmetric Chamfer distance between two point sets, in % of the true bounding-box diagonal.

    The mean distance from each point to its nearest true point and the mean distance from each
    true point to its nearest point, averaged: ``(mean_i d(a_i, B) + mean_j d(b_j, A)) / 2``.
    With ``translate`` the points are first moved by the translation found by translation-only
    ICP [2]_ (least squares over both directions' nearest-neighbour pairs), started from no shift
    and from the offset of the centroids, keeping the better end: a reconstruction from
    orthographic views fixes no depth offset, and the result should not punish it.

    Parameters
    ----------
    points : (N, 3) array_like
        Reconstructed surface samples (e.g. a mesh's vertices or points sampled on it).
    points_true : (M, 3) array_like
        Ground-truth surface samples (e.g. :meth:`shadeform.synth.ClosedObject.surface_points`),
        not all equal.
    translate : bool, optional
        Fit the free translation first (default), or compare in place.

    Returns
    -------
    float
        ``100 * chamfer / diagonal``, the diagonal of the axis-aligned box of ``points_true``.

    Raises
    ------
    InputError
        Arrays not (N, 3), empty or not finite, or true points that span no box.

    References
    ----------
    .. [1] H. G. Barrow, J. M. Tenenbaum, R. C. Bolles and H. C. Wolf, "Parametric
       correspondence and chamfer matching", IJCAI 1977.
    .. [2] P. J. Besl and N. D. McKay, "A method for registration of 3-D shapes", IEEE Trans.
       PAMI 14(2), 239-256, 1992.

    Examples
    --------
    >>> cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    >>> chamfer(cube + 5.0, cube)
    0.0
    """
    est, ref, diagonal = _point_sets(points, points_true)
    forward, backward, _ = _registered(est, ref, translate)
    return _chamfer(forward, backward, diagonal)


def _chamfer(forward, backward, diagonal: float) -> float:
    """:func:`chamfer` from the nearest distances both ways."""
    return float(100.0 * 0.5 * (forward.mean() + backward.mean()) / diagonal)


def f_score(points, points_true, *, threshold: float = F_SCORE_THRESHOLD, translate: bool = True) -> float:
    """F-score of two point sets at a distance threshold, in % (Tanks and Temples [1]_).

    Precision is the share of points within ``threshold * diagonal`` of a true point, recall
    the share of true points within that distance of a point; the F-score is their harmonic
    mean, ``2 P R / (P + R)`` (0 when both are 0). The diagonal is that of the true points'
    axis-aligned bounding box; with ``translate`` the points are first moved by the same
    translation as :func:`chamfer` finds.

    Parameters
    ----------
    points : (N, 3) array_like
        Reconstructed surface samples.
    points_true : (M, 3) array_like
        Ground-truth surface samples, not all equal.
    threshold : float, optional
        Distance threshold as a fraction of the diagonal, > 0 (1 % by default).
    translate : bool, optional
        Fit the free translation first (default), or compare in place.

    Returns
    -------
    float
        F-score in percent, in [0, 100].

    Raises
    ------
    InputError
        Bad point arrays (see :func:`chamfer`) or a threshold that is not a positive number.

    References
    ----------
    .. [1] A. Knapitsch, J. Park, Q.-Y. Zhou and V. Koltun, "Tanks and Temples: benchmarking
       large-scale scene reconstruction", ACM Trans. Graphics 36(4), 2017.

    Examples
    --------
    >>> cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    >>> f_score(cube, cube)
    100.0
    """
    if isinstance(threshold, bool) or not isinstance(threshold, numbers.Real):
        raise InputError(
            f"threshold must be a positive number (a fraction of the diagonal), got {threshold!r}"
        )
    if not (np.isfinite(threshold) and threshold > 0):
        raise InputError(
            f"threshold must be a positive number (a fraction of the diagonal), got {threshold!r}"
        )
    est, ref, diagonal = _point_sets(points, points_true)
    forward, backward, _ = _registered(est, ref, translate)
    return _f_score(forward, backward, float(threshold) * diagonal)


def _f_score(forward, backward, tolerance: float) -> float:
    """:func:`f_score` from the nearest distances both ways and the distance threshold."""
    precision = float(np.mean(forward < tolerance))
    recall = float(np.mean(backward < tolerance))
    if precision + recall == 0:
        return 0.0
    return float(100.0 * 2.0 * precision * recall / (precision + recall))


def volume_error(mesh_or_volume, volume_true, *, signed: bool = False) -> float:
    """Relative error of a closed mesh's volume, in %.

    The volume of a closed, consistently wound triangle mesh is the divergence-theorem sum
    ``|sum over faces of det(v0, v1, v2)| / 6`` (either winding gives the same magnitude).

    Parameters
    ----------
    mesh_or_volume : Mesh, trimesh.Trimesh or float
        Anything with ``vertices`` (V, 3) and ``faces`` (F, 3) (:class:`shadeform.mesh.Mesh`,
        a trimesh), closed: every edge shared by exactly two faces, wound consistently; or the
        volume itself.
    volume_true : float
        The true volume, > 0, in the same units cubed
        (e.g. :attr:`shadeform.synth.ClosedObject.volume`).
    signed : bool, optional
        Return the signed error (positive: too large) instead of its magnitude.

    Returns
    -------
    float
        ``100 * |V - volume_true| / volume_true`` (signed with ``signed=True``).

    Raises
    ------
    InputError
        A mesh that is not closed or not consistently wound, bad faces, or a volume that is
        not a positive finite number.

    Examples
    --------
    >>> tetra = type("T", (), {"vertices": np.eye(4, 3, k=-1), "faces": [[0, 2, 1], [0, 1, 3],
    ...                                                                  [0, 3, 2], [1, 2, 3]]})
    >>> round(volume_error(tetra, 1 / 6), 12)
    0.0
    """
    volume_true = _positive_volume(volume_true, "volume_true")
    if hasattr(mesh_or_volume, "vertices") and hasattr(mesh_or_volume, "faces"):
        volume = _mesh_volume(mesh_or_volume.vertices, mesh_or_volume.faces)
    else:
        volume = _positive_volume(mesh_or_volume, "volume")
    error = 100.0 * (volume - volume_true) / volume_true
    return float(error if signed else abs(error))


def surface_scores(mesh, points_true, volume_true, *, samples: int = 50_000, seed: int = 0) -> dict:
    """A closed mesh scored against a true surface: Chamfer, F-score, volume error, closedness.

    Points are sampled uniformly by area on the mesh (trimesh) and compared with points on the
    true surface. Point samplings have a floor: a surface against a sampling of itself scores
    about 0.17 % Chamfer with 50,000 points against 200,000, 0.57 % with 8,000 a side, so give
    the true surface densely.

    Parameters
    ----------
    mesh : Mesh or trimesh.Trimesh
        The model, closed.
    points_true : (M, 3) float
        Points on the true surface (e.g. :meth:`shadeform.synth.ClosedObject.surface_points`).
    volume_true : float
        The true volume.
    samples, seed : int
        Points sampled on the mesh, and the sampling's seed.

    Returns
    -------
    dict
        ``chamfer`` (% of the diagonal, :func:`chamfer`), ``f_score`` (% at 1 % of the
        diagonal, :func:`f_score`), ``volume_error`` (%, signed: positive is too large) and
        ``watertight`` (bool: closed, consistently wound, positive volume).
    """
    import trimesh

    solid = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    points = trimesh.sample.sample_surface(solid, int(samples), seed=seed)[0]
    closed = bool(solid.is_watertight and solid.is_winding_consistent and solid.volume > 0)
    # one registration for both scores: chamfer and f_score each fit the same translation
    est, ref, diagonal = _point_sets(points, points_true)
    forward, backward, _ = _registered(est, ref, True)
    return {
        "chamfer": _chamfer(forward, backward, diagonal),
        "f_score": _f_score(forward, backward, F_SCORE_THRESHOLD * diagonal),
        "volume_error": volume_error(solid, volume_true, signed=True) if closed else float("nan"),
        "watertight": closed,
    }


def _point_sets(points, points_true):
    """Validated float64 ``(N, 3)`` and ``(M, 3)`` arrays and the true bounding-box diagonal."""
    sets = []
    for what, value in (("points", points), ("points_true", points_true)):
        try:
            array = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(
                f"{what} must be an (N, 3) array of numbers, got {type(value).__name__}"
            ) from None
        if array.ndim != 2 or array.shape[1] != 3 or array.shape[0] == 0:
            raise InputError(f"{what} must be a non-empty (N, 3) array, got shape {array.shape}")
        if not np.isfinite(array).all():
            raise InputError(f"{what} contain NaN or inf; drop those points first")
        sets.append(array)
    est, ref = sets
    diagonal = float(np.linalg.norm(ref.max(axis=0) - ref.min(axis=0)))
    if diagonal == 0:
        raise InputError("points_true are all the same point; their bounding box has no diagonal")
    return est, ref, diagonal


#: Points of each set the translation is fitted on (evenly strided); the distances use all.
REGISTRATION_POINTS = 10_000


def _registered(est, ref, translate: bool, iterations: int = 100):
    """Nearest distances both ways after the best translation of ``est``, and that translation.

    The translation is fitted on at most :data:`REGISTRATION_POINTS` of each set (it is a mean
    over thousands of pairs, which a subset gives as well), the distances use every point."""
    from scipy.spatial import cKDTree

    def distances(est, ref, shift, trees):
        forward, to_ref = trees[0].query(est + shift)
        backward, to_est = trees[1].query(ref - shift)
        return forward, backward, to_ref, to_est

    full = (cKDTree(ref), cKDTree(est))
    if not translate:
        forward, backward, _, _ = distances(est, ref, np.zeros(3), full)
        return forward, backward, np.zeros(3)
    sub_est = est[:: max(1, len(est) // REGISTRATION_POINTS)]
    sub_ref = ref[:: max(1, len(ref) // REGISTRATION_POINTS)]
    trees = (cKDTree(sub_ref), cKDTree(sub_est))
    scale = float(np.linalg.norm(ref.max(axis=0) - ref.min(axis=0)))
    best = None
    for shift in (np.zeros(3), ref.mean(axis=0) - est.mean(axis=0)):
        for _ in range(iterations):
            forward, backward, to_ref, to_est = distances(sub_est, sub_ref, shift, trees)
            # Least-squares translation for these pairs: the mean of (true - estimate) over both.
            update = (
                sub_ref[to_ref].sum(axis=0)
                - sub_est.sum(axis=0)
                + sub_ref.sum(axis=0)
                - sub_est[to_est].sum(axis=0)
            ) / (sub_est.shape[0] + sub_ref.shape[0])
            moved = float(np.linalg.norm(update - shift))
            shift = update
            if moved <= 1e-9 * scale:
                break
        forward, backward, _, _ = distances(est, ref, shift, full)
        score = forward.mean() + backward.mean()
        if best is None or score < best[0]:
            best = (score, forward, backward, shift)
    return best[1], best[2], best[3]


def _positive_volume(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not np.isfinite(value) or value <= 0:
        raise InputError(f"{what} must be a positive finite number, got {value!r}")
    return float(value)


def _mesh_volume(vertices, faces) -> float:
    """Enclosed volume of a closed, consistently wound triangle mesh (divergence theorem)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    if (
        vertices.ndim != 2
        or vertices.shape[1] != 3
        or faces.ndim != 2
        or faces.shape[1] != 3
        or not len(faces)
    ):
        raise InputError(
            f"mesh must have (V, 3) vertices and (F, 3) faces, got {vertices.shape} and {faces.shape}"
        )
    if not np.issubdtype(faces.dtype, np.integer) or faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError(f"mesh faces must be vertex indices in [0, {len(vertices)})")
    if not np.isfinite(vertices).all():
        raise InputError("mesh vertices contain NaN or inf; the volume is undefined")
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]).astype(np.int64)
    # each edge as one integer key: a 1-D unique sorts ten times faster than rows (axis=0)
    undirected = np.sort(directed, axis=1)
    _, uses = np.unique(undirected[:, 0] * len(vertices) + undirected[:, 1], return_counts=True)
    if np.any(uses != 2):
        raise InputError(
            f"mesh is not closed ({int(np.sum(uses != 2))} edges are not shared by exactly two faces); "
            "its volume is undefined"
        )
    if len(np.unique(directed[:, 0] * len(vertices) + directed[:, 1])) != len(directed):
        raise InputError("mesh faces are not wound consistently; fix their orientation first")
    v0, v1, v2 = (vertices[faces[:, k]] for k in range(3))
    return float(abs(np.einsum("ij,ij->i", v0, np.cross(v1, v2)).sum()) / 6.0)
