"""Complete models: partial models of several views fused into one closed mesh.

A user photographs an object from several sides (a turntable, or walking around it) and gets
one :class:`~shadeform.Reconstruction` per photo; :func:`fuse` places them in one frame (the
turntable's axis found from the silhouettes, each view's unknown depth offset from what the
other views' silhouettes allow), fuses their surfaces in a signed-distance volume bounded by
their visual hull and meshes it (:mod:`.volume`). The result is closed and watertight; a part no
view saw (the poles of a turntable object) is closed by the hull, never left open.

What one photo leaves open (a waist read as a hill top) is settled by the other views'
silhouettes (:mod:`.settle`) and checked once the poses are refined: each view's other readings
are tried again from the given poses, and a placement where the views clearly agree better is
kept (:func:`_checked`).

One photo alone gives a closed model too, its back a guess (:func:`close`, :mod:`.closed`).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from shadeform._checks import check_choice
from shadeform._deprecated import renamed_keywords
from shadeform.errors import InputError
from shadeform.fusion.closed import Closed, close
from shadeform.fusion.geometry import axis_column, parse_pose
from shadeform.fusion.poisson import poisson_solid, require_open3d
from shadeform.fusion.register import disagreement, refine_poses
from shadeform.fusion.settle import _alternatives
from shadeform.fusion.settle import settle as _settle  # the package keeps .settle, the module
from shadeform.fusion.volume import (
    FusionView,
    Grid,
    crossed,
    fused_distance,
    hull,
    hull_depth,
    one_solid,
    touching_offset,
    view_offsets,
)

__all__ = ["Closed", "Placement", "Rival", "close", "fuse", "place", "solid"]

#: The ways :func:`fuse` turns the placed views into one surface.
SURFACES = ("volume", "poisson")
# what a user reads when the views' silhouettes do not meet
_NOTHING_SHARED = "the views share no volume: their silhouettes do not meet at these poses; check the angles"
#: Most voxels of the fusion grid when ``resolution`` is not given.
MAX_VOXELS = 6_000_000
#: A placement tried again replaces the one found only if the views disagree less by more
#: than this factor (:func:`_checked`). Set by hand (twice), not swept, on synth's waisted
#: object, whose draws ``benchmarks/results/fusion-draws.md`` reports: a view left with the
#: wrong reading disagreed 6-12 times more than the right placement (8 views); with 4 views,
#: placements that explain the photos alike (the object turned) came within 1.7 times of each
#: other. The held-out shapes of ``fusion-shapes.md`` were used to drop a first form of the
#: rule (ties broken by the given angles), so they are no longer held out for this choice.
CLEARLY = 2.0
#: The most a view's pose is corrected, degrees: what :func:`fuse` promises (poses off by up to
#: 10 degrees). A placement tried again that turns a view further from its given pose, by more
#: than its surface can show (:func:`_beyond`), is not taken: two lobes that look alike make
#: placements turned by twice that agree as well.
CORRECTED = 10.0
#: Surface points per view when :func:`_checked` tries readings (the refinement's own:
#: :data:`shadeform.fusion.register.SAMPLES`); a third, for speed. Set by hand.
TRIAL_SAMPLES = 500
#: At most this many placements per view are tried by :func:`_checked` in all (each is a
#: refinement of every view): a bound on the work, not a measurement.
TRIALS_PER_VIEW = 2
#: Truncation of the signed distance, in voxels (set by hand; checked only on the synthetic closed
#: objects of benchmarks/results/fusion.md).
TRUNCATION_VOXELS = 3.0


@renamed_keywords(refine="refine_poses")
def fuse(
    views: Sequence,
    *,
    resolution: float | None = None,
    refine_poses: bool = True,
    axis: float | None = None,
    resolve: Callable[[int, list], object] | None = None,
    surface: str = "volume",
):
    """One closed mesh from several views' reconstructions.

    Parameters
    ----------
    views : sequence of (Reconstruction, pose)
        Two or more single-photo reconstructions (orthographic, pixel units, the same image
        size) with their poses: a turntable angle in degrees (the object turned by that angle
        about the camera's vertical axis, right-handed about +y: camera point
        ``= R_y(angle) @ object point``) or a 4x4 matrix taking object points to the view's
        camera frame (``docs/conventions.md``; its x = 0 at the image's centre column).
    resolution : float, optional
        Voxel edge in pixels; default: 1, or coarser so that the grid has at most
        :data:`MAX_VOXELS` voxels.
    refine_poses : bool
        Correct the poses and depth offsets so that the views agree (:mod:`.register`): each
        view's points inside the others' silhouettes, overlapping surfaces at one depth. Poses
        off by up to 10 degrees are corrected this way. False takes the poses as given.
    axis : float, optional
        The turntable axis's column in the images; default: found from the silhouettes
        (:func:`shadeform.fusion.geometry.axis_column`).
    resolve : callable, optional
        ``resolve(i, regions) -> Reconstruction``: view ``i`` solved again with ``regions`` (a
        list of :class:`shadeform.regions.Region`) marked concave besides the user's. Given, the
        areas each photo could not settle (``info["unsure"]``) are read as concave where the
        other views' silhouettes say so (:mod:`.settle`): a waist between two lobes, which one
        photo reads as a third hill top. With ``refine_poses``, the readings are then tried again
        from the given poses and kept where the views clearly agree better (:func:`_checked`).
    surface : {"volume", "poisson"}
        How the placed views become one surface: ``"volume"``, their truncated signed distance
        meshed by marching cubes (:func:`solid`), or ``"poisson"``, screened Poisson
        reconstruction of their oriented points (:func:`~shadeform.fusion.poisson.poisson_solid`;
        needs Open3D: ``pip install 'shadeform[fusion]'``).

    Returns
    -------
    shadeform.mesh.Mesh
        Closed, watertight, outward-facing, in the object frame (the frame of the view whose
        pose is 0 or the identity), pixel units. Where the photos fit another placement about
        as well (four views 90 degrees apart of a waisted body, given 9 degrees off), the mesh
        is one of the two: :func:`place` names the other (:attr:`Placement.rivals`), as the CLI
        and the app do.

    Raises
    ------
    InputError
        Fewer than two views, views of different sizes, a malformed pose, an empty mask, views
        that share no volume, an unknown ``surface``, or ``"poisson"`` without Open3D.
    """
    if check_choice(surface, SURFACES, "surface") == "poisson":
        require_open3d(load=False)  # before the placement's seconds, not after
    placement = place(views, resolution=resolution, refine_poses=refine_poses, axis=axis, resolve=resolve)
    return solid(placement, surface=surface)


@dataclass(frozen=True)
class Rival:
    """Another placement that explains the views about as well as the one kept (:func:`_checked`).

    Attributes
    ----------
    turns : tuple of float
        Per view, the angle in degrees between its pose there and in the kept placement (0 for
        views that are not turned further than a voxel's worth: :func:`_moved`).
    ratio : float
        Its disagreement over the kept placement's: at most :data:`CLEARLY`, below 1 where it
        agrees slightly better but not clearly.
    """

    turns: tuple[float, ...]
    ratio: float


@dataclass(frozen=True, eq=False)
class Placement:
    """The views placed in one frame, ready to be fused (:func:`place`).

    Attributes
    ----------
    views : tuple of FusionView
        Each view at its (refined) pose and depth offset.
    grid : Grid
        The voxels over the views' visual hull, object frame.
    axis : float
        The column of the object frame's x = 0 in the images (the turntable axis).
    readings : tuple of Reconstruction
        Each view's reconstruction as placed: the one given, or the one :func:`place` solved
        again with unsure areas read as concave (``concave``).
    concave : tuple of tuple of dict
        Per view, the unsure areas (its ``info["unsure"]`` entries) the other views' silhouettes
        showed to be concave (:mod:`.settle`); empty when nothing was settled.
    rivals : tuple of Rival
        Other placements that explain the photos about as well as this one (within
        :data:`CLEARLY`), with views turned elsewhere: the photos do not decide between them, and
        the fused model may be wrong. Empty when none was found.
    """

    views: tuple[FusionView, ...]
    grid: Grid
    axis: float
    readings: tuple
    concave: tuple[tuple[dict, ...], ...]
    rivals: tuple[Rival, ...] = ()

    @property
    def depth_fixed(self) -> bool:
        """Whether the views fix the object's depth: two of them look along directions more than
        :data:`CORRECTED` degrees from parallel (poses may be that far off). Views from opposite
        sides only (0 and 180 degrees) see its width and height twice and its depth never: their
        rims are joined (:func:`~shadeform.fusion.volume.rim_offset`), and the fused
        model's thickness rests on each photo's shading alone."""
        axes = [view.rotation.T @ np.array([0.0, 0.0, 1.0]) for view in self.views]  # object frame
        return any(
            np.linalg.norm(np.cross(a, b)) > np.sin(np.radians(CORRECTED))
            for i, a in enumerate(axes)
            for b in axes[i + 1 :]
        )

    def transforms(self) -> list[np.ndarray]:
        """Per view, the 4x4 matrix taking its partial model's vertices (the mesh frame of
        ``docs/conventions.md``: ``(c, -r, depth[r, c])`` of its reading,
        ``shadeform.mesh.to_mesh(placement.readings[i])``) to the object frame; the partial
        models then lie where the fused one does."""
        out = []
        for view, rec in zip(self.views, self.readings):
            # mesh (c, -r, d) -> camera (c - c0, row0 - r, d - median + offset) -> object
            shift = np.eye(4)
            shift[:3, 3] = [-view.column0, view.row0, view.offset - _depth_centre(view.mask, rec.depth)]
            inverse = np.eye(4)
            inverse[:3, :3] = view.rotation.T
            inverse[:3, 3] = -view.rotation.T @ view.translation
            out.append(inverse @ shift)
        return out


@renamed_keywords(refine="refine_poses")
def place(
    views: Sequence,
    *,
    resolution: float | None = None,
    refine_poses: bool = True,
    axis: float | None = None,
    resolve: Callable[[int, list], object] | None = None,
) -> Placement:
    """Several views' reconstructions placed in one frame: the first half of :func:`fuse`
    (its parameters), for a caller that also shows the partial models where they were put
    (:meth:`Placement.transforms`) or meshes the placement itself (:func:`solid`)."""
    items = _check(views)
    poses = [parse_pose(pose, i) for i, (_, pose) in enumerate(items)]
    recs = [rec for rec, _ in items]
    turntable = all(pose.angle is not None for pose in poses)
    width = recs[0].mask.shape[1]
    if axis is not None:
        column0 = float(axis)
    elif turntable:
        column0 = axis_column([rec.mask for rec in recs], [pose.angle for pose in poses])
    else:
        column0 = (width - 1) / 2.0
    placed = [_placed(rec, pose.matrix, column0) for rec, pose in zip(recs, poses)]
    grid = _grid(placed, resolution)
    inside = _shared(placed, grid)
    placed = _touching(placed, grid, inside)
    readings, concave = list(recs), ((),) * len(recs)
    if resolve is not None:
        resolve = _remembered(resolve)
    # settled before the poses are refined (a lobe read tens of pixels too deep pulls them off)
    # and again after (at poses 10 degrees off the hull may not show which reading is right)
    for round_ in range(2 if resolve is not None and refine_poses else 1):
        if resolve is not None:
            if round_:
                inside = _shared(placed, grid)
            chosen, concave = _settle(placed, grid, inside, recs, resolve)
            if round_ and all(new is old for new, old in zip(chosen, readings)):
                break
            placed, readings = _replaced(placed, readings, chosen, grid, column0), chosen
        if refine_poses:
            placed = _refined(placed, turntable=turntable)
    if resolve is not None and refine_poses:
        given = [pose.matrix for pose in poses]
        placed, readings, concave, rivals = _checked(
            placed, readings, concave, recs, given, grid, column0, resolve, turntable=turntable
        )
    else:
        rivals = ()
    if refine_poses and not hull(placed, grid).any():
        raise InputError("the views share no volume at the refined poses; check the angles")
    return Placement(tuple(placed), grid, column0, tuple(readings), tuple(concave), rivals)


def _refined(views, **keywords):
    """This package's ``refine_poses``, looked up when called (place's flag hides it; tests replace it)."""
    return refine_poses(views, **keywords)


def _checked(placed, readings, concave, recs, given, grid, column0, resolve, *, turntable):
    """The placement with the views' readings tried again from the given poses.

    Settling chooses by the hull, which is only as right as the starting poses: with poses 10
    degrees off, a view can keep a reading of its unsure area that turns its surface (one lobe
    deeper than the other), and the refinement then turns the view, or all the others, to
    match. So the views' other readings are tried once more, one or two views changed at a time
    (the front and back views of a body can both be wrong, and agree): every view started
    again from its given pose and refined (with :data:`TRIAL_SAMPLES` points a view, at most
    :data:`TRIALS_PER_VIEW` trials a view, views seen from opposite sides paired first), the
    views' disagreement measured (:func:`~shadeform.fusion.register.disagreement`, at one
    scale for all). The trial that disagrees least replaces the placement if it disagrees less
    by more than a factor :data:`CLEARLY` and turns no view more than :data:`CORRECTED` degrees
    from its given pose (beyond what a voxel resolves: :func:`_beyond`); this repeats from the
    kept placement until it stays.
    Where the views cannot tell two placements apart (four views of a body of revolution, whose
    front and back readings each explain the photos with the object turned), the placement
    stays as settled: the user's angles are not trusted to choose (on shapes held out, trusting
    them in ties made the result worse). The trials that come within :data:`CLEARLY` of the
    placement kept with a view turned elsewhere are returned as its rivals (:class:`Rival`),
    so that the user learns the photos do not decide.
    """
    loss, scale = disagreement(placed, turntable=turntable, samples=TRIAL_SAMPLES, every_piece=True)
    best = _Trial(placed, loss, tuple(readings), tuple(concave))
    options = [_distinct(rec, resolve, i, grid.spacing) for i, rec in enumerate(recs)]
    if all(len(choices) < 2 for choices in options):
        return placed, readings, concave, ()
    # each view at its given pose, touching the hull there; the hull's front seen from a view is
    # the same for every reading of it (a reading changes depth, not mask)
    start = [_placed(rec, pose, column0) for rec, pose in zip(readings, given)]
    inside = _shared(start, grid)
    fronts = [
        hull_depth(view, grid, inside) if crossed(view, start[:i] + start[i + 1 :]) else None
        for i, view in enumerate(start)
    ]
    starts, trials = {}, {}

    def started(i, reading):
        if (i, id(reading)) not in starts:
            view = _placed(reading, given[i], column0)
            if fronts[i] is not None:
                offset = touching_offset(view, fronts[i], start[:i] + start[i + 1 :])
                view = view.at(view.rotation, view.translation, offset)
            starts[i, id(reading)] = view
        return starts[i, id(reading)]

    def trial(tried, marked):
        key = tuple(id(reading) for reading in tried)
        if key not in trials:
            if len(trials) >= TRIALS_PER_VIEW * len(recs):
                return None
            views = [started(k, reading) for k, reading in enumerate(tried)]
            moved = refine_poses(views, turntable=turntable, samples=TRIAL_SAMPLES)
            loss, _ = disagreement(
                moved, turntable=turntable, scale=scale, samples=TRIAL_SAMPLES, every_piece=True
            )
            if _beyond(moved, given, grid.spacing, turntable=turntable):
                loss = np.inf  # a view turned further than a pose is ever corrected
            trials[key] = _Trial(moved, loss, tried, marked)
        return trials[key]

    unsure = [i for i, choices in enumerate(options) if len(choices) > 1]
    # two views' wrong readings agree when they see the object from opposite sides: those first
    directions = [pose[:3, :3].T @ [0.0, 0.0, 1.0] for pose in given]
    pairs = sorted(
        itertools.combinations(unsure, 2), key=lambda p: float(directions[p[0]] @ directions[p[1]])
    )
    for _ in range(len(recs)):
        candidates = [best]
        for changed in (*((i,) for i in unsure), *pairs):
            for choice in itertools.product(*(options[i] for i in changed)):
                if any(
                    _alike(reading, best.readings[i], grid.spacing)
                    for i, (_, reading) in zip(changed, choice)
                ):
                    continue
                tried, marked = list(best.readings), list(best.concave)
                for i, (chosen, reading) in zip(changed, choice):
                    tried[i], marked[i] = reading, tuple(chosen)
                candidates.append(trial(tuple(tried), tuple(marked)))
        candidates = [candidate for candidate in candidates if candidate is not None]
        kept = min(candidates, key=lambda candidate: candidate.loss)
        if kept.loss * CLEARLY >= best.loss:
            break
        best = kept
    rivals = _rivals(best, trials.values(), grid.spacing, turntable=turntable)
    if best.placed is placed:
        return placed, readings, concave, rivals
    return refine_poses(best.placed, turntable=turntable), list(best.readings), best.concave, rivals


def _rivals(best: _Trial, trials, spacing: float, *, turntable: bool) -> tuple[Rival, ...]:
    """The trials within :data:`CLEARLY` of ``best`` with a view turned elsewhere, each once."""
    out: list[tuple[_Trial, Rival]] = []
    for trial in sorted(trials, key=lambda trial: trial.loss):
        if not np.isfinite(trial.loss) or trial.loss > best.loss * CLEARLY:
            continue
        if not _apart(trial.placed, best.placed, spacing, turntable=turntable):
            continue
        if any(not _apart(trial.placed, seen.placed, spacing, turntable=turntable) for seen, _ in out):
            continue
        turns = tuple(
            float(np.degrees(_angle(a.rotation, b.rotation)))
            if _moved(a, b, spacing, turntable=turntable)
            else 0.0
            for a, b in zip(trial.placed, best.placed)
        )
        out.append((trial, Rival(turns, float(trial.loss / best.loss) if best.loss > 0 else 1.0)))
    return tuple(rival for _, rival in out)


def _apart(a: list[FusionView], b: list[FusionView], spacing: float, *, turntable: bool) -> bool:
    """Whether two placements of the same views differ: a view turned by more than a voxel's worth."""
    return any(_moved(u, v, spacing, turntable=turntable) for u, v in zip(a, b))


