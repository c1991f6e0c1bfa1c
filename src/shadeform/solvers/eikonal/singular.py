"""Singular points: where the eikonal solver's marching starts, what kind each is, how high.

Where ``c = I / k = 1`` the surface is level: a local maximum, minimum or saddle of the height.
The image fixes ``|grad z|`` everywhere else, so these points, their kinds and their heights
decide the whole surface (Oliensis, 1991; see :mod:`shadeform.solvers.eikonal`). This module

1. finds them: the bright caps around maxima of ``c`` that reach ``1 - tol`` and rise at least
   ``tol`` above the pass to any brighter one (h-maxima, by morphological reconstruction), so
   noise and ripples on a level plateau do not split a cap. A cap's pixels within
   ``SOURCE_FRACTION * tol`` of its top start the marching: a point, a ridge's crest or a plateau;
2. gives each its kind from the user's concave masks (``docs/conventions.md``): a maximum by
   default, a minimum where the surface is concave along both axes (a bowl's bottom), a saddle
   where it is concave along one only (a vase's neck: convex across, concave along it);
3. adds the user's references (which replace the detected cap they fall in) and the brightest
   pixel of every connected part of the mask left without one, and picks each part's main
   singular point (``z = 0``): the first reference, else the brightest;
4. places their heights from the weighted distances ``D_ab`` between them (Dupuis & Oliensis,
   1994): ``|z_b - z_a| <= D_ab``; a maximum takes the lowest upper bound, a minimum the highest
   lower bound, both reached when a path of steepest ascent (descent) joins ``b`` to a placed
   point, as it does between singular points of different kinds, so those go first (a vase's lip
   is placed from its neck, not from its belly).

References
----------
.. [1] J. Oliensis, "Uniqueness in shape from shading", IJCV 6(2), 75-104, 1991.
.. [2] P. Dupuis and J. Oliensis, "An optimal control formulation and related numerical methods
   for a problem in shape reconstruction", Ann. Appl. Probab. 4(2), 287-346, 1994.
.. [3] L. Vincent, "Morphological grayscale reconstruction in image analysis: applications and
   efficient algorithms", IEEE Trans. Image Processing 2(2), 176-201, 1993 (h-maxima).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage as ndi
from skimage.morphology import local_maxima, reconstruction

from shadeform._checks import check_choice, whole
from shadeform.errors import InputError
from shadeform.solvers.eikonal.marching import run_march, side_by_side

__all__ = ["KINDS", "MAX_DETECTED", "SOURCE_FRACTION", "TOL", "SingularPoint"]

#: Kinds of singular points.
KINDS = ("max", "min", "saddle")

#: Default tolerance on ``c = I / k``: a singular region's top reaches ``1 - tol`` and rises
#: ``tol`` above the pass to any brighter one. Noisy images need more: 2e-2 at 1% noise after a
#: Gaussian of sigma 2. Both measured on the 256 px synthetic scenes, noise-free and at 1% noise:
#: ``benchmarks/results/eikonal.md``, Constants; the scenes the benchmarks report, so not held out.
TOL = 1e-3
#: The marching starts from a singular region's pixels within this fraction of ``tol`` of its top
#: (a ridge's crest or a plateau, not its flanks). A choice, not a measurement.
SOURCE_FRACTION = 0.1
#: At most this many detected singular regions are kept (the largest); more mean noise. A guard
#: on the work (one marching per singular point to place the heights), not a measurement.
MAX_DETECTED = 32

EIGHT = np.ones((3, 3), dtype=bool)  # 8-connectivity


@dataclass(frozen=True, eq=False)
class SingularPoint:
    """A singular point (or region) of the surface: where the marching starts.

    Attributes
    ----------
    row, col : int
        Its representative pixel: of its pixels, the one nearest their centroid.
    kind : {"max", "min", "saddle"}
        Local maximum, minimum or saddle of the height.
    height : float
        The height ``z`` it was given, in the result's frame (pixel units).
    pixels : (P, 2) int64
        ``(row, col)`` of the pixels where the marching starts (``T = 0``), read-only.
    origin : {"detected", "user", "brightest"}
        Found as a singular region, given by the user as a reference, or the brightest pixel of a
        part of the mask that had no other singular point.
    """

    row: int
    col: int
    kind: str
    height: float
    pixels: np.ndarray
    origin: str


@dataclass
class Node:
    """A singular point while it is being found and placed (mutable; :class:`SingularPoint` after)."""

    pixels: np.ndarray  # (P, 2) int64
    kind: str
    part: int
    top: float  # brightest c in the node
    size: int  # pixels in its singular region (for choosing the main one)
    origin: str
    region: int = 0  # label of its detected singular region, 0 for none
    height: float = np.nan

    @property
    def representative(self) -> tuple[int, int]:
        centre = self.pixels.mean(axis=0)
        r, c = self.pixels[np.argmin(((self.pixels - centre) ** 2).sum(axis=1))]
        return int(r), int(c)

    def frozen(self) -> SingularPoint:
        r, c = self.representative
        pixels = self.pixels.copy()
        pixels.flags.writeable = False
        return SingularPoint(
            row=r, col=c, kind=self.kind, height=float(self.height), pixels=pixels, origin=self.origin
        )


def find_singular_points(
    cos_seen, mask, parts, n_parts, *, concave_x, concave_y, tol, detect, references
) -> tuple[list[Node], dict[int, int], int]:
    """Steps 1-3 of the module docstring: ``(nodes, main node of each part, caps detected)``.

    Parameters
    ----------
    cos_seen : (H, W) float64
        ``c = I / k`` (of the smoothed image, if any), 0 off the mask.
    mask : (H, W) bool
    parts : (H, W) int
        Labels of the 8-connected parts of the mask, ``1..n_parts``.
    n_parts : int
    concave_x, concave_y : (H, W) bool
    tol : float
    detect : bool
        Find singular regions (else only the references and each part's brightest pixel).
    references : sequence or None
        ``(row, col)`` or ``(row, col, kind)``; checked here.
    """
    if detect:
        nodes, regions, found = _detect(cos_seen, mask, parts, concave_x, concave_y, tol)
    else:
        nodes, regions, found = [], np.zeros(mask.shape, dtype=np.int32), 0
    nodes = _add_references(nodes, regions, references, cos_seen, mask, parts, concave_x, concave_y)
    nodes = _cover_parts(nodes, cos_seen, parts, n_parts, concave_x, concave_y)
    return nodes, _main_nodes(nodes, n_parts), found


def _kind_at(r: int, c: int, concave_x, concave_y) -> str:
    x, y = bool(concave_x[r, c]), bool(concave_y[r, c])
    if x and y:
        return "min"
    if x or y:
        return "saddle"
    return "max"


def _single(r: int, c: int, parts, cos_seen, kind: str, origin: str) -> Node:
    """A node of one pixel."""
    return Node(
        pixels=np.array([[r, c]], dtype=np.int64),
        kind=kind,
        part=int(parts[r, c]),
        top=float(cos_seen[r, c]),
        size=1,
        origin=origin,
    )


def _detect(cos_seen, mask, parts, concave_x, concave_y, tol):
    """One node per significant bright cap: ``(nodes, label image of their caps, caps found)``.

    A cap is the connected set of pixels within ``tol`` of a regional maximum of ``c`` that rises
    at least ``tol`` above the pass to any brighter one (an h-maximum, found by morphological
    reconstruction of ``c - tol`` under ``c``), so maxima of noise or ripples on a singular
    plateau merge into one. A cap whose top reaches ``1 - tol`` is singular; the marching starts
    from its pixels within ``SOURCE_FRACTION * tol`` of the top (a ridge's whole crest, a plateau).
    """
    # Only caps reaching 1 - tol matter, and they lie above 1 - 2 tol: flooring c there and
    # cropping to where it rises above the floor changes none of them, and saves most of the work.
    floor = 1.0 - 2.0 * tol
    bright = mask & (cos_seen > floor)
    regions = np.zeros(mask.shape, dtype=np.int32)
    if not bright.any():
        return [], regions, 0
    rows, cols = np.nonzero(bright)
    box = (slice(max(rows.min() - 1, 0), rows.max() + 2), slice(max(cols.min() - 1, 0), cols.max() + 2))
    c = np.where(bright[box], cos_seen[box], floor)
    domes = reconstruction(c - tol, c, method="dilation", footprint=EIGHT)
    caps = local_maxima(domes, connectivity=2, allow_borders=True) & bright[box]
    count = ndi.label(caps, structure=EIGHT, output=regions[box])
    nodes = []
    kept = np.zeros(count + 1, dtype=bool)
    for index, window in enumerate(ndi.find_objects(regions), start=1):
        if window is None:
            continue
        inside = regions[window] == index
        values = cos_seen[window]
        top = float(values[inside].max())
        if top < 1.0 - tol:
            continue
        kept[index] = True
        rows, cols = np.nonzero(inside & (values >= top - SOURCE_FRACTION * tol))
        pixels = np.column_stack([rows + window[0].start, cols + window[1].start]).astype(np.int64)
        node = Node(
            pixels=pixels,
            kind="max",
            part=int(parts[pixels[0, 0], pixels[0, 1]]),
            top=top,
            size=int(inside.sum()),
            origin="detected",
            region=index,
        )
        node.kind = _kind_at(*node.representative, concave_x, concave_y)
        nodes.append(node)
    found = len(nodes)
    if found > MAX_DETECTED:
        # Noise: a true singular point has a wide cap, a speck of noise a small one. Dropping a
        # maximum that was not one only removes a singular point whose bound added nothing.
        nodes = sorted(nodes, key=lambda node: -node.size)[:MAX_DETECTED]
        nodes.sort(key=lambda node: node.region)
        kept[:] = False
        kept[[node.region for node in nodes]] = True
    labelled = regions[box]  # a view: the regions dropped are cleared in place
    labelled[~kept[labelled]] = 0
    return nodes, regions, found


def _add_references(nodes, regions, references, cos_seen, mask, parts, concave_x, concave_y) -> list[Node]:
    """The user's references first (in their order); each replaces the detected region it falls in."""
    if references is None:
        return nodes
    if isinstance(references, (str, bytes)) or not hasattr(references, "__iter__"):
        raise InputError("references must be a sequence of (row, col) or (row, col, kind)")
    user = []
    replaced = set()
    for item in references:
        r, c, kind = _parse_reference(item, mask)
        if regions[r, c] > 0:
            replaced.add(int(regions[r, c]))
        user.append(_single(r, c, parts, cos_seen, kind or _kind_at(r, c, concave_x, concave_y), "user"))
    return user + [node for node in nodes if node.region not in replaced]


def _parse_reference(item, mask) -> tuple[int, int, str | None]:
    try:
        length = len(item)
    except TypeError:
        length = -1
    if length not in (2, 3):
        raise InputError(f"reference {item!r} must be (row, col) or (row, col, kind)")
    r = whole(item[0], f"the row of reference {item!r}")
    c = whole(item[1], f"the column of reference {item!r}")
    if not (r < mask.shape[0] and c < mask.shape[1]) or not mask[r, c]:
        raise InputError(
            f"reference pixel (row {r}, col {c}) is not on the object; pick a pixel inside the mask"
        )
    kind = item[2] if length == 3 else None
    if kind is not None:
        check_choice(kind, KINDS, "reference kind")
    return r, c, kind


def _cover_parts(nodes, cos_seen, parts, n_parts, concave_x, concave_y) -> list[Node]:
    """Give every connected part of the mask without a singular point its brightest pixel."""
    bare = sorted(set(range(1, n_parts + 1)) - {node.part for node in nodes})
    if not bare:
        return nodes
    for r, c in ndi.maximum_position(cos_seen, parts, bare):
        r, c = int(r), int(c)
        nodes.append(_single(r, c, parts, cos_seen, _kind_at(r, c, concave_x, concave_y), "brightest"))
    return nodes


def _main_nodes(nodes, n_parts) -> dict[int, int]:
    """Per part, the node at z = 0: the first reference, else the brightest (then largest)."""
    main = {}
    for i, node in enumerate(nodes):
        if node.origin == "user" and node.part not in main:
            main[node.part] = i
    for part in range(1, n_parts + 1):
        if part in main:
            continue
        members = [i for i, node in enumerate(nodes) if node.part == part]
        main[part] = max(members, key=lambda i: (nodes[i].top, nodes[i].size, -i))
    return main


def place_heights(nodes, main_of_part, f, theta, mask, steep) -> None:
    """Heights of all nodes from their weighted distances (module docstring, step 4).

    Every placed node ``a`` bounds a new one ``b``: ``|z_b - z_a| <= D_ab``. A maximum takes the
    lowest upper bound, a minimum the highest lower bound; both are reached where a path of
    steepest ascent (descent) joins ``b`` to a placed node, which is why nodes linked to a placed
    one of another kind go first. A saddle lies below the maximum or above the minimum that links
    it; one that nothing links takes its nearest neighbour's height.
    """
    for part, main in main_of_part.items():
        members = [i for i, node in enumerate(nodes) if node.part == part]
        nodes[main].height = 0.0
        if len(members) == 1:
            continue
        d = np.full((len(nodes), len(nodes)), np.nan)  # by node index
        d[np.ix_(members, members)] = _pairwise_distances([nodes[i] for i in members], f, theta, mask, steep)
        placed = [main]
        waiting = [i for i in members if i != main]
        while waiting:
            linked = [(d[a, b], b, a) for b in waiting for a in placed if nodes[a].kind != nodes[b].kind]
            _, b, nearest = min(linked or [(d[a, b], b, a) for b in waiting for a in placed])
            lower = max(nodes[a].height - d[a, b] for a in placed)
            upper = min(nodes[a].height + d[a, b] for a in placed)
            kind = nodes[b].kind
            if kind == "max":
                nodes[b].height = upper
            elif kind == "min":
                nodes[b].height = lower
            elif not linked:
                nodes[b].height = nodes[nearest].height
            else:
                nodes[b].height = lower if nodes[nearest].kind == "max" else upper
            placed.append(b)
            waiting.remove(b)


def _pairwise_distances(members, f, theta, mask, steep) -> np.ndarray:
    """``D[a, b]``: weighted distance between the pixels of nodes a and b (symmetric).

    The marching from node a measures the nodes after it and stops once it has reached them all;
    the marches are independent and run side by side.
    """
    n = len(members)
    goal = np.full(mask.shape, -1, dtype=np.int32)
    for j, node in enumerate(members):
        goal[node.pixels[:, 0], node.pixels[:, 1]] = j
    present = np.unique(goal[goal >= 0])  # a node whose pixels all belong to later ones has none
    width = mask.shape[1]

    def distances_from(a: int) -> list[float]:
        node = members[a]
        index = node.pixels[:, 0] * width + node.pixels[:, 1]
        need = int(np.count_nonzero(present > a))
        T, _, reached = run_march(
            f, theta, mask, steep, index, np.zeros(len(index)), goal=goal, first=a + 1, need=need
        )
        # the first pixel of b accepted has the least T of b's pixels (they are accepted in
        # increasing order); a node without target pixels is read from T
        return [
            min(
                reached[b] if b < len(reached) else np.inf,
                T[members[b].pixels[:, 0], members[b].pixels[:, 1]].min(),
            )
            for b in range(a + 1, n)
        ]

    distance = np.zeros((n, n))
    for a, row in enumerate(side_by_side(distances_from, range(n - 1))):
        distance[a, a + 1 :] = distance[a + 1 :, a] = row
    return distance
