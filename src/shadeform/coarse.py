"""Reconstructions on a coarser grid than the photo's: every ``step``-th row and column solved
alone, or a pyramid level of averaged blocks.

:func:`reconstruct_on_grid` solves the grid for what will only be seen on it (a relief's
budget, :func:`shadeform.solid.grid_step`); :func:`reconstruct_preview` places that solve back
on the input's pixels as the quick look of a mesh, and :func:`preview_step` sizes its grid to
the solver's budget. :func:`reconstruct_on_level` is a large photo's quick look, solved on its
pyramid level (the user's filter, references and regions carried there). They call :func:`shadeform.pipeline.reconstruct`, which knows nothing of
them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from scipy import ndimage as ndi

# reconstruct is called as pipeline.reconstruct, looked up at each call as it was when these lived
# there (a patched one, e.g. a test's, is the one used)
from shadeform import pipeline
from shadeform._checks import whole
from shadeform._deprecated import renamed_keywords
from shadeform.errors import InputError
from shadeform.light import as_light
from shadeform.masks import FoundObject, find_object
from shadeform.pipeline import MIN_SIDE, _check_image, _check_shading, _object, _parse_reference
from shadeform.preprocess import Filter, parse_filter
from shadeform.reconstruction import Reconstruction
from shadeform.regions import Region, as_regions
from shadeform.solvers import AUTO, choose, get_solver

__all__ = ["preview_step", "reconstruct_on_grid", "reconstruct_on_level", "reconstruct_preview"]


def reconstruct_on_grid(
    image: np.ndarray,
    *,
    step: int,
    mask: np.ndarray | FoundObject | None = None,
    filter: str | None = None,
    references: Sequence | None = None,
    concave: Any = None,
    **options: Any,
) -> Reconstruction:
    """The reconstruction of the image's grid: every ``step``-th row and column, solved alone.

    ``step**2`` times fewer pixels than :func:`reconstruct`, for what will only be seen on that
    grid anyway: the quick look of a mesh of that step (:func:`reconstruct_preview`), a relief
    whose triangle budget samples the surface that coarsely (:func:`shadeform.solid.grid_step`).
    The image is sampled, not averaged: an average flattens the narrow bright ridges where the
    eikonal solver finds its singular points (the vase's rim); a bright cap that falls between
    grid points (a singular point on a thin rim or on the object's top row) is kept at the nearest
    grid point, so the solvers still start from it. Filter sizes, references and concave regions
    are carried to the grid. Features narrower than the grid are lost.

    Parameters
    ----------
    image : (H, W) float array
        As for :func:`reconstruct`.
    step : int, keyword-only
        Grid spacing in pixels, ``>= 1`` (1 is :func:`reconstruct`).
    mask, filter, references, concave
        As for :func:`reconstruct`, in pixels of the input image. A reference whose grid point
        falls off the coarse object moves to the nearest grid point on it.
    **options
        ``light``, ``solver``, ``integrator``, ``refine``: as for :func:`reconstruct`.

    Returns
    -------
    Reconstruction
        Arrays of the grid's shape ``(ceil(H / step), ceil(W / step))``: pixel ``(i, j)`` is the
        input's ``(i * step, j * step)``; depth in grid pixels (input pixels / ``step``). ``info``
        is :func:`reconstruct`'s with ``grid_step``; its references and unsure areas are in
        pixels of the input image, as the user gave them.

    Examples
    --------
    >>> from shadeform import synth
    >>> scene = synth.scene("sphere", size=64)
    >>> reconstruct_on_grid(scene.image, mask=scene.mask, step=2).depth.shape
    (32, 32)
    """
    image = _check_image(image)
    step = whole(step, "step", minimum=1)
    found = mask if isinstance(mask, FoundObject) else None
    mask, warning = _object(image, mask)
    _check_shading(image, mask)
    if step == 1:
        rec = pipeline.reconstruct(
            image, mask=found or mask, filter=filter, references=references, concave=concave, **options
        )
        return replace(rec, info={**rec.info, "grid_step": 1})
    coarse_mask = mask[::step, ::step]
    if not coarse_mask.any():
        raise InputError(f"the object has no pixel on the grid of step {step}; use a smaller step")
    coarse = _keep_caps(image, mask, np.where(coarse_mask, image[::step, ::step], 0.0), coarse_mask, step)

    spec = _scaled_filter(filter, step)  # the filter, scaled to the grid, does the smoothing
    coarse_refs = None
    if references:
        coarse_refs = [_coarse_reference(item, mask, coarse_mask, step) for item in references]
    regions = tuple(Region(region.polygon / step, region.axis) for region in as_regions(concave))
    rec = pipeline.reconstruct(
        coarse, mask=coarse_mask, filter=spec, references=coarse_refs, concave=regions or None, **options
    )
    info = {
        **rec.info,
        **({"mask_warning": warning} if warning else {}),
        "grid_step": step,
        "references": [(r * step, c * step) for r, c in rec.info["references"]],
        "unsure": [  # in input pixels, like the references
            {
                **area,
                "polygon": [[x * step, y * step] for x, y in area["polygon"]],
                "centre": [area["centre"][0] * step, area["centre"][1] * step],
            }
            for area in rec.info["unsure"]
        ],
    }
    return replace(rec, info=info)


def reconstruct_preview(
    image: np.ndarray,
    *,
    step: int,
    mask: np.ndarray | FoundObject | None = None,
    **options: Any,
) -> Reconstruction:
    """A quick look at what ``to_mesh(reconstruct(...), step=step)`` will show.

    The image's grid at the mesh's spacing solved alone (:func:`reconstruct_on_grid`), ``step**2``
    times fewer pixels, and placed back on the input's pixels: interactive tools show this while
    the full-resolution solve runs. Features narrower than the grid are lost until the full result
    replaces the preview.

    Parameters
    ----------
    image : (H, W) float array
        As for :func:`reconstruct`.
    step : int, keyword-only
        The mesh's grid spacing in pixels, ``>= 1`` (1 is the full solve).
    mask : (H, W) bool or FoundObject, keyword-only
        As for :func:`reconstruct`.
    **options
        ``filter``, ``references``, ``concave``, ``light``, ``solver``, ``integrator``,
        ``refine``: as for :func:`reconstruct_on_grid`, in pixels of the input image.

    Returns
    -------
    Reconstruction
        Full-size arrays (H, W): ``mask`` the object mask, ``normals`` and ``depth`` set at the
        grid points ``[::step, ::step]`` inside the mask and NaN elsewhere, so that
        ``to_mesh(preview, step=step)`` has the vertices and triangles of the full result's mesh.
        ``info`` is the coarse solve's, with ``preview_step``; its references are in input
        pixels.

    Examples
    --------
    >>> from shadeform import reconstruct, synth, to_mesh
    >>> scene = synth.scene("sphere", size=64)
    >>> quick = reconstruct_preview(scene.image, mask=scene.mask, step=2)
    >>> to_mesh(quick, step=2).n_vertices == to_mesh(reconstruct(scene.image, mask=scene.mask), step=2).n_vertices
    True
    """
    image = _check_image(image)
    step = whole(step, "step", minimum=1)
    if mask is None:
        mask = find_object(image)  # once, for the grid's solve and the full-size mask
    if step == 1:
        return pipeline.reconstruct(image, mask=mask, **options)
    rec = reconstruct_on_grid(image, step=step, mask=mask, **options)
    mask, _ = _object(image, mask)  # as the grid's solve took it (its warning is in rec.info)
    coarse_mask = rec.mask

    normals = np.full(image.shape + (3,), np.nan)
    depth = np.full(image.shape, np.nan)
    grid_normals = normals[::step, ::step]
    grid_depth = depth[::step, ::step]
    grid_normals[coarse_mask] = rec.normals[coarse_mask]
    grid_depth[coarse_mask] = rec.depth[coarse_mask] * step  # heights in input pixels
    confidence = np.full(image.shape, np.nan)
    confidence[::step, ::step][coarse_mask] = rec.confidence[coarse_mask]
    info = {key: value for key, value in rec.info.items() if key != "grid_step"}
    info["preview_step"] = step
    return Reconstruction(
        normals=normals,
        depth=depth,
        mask=mask,
        light=rec.light,
        albedo=rec.albedo,
        info=info,
        confidence=confidence,
    )


def _keep_caps(image, mask, coarse, coarse_mask, step: int) -> np.ndarray:
    """``coarse`` with every bright cap of ``image`` kept: a cap (the pixels within the eikonal
    solver's tolerance of the object's brightest value, where the eikonal and oblique solvers
    find their singular points) that no grid point samples (the vase's lip on the top row, a thin
    rim) gives its brightest value to the grid point on the object nearest to it. Without it the
    quick look loses that singular point and marches the region from elsewhere (the tests bound
    the vase's and the bumps' quick looks)."""
    from scipy.spatial import cKDTree

    from shadeform.solvers.eikonal import TOL

    peak = float(image[mask].max())
    labels, count = ndi.label(mask & (image >= (1.0 - TOL) * peak), structure=np.ones((3, 3)))
    sampled = np.zeros(count + 1, dtype=bool)
    sampled[labels[::step, ::step][coarse_mask]] = True
    missing = np.flatnonzero(~sampled[1:]) + 1
    if missing.size == 0:
        return coarse
    # the brightest pixel of each missing cap: the last of its pixels sorted by value
    rows, cols = np.nonzero(np.isin(labels, missing))
    owner = labels[rows, cols]
    order = np.lexsort((image[rows, cols], owner))
    last = order[np.r_[owner[order][1:] != owner[order][:-1], True]]
    brightest = np.column_stack([rows[last], cols[last]])
    # the nearest grid point; a search over the object's grid points only where that is off it
    near = np.minimum(np.rint(brightest / step).astype(int), np.array(coarse_mask.shape) - 1)
    off = ~coarse_mask[near[:, 0], near[:, 1]]
    if off.any():
        grid = np.argwhere(coarse_mask)
        near[off] = grid[cKDTree(grid * step).query(brightest[off])[1]]
    out = coarse.copy()
    np.maximum.at(out, (near[:, 0], near[:, 1]), image[brightest[:, 0], brightest[:, 1]])
    return out


@renamed_keywords(method="solver")
def preview_step(mask: np.ndarray, step: int, *, solver: str = "auto", light: Any = (0.0, 0.0, 1.0)) -> int:
    """The grid spacing of a quick look (:func:`reconstruct_preview`) for a mesh of ``step``.

    ``step`` itself, doubled until the object's pixels on the grid fit the solver's budget
    (:attr:`shadeform.solvers.Solver.preview_pixels`); the quick look's mesh is then coarser than the one asked for.

    Parameters
    ----------
    mask : (H, W) bool
        The object.
    step : int
        The mesh's grid spacing in pixels.
    solver : str, keyword-only
        As for :func:`reconstruct`; "auto" is resolved for ``light`` on a clean image.
    light : (3,) float or "estimate", keyword-only
        As for :func:`reconstruct`; an estimated light counts as oblique.

    Returns
    -------
    int
        A multiple of ``step``.
    """
    chosen = (
        choose(None if isinstance(light, str) else as_light(light)) if solver == AUTO else get_solver(solver)
    )
    budget = chosen.preview_pixels
    count = int(np.count_nonzero(mask))
    spacing = max(int(step), 1)
    while count / spacing**2 > budget and min(mask.shape) // (2 * spacing) >= MIN_SIDE:
        spacing *= 2
    return spacing


def _coarse_reference(item, mask, coarse_mask, step):
    """A reference ``(row, col[, normal])`` in input pixels, checked, moved to the coarse grid."""
    r, c, normal = _parse_reference(item, mask)
    height, width = coarse_mask.shape
    cr, cc = min(round(r / step), height - 1), min(round(c / step), width - 1)
    if not coarse_mask[cr, cc]:
        rows, cols = np.nonzero(coarse_mask)
        nearest = np.argmin((rows - r / step) ** 2 + (cols - c / step) ** 2)
        cr, cc = int(rows[nearest]), int(cols[nearest])
    return (cr, cc) if normal is None else (cr, cc, normal)


def reconstruct_on_level(
    level: np.ndarray,
    *,
    factor: int,
    step: int,
    mask: np.ndarray,
    filter: str | Filter | None = None,
    references: Sequence | None = None,
    concave: Any = None,
    **options: Any,
) -> Reconstruction:
    """A large photo's quick look: :func:`reconstruct_preview` of its pyramid level, the photo's
    ``factor`` x ``factor`` blocks averaged, with the user's settings carried to the level.

    Parameters
    ----------
    level : (H // factor, W // factor) float array
        The level's shading image (blocks of the photo averaged, as the caller keeps it).
    factor : int, keyword-only
        The block side, ``>= 1``.
    step : int, keyword-only
        The preview grid's spacing on the level (:func:`preview_step`).
    mask : (h, w) bool, keyword-only
        The object on the level.
    filter, references, concave
        As for :func:`reconstruct`, in pixels of the full photo: the filter's size divided by
        ``factor`` (a median's window rounded, one that is not whole left for :func:`reconstruct`
        to refuse), a reference to the block it falls in (the nearest object pixel where that
        block is off the object; one off the image left for :func:`reconstruct` to refuse),
        regions' vertices divided by ``factor``.
    **options
        ``light``, ``solver``, ``integrator``, ``refine``: as for :func:`reconstruct`.

    Returns
    -------
    Reconstruction
        :func:`reconstruct_preview`'s on the level: arrays of the level's shape, depth in level
        pixels.
    """
    factor = whole(factor, "factor", minimum=1)
    moved = [_level_reference(ref, mask, factor) for ref in references or ()]
    regions = tuple(Region(region.polygon / factor, region.axis) for region in as_regions(concave))
    return reconstruct_preview(
        level,
        step=step,
        mask=mask,
        filter=_scaled_filter(filter, factor),
        references=moved,
        concave=regions or None,
        **options,
    )


def _scaled_filter(filter, factor: int) -> Filter | None:
    """``filter`` (a spec or its text) for pixels ``factor`` times larger: a Gaussian's sigma
    divided, a median's window divided and rounded (one that is not whole left as it is, for
    :func:`reconstruct` to refuse); None where nothing is left of it."""
    spec = parse_filter(filter) if filter else None
    if spec is None or spec.kind == "none" or factor == 1:
        return spec
    if spec.kind != "gaussian" and spec.size != round(spec.size):
        return spec
    size = spec.size / factor if spec.kind == "gaussian" else float(round(spec.size / factor))
    return Filter(spec.kind, size) if size > 0 else None


def _level_reference(ref, mask: np.ndarray, factor: int) -> tuple:
    """A reference ``(row, col[, normal])`` in the photo's pixels moved to the block it falls in
    on the level (the nearest object pixel where that block is off the object); one off the image
    is left as it is, for :func:`reconstruct` to refuse."""
    row, col = min(int(ref[0]) // factor, mask.shape[0] - 1), min(int(ref[1]) // factor, mask.shape[1] - 1)
    if row < 0 or col < 0:
        return tuple(ref)
    if not mask[row, col]:
        rows, cols = np.nonzero(mask)
        nearest = np.argmin((rows - row) ** 2 + (cols - col) ** 2)
        row, col = int(rows[nearest]), int(cols[nearest])
    return (row, col, *ref[2:])