def _moved(a: FusionView, b: FusionView, spacing: float, *, turntable: bool) -> bool:
    """Whether the turn between two poses of one view moves its trusted surface by more than
    ``spacing`` (:func:`_reach`)."""
    return _angle(a.rotation, b.rotation) * _reach(a, turntable=turntable) > spacing


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    """The angle (radians) of the rotation between two rotation matrices."""
    cosine = (np.trace(a.T @ b) - 1.0) / 2.0
    return float(np.arccos(np.clip(cosine, -1.0, 1.0)))


def _reach(view: FusionView, *, turntable: bool) -> float:
    """How far the view's trusted surface point farthest from the axis (from the origin, for poses
    given as matrices) lies, in pixels: a turn by ``t`` radians moves it ``t`` times that."""
    rows, cols = np.nonzero(view.mask & view.trusted & np.isfinite(view.depth))
    points = view.surface_points(rows, cols)
    reach = np.hypot(points[:, 0], points[:, 2]) if turntable else np.linalg.norm(points, axis=1)
    return float(reach.max(initial=0.0))


@dataclass(frozen=True)
class _Trial:
    """A placement tried by :func:`_checked`: the views, their disagreement, and the readings
    and concave areas."""

    placed: list
    loss: float
    readings: tuple
    concave: tuple


