"""Large photos in the app: a pyramid level for the quick look, meshes sized for the screen, and
photos over the pixel limit downsampled to fit.

A phone photo has 12 Mpx. Everything done on it at full resolution takes seconds (on the 2-core
machine: the automatic mask 1.6 s, the eikonal solve 12 s, its mesh at step 2 a million vertices,
81 MB of base64), so for an image of more than :data:`LARGE_PIXELS` the app

- solves the quick look on a downsampled copy (:func:`level`: the mean of ``k x k`` blocks, at
  most :data:`LEVEL_PIXELS`), whose cost does not grow with the photo; its mesh is scaled back to
  the photo's pixels (:func:`scale_mesh`);
- solves the full resolution in a worker process (:mod:`shadeform.app.jobs`), with progress and
  cancel, and sends a mesh of at most :data:`VIEW_VERTICES` vertices (:func:`view_step`): more
  than a screen shows; the exports keep the step the user chose.

A photo over the server's ``max_pixels`` is offered a downsample to fit (:func:`fit_factor`,
:func:`downsample`), up to :data:`FIT_FACTOR` times the limit; for the full resolution, the CLI's
tiled path (:data:`TILED_COMMAND`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

__all__ = [
    "LARGE_PIXELS",
    "LEVEL_PIXELS",
    "VIEW_VERTICES",
    "FIT_FACTOR",
    "TILED_COMMAND",
    "downsample",
    "level_factor",
    "level",
    "scale_mesh",
    "view_step",
    "fit_factor",
]

#: Images with more pixels than this get the quick look on a pyramid level and the full solve in
#: the background. 2 Mpx: below it the whole quick look (mask, solve at the mesh grid, mesh) took
#: under 0.3 s on the 2-core machine (the 512 px to 1 Mpx app benchmarks), above it the mask
#: alone grows past that (1.6 s at 12 Mpx).
LARGE_PIXELS = 2 * 2**20

#: Most pixels of the level the quick look is solved on: 1 Mpx, whose mask, solve on the
#: solvers' preview grid and mesh take about 0.15 s together (12 Mpx vase, level 4x smaller).
LEVEL_PIXELS = 2**20

#: Most vertices of a mesh sent to the 3D view: more than a 3D pane of about a megapixel shows
#: (one vertex per 4 screen pixels), and what the page uploads to the GPU without a long task.
VIEW_VERTICES = 300_000

#: A photo up to this many times ``max_pixels`` may be downsampled to fit (it is decoded whole
#: first: 12 bytes a pixel for colour); beyond, only the CLI's tiled path takes it.
FIT_FACTOR = 4

#: The CLI command that reconstructs a photo too large for the app at full resolution.
TILED_COMMAND = "shadeform reconstruct PHOTO --tiles auto"


def downsample(values: np.ndarray, factor: int) -> np.ndarray:
    """The mean of each ``factor x factor`` block of ``values`` (H, W, ...), the last blocks padded
    with their edge: shape ``(ceil(H / factor), ceil(W / factor), ...)``; block ``(i, j)`` covers
    input pixels ``[i * factor, (i + 1) * factor)``. ``factor`` 1 returns ``values``."""
    if factor == 1:
        return values
    rows, cols = values.shape[:2]
    pad = ((0, -rows % factor), (0, -cols % factor)) + ((0, 0),) * (values.ndim - 2)
    padded = np.pad(values, pad, mode="edge") if any(p[1] for p in pad) else values
    blocks = padded.reshape(
        padded.shape[0] // factor, factor, padded.shape[1] // factor, factor, *values.shape[2:]
    )
    return blocks.mean(axis=(1, 3), dtype=np.float32 if values.dtype == np.float32 else None)


def level_factor(shape: tuple[int, ...]) -> int:
    """The block side of the quick look's level for an image of ``shape``: 1 up to
    :data:`LARGE_PIXELS`, else the smallest that leaves at most :data:`LEVEL_PIXELS`."""
    pixels = shape[0] * shape[1]
    if pixels <= LARGE_PIXELS:
        return 1
    return max(2, math.ceil(math.sqrt(pixels / LEVEL_PIXELS)))


def level(image: np.ndarray, mask: np.ndarray | None, factor: int) -> tuple[np.ndarray, np.ndarray | None]:
    """One channel (H, W) and its mask (or None) at the level of ``factor``: block means, a block
    being object where at least half its pixels are."""
    small = downsample(image, factor)
    small_mask = None if mask is None else downsample(mask.astype(np.float32), factor) >= 0.5
    return small, small_mask


def scale_mesh(mesh, factor: int):
    """A mesh made on a level of ``factor`` in the photo's pixels: a level pixel is the centre of
    its block, depth scaled alike (the texture coordinates are already fractions of the image)."""
    if factor == 1:
        return mesh
    centre = (factor - 1) / 2
    vertices = mesh.vertices * factor + np.array([centre, -centre, 0.0])
    return replace(mesh, vertices=vertices)


def scale_pixel(pixel, factor: int) -> tuple[int, int]:
    """A level's pixel ``(row, col)`` as the photo's pixel at its block's centre."""
    return tuple(int(v) * factor + (factor - 1) // 2 for v in pixel[:2])


def view_step(object_pixels: int, step: int) -> int:
    """The mesh step the 3D view gets: ``step``, or the smallest larger one whose mesh has at
    most :data:`VIEW_VERTICES` vertices (one per object pixel on the grid)."""
    return max(int(step), math.ceil(math.sqrt(object_pixels / VIEW_VERTICES)))


def fit_factor(width: int, height: int, max_pixels: int) -> int | None:
    """The block side that makes a ``width x height`` photo fit ``max_pixels`` (1 if it fits),
    or None if it is more than :data:`FIT_FACTOR` times the limit."""
    pixels = width * height
    if pixels <= max_pixels:
        return 1
    if pixels > FIT_FACTOR * max_pixels:
        return None
    factor = 2
    while math.ceil(width / factor) * math.ceil(height / factor) > max_pixels:
        factor += 1
    return factor
