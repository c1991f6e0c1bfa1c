"""A closed model from one photo: the photo's reconstruction as the front, the back completed.

One photo shows one side of an object. :func:`close` completes the side it does not show and
fuses the two into a closed, watertight model with the same code that fuses a photo and a photo
from behind (:func:`shadeform.fusion.place` and :func:`shadeform.fusion.solid`, the pair joined
at their shared rim: :func:`shadeform.fusion.volume.rim_offset`). The back is a guess, and the
returned model says so (:attr:`Closed.back`): ``"mirror"`` takes the front turned 180 degrees
about the vertical axis (its depth map flipped left to right, seen from behind), which is the
true back only for an object symmetric front to back.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from shadeform._checks import check_choice, positive
from shadeform.errors import InputError
from shadeform.mesh import Mesh, solid_measures

__all__ = ["BACKS", "Closed", "close", "in_millimetres", "mirrored"]

#: The ways :func:`close` completes the back, each with what the model then says about it.
BACKS = {
    "mirror": "mirror: a guess, the photo does not show it (the front turned 180 degrees about the vertical axis)"
}


@dataclass(frozen=True, eq=False)
class Closed(Mesh):
    """A closed model from one photo (:func:`close`): a :class:`~shadeform.mesh.Mesh` in pixel
    units, in the photo's camera frame with ``x = 0`` at the image's centre column and
    ``y = 0`` at its centre row (``docs/conventions.md``, turntable views).

    Attributes
    ----------
    vertices, faces, normals, uv, unit
        As for :class:`~shadeform.mesh.Mesh`.
    back : str
        What the back is: a guess (:data:`BACKS`), never measured.
    outline_iou : float
        The model's projection into the photo against the photo's mask
        (:func:`shadeform.fusion.outlines.outline_iou`), in ``[0, 1]``.
    watertight : bool
        Every edge shared by exactly two consistently wound faces
        (:func:`shadeform.mesh.solid_measures`).
    volume : float
        Enclosed volume, cubic pixels.
    """

    back: str = ""
    outline_iou: float = 0.0
    watertight: bool = False
    volume: float = 0.0


def mirrored(reconstruction):
    """The photo's reconstruction as seen from behind if the object were symmetric front to back:
    turned 180 degrees about the vertical axis, so its maps are flipped left to right and its
    normals' x negated (the depth is unchanged: the back's height toward that camera)."""
    flip = np.array([-1.0, 1.0, 1.0], dtype=np.asarray(reconstruction.normals).dtype)
    confidence = reconstruction.confidence
    return replace(
        reconstruction,
        normals=np.ascontiguousarray(np.asarray(reconstruction.normals)[:, ::-1] * flip),
        depth=np.ascontiguousarray(np.asarray(reconstruction.depth)[:, ::-1]),
        mask=np.ascontiguousarray(np.asarray(reconstruction.mask)[:, ::-1]),
        confidence=None if confidence is None else np.ascontiguousarray(confidence[:, ::-1]),
        info={
            key: value for key, value in reconstruction.info.items() if key not in ("unsure", "unsure_others")
        },
    )


def close(reconstruction, *, back: str = "mirror", resolution: float | None = None) -> Closed:
    """A closed, watertight model from one photo's reconstruction: the photo is the front, the
    back a guess.

    Parameters
    ----------
    reconstruction : Reconstruction
        One photo's (:func:`shadeform.reconstruct`), orthographic, pixel units.
    back : {"mirror"}
        How the back is completed: ``"mirror"``, the front turned 180 degrees about the vertical
        axis (:func:`mirrored`), fused with it as a view from behind is (:func:`shadeform.fusion.place`
        at 0 and 180 degrees about the image's centre column, the two joined at their shared
        rim, no pose refinement: the pose is exact by construction). Right for an object
        symmetric front to back; for any other, the model's thickness and back are wrong by how
        far the object is from that symmetry.
    resolution : float, optional
        Voxel edge in pixels (:func:`shadeform.fusion.fuse`'s).

    Returns
    -------
    Closed
        The model, with what its back is, the photo's outline kept and whether it is watertight.

    Raises
    ------
    InputError
        An unknown ``back``, an empty mask, or a bad ``resolution``.
    """
    from shadeform.fusion import place, solid
    from shadeform.fusion.outlines import outline_iou

    check_choice(back, tuple(BACKS), "back")
    mask = np.asarray(reconstruction.mask, bool) & np.isfinite(reconstruction.depth)
    if not mask.any():
        raise InputError("the reconstruction has no object pixels with a depth; nothing to close")
    centre = (mask.shape[1] - 1) / 2.0  # the mirror's axis: the flipped maps turn about it
    placement = place(
        [(reconstruction, 0.0), (mirrored(reconstruction), 180.0)],
        resolution=resolution,
        refine_poses=False,
        axis=centre,
    )
    mesh = solid(placement)
    measures = solid_measures(mesh)
    return Closed(
        vertices=mesh.vertices,
        faces=mesh.faces,
        normals=mesh.normals,
        back=BACKS[back],
        outline_iou=outline_iou(mesh, placement)[0],
        watertight=measures["watertight"],
        volume=measures["volume"],
    )


def in_millimetres(model: Closed, *, width_mm: float) -> Closed:
    """A closed model scaled for printing: the longest side of its outline (its larger extent
    in x and y, the photo's plane) ``width_mm`` millimetres, its depth in proportion, its
    bounding box starting at 0 and ``unit`` ``"millimeter"`` (what the exporters write).

    Parameters
    ----------
    model : Closed
        From :func:`close`, pixel units.
    width_mm : float
        Longest side of the outline, mm (the range :func:`shadeform.solid.check_options` allows).

    Returns
    -------
    Closed
        The same model in millimetres; its ``volume`` in cubic millimetres.
    """
    width_mm = positive(width_mm, "width_mm")
    vertices = np.asarray(model.vertices)
    low = vertices.min(axis=0)
    scale = width_mm / float(max(np.ptp(vertices[:, :2], axis=0)))
    return replace(
        model, vertices=(vertices - low) * scale, unit="millimeter", volume=model.volume * scale**3
    )