def _distinct(rec, resolve, i: int, tolerance: float) -> list[tuple[tuple, object]]:
    """A view's readings that differ (:func:`_alike`): its own and those with its unsure areas
    marked concave (:func:`~shadeform.fusion.settle._alternatives`), each with the areas."""
    out = [((), rec)]
    for chosen, regions in _alternatives(rec):
        reading = resolve(i, regions)
        if not any(_alike(reading, other, tolerance) for _, other in out):
            out.append((chosen, reading))
    return out


def _beyond(placed: list[FusionView], given: list[np.ndarray], spacing: float, *, turntable: bool) -> bool:
    """Whether a view is turned from its given pose further than :data:`CORRECTED` degrees, by
    more than a voxel's worth: its trusted surface point farthest from the axis (from the
    origin, for poses given as matrices) moved by more than ``spacing`` through the excess turn.

    A pose given exactly :data:`CORRECTED` degrees off is a promised case, and its true pose,
    refined, lands on either side of the bound by the refinement's own error (on synth's
    waisted object, 8 views: 9.95 degrees given, 10.03 refined); a turn that moves no surface
    point by a voxel is finer than the fused volume, the hull and the settling resolve.
    """
    for view, pose in zip(placed, given):
        excess = _angle(pose[:3, :3], view.rotation) - np.radians(CORRECTED)
        if excess > 0 and excess * _reach(view, turntable=turntable) > spacing:
            return True
    return False


