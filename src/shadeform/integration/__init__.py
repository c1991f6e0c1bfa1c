"""Depth from normals: ``integrate(normals, mask, integrator=...)``, and the registry of integrators.

Integrators
-----------
paths
    The 2002 report's method: average of many integration paths from a reference pixel
    (:mod:`shadeform.integration.paths`).
poisson
    Masked least squares, solved by multigrid-preconditioned conjugate gradients
    (:mod:`shadeform.integration.poisson`).
fourier
    The discrete Poisson equation on the mask's bounding rectangle, one DCT solve
    (Frankot & Chellappa 1988; :mod:`shadeform.integration.fourier`): the fastest, exact on full
    rectangles, approximate near the silhouette of other masks.
bilateral
    Discontinuity-preserving integration in the spirit of BiNI (Cao et al., ECCV 2022):
    one-sided differences reweighted by how well each side agrees; orthographic or perspective
    (:mod:`shadeform.integration.bilateral`).

A new integrator is one module with ``function(normals, mask, *, origin) -> depth`` (``z = 0`` at
``origin``; with ``perspective=True`` also ``K=``) and one :func:`register` line below: the
pipeline, the CLI's ``--integrator`` and the app's picker list it from here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from shadeform._checks import check_mask
from shadeform._deprecated import renamed_keywords
from shadeform.errors import InputError
from shadeform.registry import Option, Registry, load

__all__ = ["INTEGRATORS", "Integrator", "available_integrators", "integrate", "register"]


@dataclass(frozen=True)
class Integrator:
    """One integrator of the registry.

    Attributes
    ----------
    name : str
        What users pass (``integrate(integrator=name)``, ``reconstruct(integrator=name)``,
        ``--integrator name``).
    function : callable or str
        ``function(normals, mask, *, origin) -> depth`` (``(H, W)``, NaN off the mask, ``z = 0`` at
        ``origin``), or ``"module:function"`` naming it (imported on first use).
    description : str
        One line in the user's words.
    perspective : bool
        Whether it also takes ``K=`` (a pinhole camera) in place of ``origin``.
    options : tuple of Option
        Options of its own (:class:`shadeform.registry.Option`), listed by the app's
        ``/api/options``; no caller passes any yet, and the built-in integrators declare none.
    """

    name: str
    function: Callable[..., np.ndarray] | str
    description: str
    perspective: bool = False
    options: tuple[Option, ...] = ()

    def load(self) -> Callable[..., np.ndarray]:
        """The function (imports its module the first time)."""
        return load(self.function)


#: The registered integrators, in registration order.
INTEGRATORS: Registry[Integrator] = Registry("integrator", Integrator)


def register(integrator: Integrator) -> None:
    """Add (or replace) an integrator."""
    INTEGRATORS.register(integrator)


def available_integrators() -> dict[str, str]:
    """Integrator name to a one-line description, in registration order."""
    return INTEGRATORS.descriptions()


@renamed_keywords(method="integrator")
def integrate(
    normals: np.ndarray,
    mask: np.ndarray,
    *,
    integrator: str = "paths",
    origin: tuple[int, int] | None = None,
    K: np.ndarray | None = None,
) -> np.ndarray:
    """Depth from a normal field over a mask.

    Parameters
    ----------
    normals : (H, W, 3) float
        Unit normals in the camera frame (``docs/conventions.md``), finite on the mask.
    mask : (H, W) bool
    integrator : str
        A registered integrator (:func:`available_integrators`): "paths", "poisson", "fourier",
        "bilateral".
    origin : (int, int), optional
        (row, col) where ``z = 0`` (orthographic only). For "paths" only the mask's part holding
        the origin is integrated. Default: the most frontal normal's pixel.
    K : (3, 3) float, optional
        Pinhole intrinsics (OpenCV layout) for a perspective camera; "bilateral" only.

    Returns
    -------
    depth : (H, W) float64
        NaN outside the mask. Without ``K``: height in pixel units (larger = nearer the viewer)
        up to an offset. With ``K``: depth along the optical axis up to one scale factor.
    """
    normals = np.asarray(normals, dtype=np.float64)
    if normals.ndim != 3 or normals.shape[2] != 3:
        raise InputError(f"normals must be (H, W, 3), got shape {normals.shape}")
    mask = check_mask(mask, normals.shape[:2], of="the normals")
    if not np.isfinite(normals[mask]).all():
        raise InputError("normals have NaN inside the mask; fill them or leave those pixels out of the mask")
    entry = INTEGRATORS.get(integrator)
    if K is not None:
        if not entry.perspective:
            perspective = [i.name for i in INTEGRATORS.entries() if i.perspective]
            raise InputError(
                f"a perspective camera (K) needs integrator={' or '.join(map(repr, perspective))}, "
                f"not {integrator!r}"
            )
        return entry.load()(normals, mask, K=K)
    if origin is None:
        origin = np.unravel_index(np.argmax(np.where(mask, normals[..., 2], -np.inf)), mask.shape)
    origin = (int(origin[0]), int(origin[1]))
    if not (0 <= origin[0] < mask.shape[0] and 0 <= origin[1] < mask.shape[1]) or not mask[origin]:
        raise InputError(f"origin (row {origin[0]}, col {origin[1]}) is not on the mask")
    return entry.load()(normals, mask, origin=origin)


register(
    Integrator(
        "paths",
        "shadeform.integration.paths:integrate_paths",
        "the 2002 report's: the average of many integration paths from the reference",
    )
)
register(
    Integrator(
        "poisson",
        "shadeform.integration.poisson:integrate_poisson",
        "least squares over the object (multigrid conjugate gradients)",
    )
)
register(
    Integrator(
        "fourier",
        "shadeform.integration.fourier:integrate_fourier",
        "least squares on the bounding rectangle by one DCT solve: the fastest",
    )
)
register(
    Integrator(
        "bilateral",
        "shadeform.integration.bilateral:bilateral_depth",
        "keeps depth jumps at occluding edges (bilateral, BiNI); also perspective",
        perspective=True,
    )
)
