"""The fused model as a screened Poisson surface (Kazhdan & Hoppe 2013), with Open3D.

The alternative to the signed-distance volume of :mod:`.volume` (``fuse(..., surface="poisson")``):
every placed view gives oriented points, its mask pixels' surface points with their normals, both
in the object frame, and the screened Poisson reconstruction finds the indicator function whose
gradient best matches the normals, screened toward one value at the points; that level set,
meshed on an adaptive octree, is a closed surface. Parts no view saw (the poles of a turntable
object) are closed smoothly by the solution rather than by the visual hull.

How squarely a view saw the surface (its normal's ``n_z``, the weight of :mod:`.volume`) needs
no explicit weight here: under an orthographic camera a patch of area ``A`` covers ``A * n_z``
pixels, so each view already gives points in proportion to ``n_z``, and where views overlap their
mixture leans toward the one that saw it squarely. Points below the volume's floor
(:data:`~shadeform.fusion.volume.MIN_WEIGHT`), the view's grazing rim, are left out. Open3D
cannot take per-point weights (it normalises the normals).

Open3D is optional: ``pip install 'shadeform[fusion]'``.

References
----------
.. [1] M. Kazhdan, H. Hoppe, "Screened Poisson surface reconstruction", ACM Transactions on
   Graphics 32(3), 2013.
.. [2] Q.-Y. Zhou, J. Park, V. Koltun, "Open3D: a modern library for 3D data processing",
   arXiv:1801.09847, 2018.
"""

from __future__ import annotations

import importlib.util

import numpy as np

from shadeform.errors import InputError
from shadeform.fusion.volume import MIN_WEIGHT

__all__ = ["oriented_points", "poisson_depth", "poisson_solid", "require_open3d"]

#: Room left between the visual hull and the faces of Open3D's reconstruction cube, in voxels: a
#: surface reaching a face would be cut open there (set by hand; with only the points' box and
#: Open3D's default 10 % margin, the bottom of the lumpy object came out with a hole).
CUBE_MARGIN_VOXELS = 4.0
#: The deepest octree accepted (2^12 cells a side: beyond that the memory is out of reach).
MAX_DEPTH = 12


def poisson_solid(placement, *, depth: int | None = None):
    """The closed mesh of placed views by screened Poisson reconstruction (module description).

    Parameters
    ----------
    placement : Placement
        The views placed in one frame (:func:`shadeform.fusion.place`).
    depth : int, optional
        Octree depth, 2 to 12: the finest cells are ``2**depth`` to the reconstruction cube's
        side. Default: :func:`poisson_depth`, about one cell per voxel of the placement's grid,
        that is one per pixel of the views unless the object is big.

    Returns
    -------
    shadeform.mesh.Mesh
        Closed, watertight, outward-facing, in the object frame, pixel units.

    Raises
    ------
    InputError
        Open3D missing (install ``shadeform[fusion]``), a bad ``depth``, views without any
        usable pixel, or a surface that comes out open.
    """
    o3d = require_open3d()
    import trimesh

    from shadeform.mesh import outward

    points, normals = oriented_points(placement)
    if len(points) < 3:
        raise InputError("the views have no pixels with a usable normal to fuse; check the masks")
    scale = _cube_scale(points, placement.grid)
    if depth is None:
        depth = poisson_depth(points, placement.grid, scale)
    elif isinstance(depth, bool) or not isinstance(depth, (int, np.integer)) or not 2 <= depth <= MAX_DEPTH:
        raise InputError(f"depth must be a whole number from 2 to {MAX_DEPTH}, got {depth!r}")

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.normals = o3d.utility.Vector3dVector(normals)
    # One thread: with several, Open3D 0.20's Poisson gives vertices that differ from run to run
    # (by ~1e-5 px) and now and then prints "bad average roots" to stderr past its logger; one
    # thread is repeatable and quiet, and costs little on 2 cores (3-5 s at 256 px either way;
    # a many-core machine would gain from more). Only arguments Open3D 0.18 has.
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        surface, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
            cloud, depth=int(depth), scale=float(scale), n_threads=1
        )
    mesh = trimesh.Trimesh(np.asarray(surface.vertices), np.asarray(surface.triangles), process=True)
    if not len(mesh.faces):
        raise InputError("the Poisson surface is empty; check the poses and masks, or use surface='volume'")
    # One solid: where views disagree the solution leaves small closed bubbles beside the main
    # surface. Trimming low-density vertices, usual with Poisson, is not done: it would cut holes
    # where no view saw (the poles), and the model must stay closed.
    parts = mesh.split(only_watertight=False)
    mesh = max(parts, key=lambda part: len(part.faces))
    if not mesh.is_watertight:
        trimesh.repair.fill_holes(mesh)
    if not (mesh.is_watertight and mesh.is_winding_consistent):
        raise InputError(
            "the Poisson surface came out open; fuse with surface='volume', or try another depth"
        )
    return outward(mesh)