def _alike(a, b, tolerance: float) -> bool:
    """Whether two readings of one photo have the same surface, up to their offset: the root
    mean square difference of their depths under ``tolerance`` (pixels)."""
    if a is b:
        return True
    both = np.asarray(a.mask, bool) & np.isfinite(a.depth) & np.isfinite(b.depth)
    difference = a.depth[both] - b.depth[both]
    return bool(np.sqrt(np.mean((difference - np.median(difference)) ** 2)) < tolerance)


def _replaced(placed, old, new, grid, column0) -> list[FusionView]:
    """The placed views with the readings that changed from ``old`` to ``new`` put in their
    place, at the same poses, and every view moved in depth to touch the hull again."""
    changed = [i for i in range(len(new)) if new[i] is not old[i]]
    if not changed:
        return placed
    placed = list(placed)
    for i in changed:
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = placed[i].rotation, placed[i].translation
        placed[i] = _placed(new[i], pose, column0)
    # a reading solved again may have left a few more pixels without a depth
    return _touching(placed, grid, _shared(placed, grid))


def _remembered(resolve: Callable[[int, list], object]) -> Callable[[int, list], object]:
    """``resolve`` that solves each view with each set of regions once (settling runs twice)."""
    solved = {}

    def again(i: int, regions: list):
        key = (i, tuple((region.axis, np.asarray(region.polygon).tobytes()) for region in regions))
        if key not in solved:
            solved[key] = resolve(i, regions)
        return solved[key]

    return again


