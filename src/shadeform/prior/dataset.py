"""Training examples for the shape prior: generated objects, photographed, framed as at inference.

A *bank* of objects (:func:`shapes`, the slow part: ray casting) is made once per seed; each
training example then takes one object of the bank, turns or mirrors it (the eight symmetries of
the square, its normals turned with it), paints, lights and photographs it anew
(:func:`shadeform.prior.photos.random_photo`) and frames it exactly as :func:`shadeform.prior.predict`
frames a user's photo (:class:`shadeform.prior.Window`). Every draw comes from a generator seeded
by ``(seed, index)``, so an example is the same whichever process makes it.
"""

from __future__ import annotations

import numpy as np

from shadeform.prior import Window, network_input
from shadeform.prior.photos import random_photo
from shadeform.prior.shapes import Shape, random_shape

__all__ = ["CANVAS", "Example", "example", "shapes", "turned"]

#: Canvas of a generated object, a multiple of the network's side (the object is framed down).
CANVAS = 1.5


class Example:
    """One framed training example: ``x`` (2, S, S) float32, ``target`` (S, S, 3) float32 unit
    normals (0 off the object), ``weight`` (S, S) float32 (1 on object pixels inside the given
    mask)."""

    __slots__ = ("target", "weight", "x")

    def __init__(self, x, target, weight):
        self.x, self.target, self.weight = x, target, weight


def shapes(seed: int, indices, *, size: int) -> list[Shape]:
    """The bank's objects ``indices`` for ``seed`` on a canvas of ``CANVAS * size`` pixels."""
    canvas = int(round(CANVAS * size))
    return [random_shape(np.random.default_rng([seed, 0, int(i)]), canvas) for i in indices]


def turned(shape: Shape, k: int) -> Shape:
    """``shape`` turned by ``k % 4`` quarter turns counter-clockwise, mirrored left-right first
    when ``k >= 4``; its normals turn with it (x = column, y = -row)."""
    depth, normals, mask, part = shape.depth, shape.normals.copy(), shape.mask, shape.part
    if k >= 4:
        depth, mask, part = depth[:, ::-1], mask[:, ::-1], part[:, ::-1]
        normals = normals[:, ::-1].copy()
        normals[..., 0] *= -1
    for _ in range(k % 4):
        depth, mask, part = np.rot90(depth), np.rot90(mask), np.rot90(part)
        normals = np.rot90(normals).copy()
        normals[..., 0], normals[..., 1] = -normals[..., 1], normals[..., 0].copy()
    return Shape(
        np.ascontiguousarray(depth),
        np.ascontiguousarray(normals),
        np.ascontiguousarray(mask),
        np.ascontiguousarray(part),
        shape.kind,
    )


def example(bank: list[Shape], seed: int, index: int, *, size: int) -> Example:
    """Training example ``index`` of ``seed``: an object of ``bank``, turned, photographed, framed."""
    rng = np.random.default_rng([seed, 1, int(index)])
    shape = turned(bank[rng.integers(len(bank))], int(rng.integers(8)))
    photo = random_photo(rng, shape)
    window = Window.around(photo.mask, size=size)
    x = network_input(photo.image, photo.mask, window)
    target = window.cut(np.nan_to_num(photo.normals))
    truth = window.cut(shape.mask.astype(np.float32)) > 0.99  # object pixels not blurred with the edge
    length = np.linalg.norm(target, axis=-1, keepdims=True)
    target = np.where(length > 1e-6, target / np.maximum(length, 1e-6), 0.0)
    weight = truth & (x[1] > 0.5) & (length[..., 0] > 0.5)
    return Example(x, target.astype(np.float32), weight.astype(np.float32))