def oriented_points(placement) -> tuple[np.ndarray, np.ndarray]:
    """Every placed view's surface points and unit normals, object frame.

    A view's trusted mask pixels (:func:`~shadeform.fusion.volume.trusted_surface`) whose normal is finite and faces it at least
    :data:`~shadeform.fusion.volume.MIN_WEIGHT` (``n_z``); camera normals turned into the
    object frame by the transpose of the view's rotation.

    Returns
    -------
    points, normals : (N, 3) float64
    """
    points, normals = [], []
    for view in placement.views:
        camera = np.asarray(view.normals, dtype=np.float64)
        keep = (
            view.mask
            & view.trusted
            & np.isfinite(camera).all(axis=-1)
            & (np.nan_to_num(camera[..., 2]) >= MIN_WEIGHT)
        )
        rows, cols = np.nonzero(keep)
        points.append(view.surface_points(rows, cols))
        # rows of camera normals times R: each is R.T @ n
        normals.append(camera[rows, cols] @ view.rotation)
    points, normals = np.concatenate(points), np.concatenate(normals)
    finite = np.isfinite(points).all(axis=1)
    return points[finite], normals[finite]


def poisson_depth(points: np.ndarray, grid, scale: float) -> int:
    """The octree depth whose finest cells are no larger than the grid's voxels.

    Open3D's cube has ``scale`` times the largest side of the points' bounding box; depth
    ``d`` splits it into ``2**d`` cells a side. The grid's voxel is 1 pixel (coarser only for
    big objects, :data:`shadeform.fusion.MAX_VOXELS`), the views' own sampling: finer cells would
    have no points to fit, coarser ones would smooth away what the views resolved.
    """
    side = scale * float(np.max(points.max(axis=0) - points.min(axis=0)))
    return int(np.clip(np.ceil(np.log2(side / grid.spacing)), 2, MAX_DEPTH))


def _cube_scale(points: np.ndarray, grid) -> float:
    """Open3D's ``scale``: its cube (centred on the points' box) holding the whole visual hull's
    grid with :data:`CUBE_MARGIN_VOXELS` to spare, and at least Open3D's own 1.1."""
    low, high = points.min(axis=0), points.max(axis=0)
    centre = (low + high) / 2
    grid_low = grid.origin
    grid_high = grid.origin + grid.spacing * (np.asarray(grid.shape) - 1)
    reach = float(np.max(np.maximum(grid_high - centre, centre - grid_low)))
    side = 2 * (reach + CUBE_MARGIN_VOXELS * grid.spacing)
    return max(1.1, side / float(np.max(high - low)))


def require_open3d(*, load: bool = True):
    """The ``open3d`` module, or an error that says how to get it.

    With ``load=False`` only whether it is installed is checked and None returned: a caller that
    checks early (the CLI, before solving the views) does not load it yet, since Open3D's TBB
    loaded before numba's first parallel loop makes numba warn that it is too old.
    """
    missing = InputError(
        "the Poisson surface needs Open3D, which is not installed; "
        "install shadeform with its fusion extra: pip install 'shadeform[fusion]'"
    )
    if not load:
        if importlib.util.find_spec("open3d") is None:
            raise missing
        return None
    try:
        import open3d
    except ImportError as err:
        if err.name == "open3d":
            raise missing from None
        # installed, but its library did not load (on Linux it needs the system's libGL, libEGL,
        # libX11 and libusb)
        reason = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise InputError(
            f"Open3D is installed but does not load ({reason}); install the system libraries it "
            "needs (on Debian or Ubuntu: apt-get install libgl1 libegl1 libx11-6 libusb-1.0-0)"
        ) from None
    return open3d