def _shared(placed: list[FusionView], grid: Grid) -> np.ndarray:
    """The views' visual hull on the grid; none is a user's mistake (angles or masks)."""
    inside = hull(placed, grid)
    if not inside.any():
        raise InputError(_NOTHING_SHARED)
    return inside


def _touching(placed: list[FusionView], grid: Grid, inside: np.ndarray) -> list[FusionView]:
    """The views, each moved in depth until it touches the others' visual hull ``inside``."""
    offsets = view_offsets(placed, grid, inside)
    return [view.at(view.rotation, view.translation, offset) for view, offset in zip(placed, offsets)]


def solid(placement: Placement, *, surface: str = "volume"):
    """The closed mesh of placed views (the second half of :func:`fuse`): with ``"volume"``
    their truncated signed distance, one solid kept, marching cubes; with ``"poisson"`` the
    screened Poisson surface of their oriented points
    (:func:`~shadeform.fusion.poisson.poisson_solid`)."""
    if check_choice(surface, SURFACES, "surface") == "poisson":
        return poisson_solid(placement)
    return _marched(placement)


def _marched(placement: Placement):
    """The volume surface: truncated signed distance, one solid, marching cubes."""
    import trimesh
    from skimage.measure import marching_cubes

    from shadeform.mesh import outward

    grid = placement.grid
    distance = one_solid(
        fused_distance(list(placement.views), grid, truncation=TRUNCATION_VOXELS * grid.spacing)
    )
    padded = np.pad(distance, 1, constant_values=1.0)
    if not (padded < 0).any():
        raise InputError(
            "the fused model is empty: the views do not agree on any solid; check the poses and masks"
        )
    verts, faces, _, _ = marching_cubes(padded, level=0.0, spacing=(grid.spacing,) * 3)
    verts = verts + grid.origin - grid.spacing
    mesh = trimesh.Trimesh(verts, faces, process=True)
    return outward(mesh)


def _check(views) -> list:
    try:
        items = [(rec, pose) for rec, pose in views]
    except (TypeError, ValueError):
        raise InputError("views must be (reconstruction, pose) pairs") from None
    if len(items) < 2:
        raise InputError(f"fusing needs at least two views, got {len(items)}")
    shape = items[0][0].mask.shape
    for i, (rec, _) in enumerate(items):
        if rec.mask.shape != shape:
            raise InputError(
                f"view {i + 1} is {rec.mask.shape[1]}x{rec.mask.shape[0]} but view 1 is "
                f"{shape[1]}x{shape[0]}; give views from one camera, at one size"
            )
        if not rec.mask.any():
            raise InputError(f"view {i + 1} has an empty mask; every view must show the object")
    return items


def _placed(rec, pose: np.ndarray, column0: float) -> FusionView:
    mask = np.asarray(rec.mask, bool) & np.isfinite(rec.depth)
    depth = np.where(mask, rec.depth, np.nan)
    # one offset per view is unknown: start from its depths centred on 0
    depth = depth - _depth_centre(mask, rec.depth)
    return FusionView(depth, mask, np.asarray(rec.normals), pose[:3, :3], pose[:3, 3], column0)


def _depth_centre(mask: np.ndarray, depth: np.ndarray) -> float:
    """The depth a view is centred on before its offset is found: its median over the mask."""
    return float(np.median(depth[mask & np.isfinite(depth)]))


def _grid(views: list[FusionView], resolution: float | None) -> Grid:
    """A grid over the views' coarse visual hull, a few voxels beyond it."""
    h, w = views[0].mask.shape
    reach = max(h, w) + max(float(np.linalg.norm(view.translation)) for view in views)
    coarse = Grid(np.full(3, -reach), 2 * reach / 63, (64, 64, 64))
    index = np.argwhere(_shared(views, coarse))
    low = coarse.origin + coarse.spacing * (index.min(axis=0) - 2)
    high = coarse.origin + coarse.spacing * (index.max(axis=0) + 2)
    if resolution is None:
        spacing = max(1.0, float(np.prod(high - low) / MAX_VOXELS) ** (1 / 3))
    else:
        spacing = float(resolution)
        if not (np.isfinite(spacing) and spacing > 0):
            raise InputError(f"resolution must be a positive voxel size in pixels, got {resolution!r}")
    shape = tuple(int(n) for n in np.ceil((high - low) / spacing).astype(int) + 1)
    if np.prod(shape) > 20 * MAX_VOXELS:
        raise InputError(
            f"a resolution of {spacing:g} pixels needs {np.prod(shape):,} voxels; choose a coarser one"
        )
    return Grid(low, spacing, shape)
