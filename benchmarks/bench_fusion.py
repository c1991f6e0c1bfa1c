"""Complete models from several views: accuracy and time of ``shadeform.fuse``.

Each closed synthetic object (``shadeform.synth.CLOSED_OBJECTS``) is rendered from 4 and from 8
turntable angles (256x256, light from the camera, Lambertian), every view is reconstructed from
its photo alone (``shadeform.reconstruct``, light (0, 0, 1), the true mask), and the views are
fused with ``resolve`` (each photo's unsure areas settled by the other views' silhouettes; the
fuse times include those solves; ``--no-settle`` fuses without); then again with every pose but the first disturbed by up to 10 degrees (seeded) and
``refine_poses=True``. Scored against the object's true surface: Chamfer distance (% of the bounding
box's diagonal, after the free translation), F-score at 1 % of the diagonal, volume error, and
whether the mesh is watertight (trimesh); 50,000 points sampled on the mesh against 200,000 on
the true surface, whose sampling floor is 0.17 % Chamfer. Times: the fusion alone (the first
single-photo solves are timed apart), median and worst of ``--repeats`` runs, wall clock.

Bars (issue 13): Chamfer <= 0.5 %, F-score >= 95 %, volume error <= 3 % on the shapes without a
concavity, Chamfer <= 2 % on the waisted one, every result watertight; 4 views fused in <= 10 s.

With ``--surface poisson`` (needs ``pip install 'shadeform[fusion]'``) each case's views are fused
both ways, ``surface="volume"`` and ``surface="poisson"``, from the same single-photo solves and
the same placement; the table goes to its own section of ``--out``, the volume's section is kept.

    .venv/bin/python benchmarks/bench_fusion.py [--repeats 3] [--out benchmarks/results/fusion.md]
    .venv/bin/python benchmarks/bench_fusion.py --surface poisson --views 4 --poses exact
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import shadeform
from shadeform import metrics, synth
from shadeform.fusion import place, solid

SIZE = 256
ANGLE_SETS = {4: tuple(range(0, 360, 90)), 8: tuple(range(0, 360, 45))}
DISTURBANCE = 10.0
#: Points sampled on the fused mesh and on the true surface: dense enough that the true surface
#: against a sampling of itself scores 0.17 % (8,000 a side: 0.57 %, the bar's own size).
SAMPLES, TRUE_SAMPLES = 50_000, 200_000
VOLUME_TITLE = "# Fusion of several views into one closed model (`shadeform.fuse`)"
POISSON_TITLE = '## Screened Poisson surface against the volume (`fuse(..., surface="poisson")`, Open3D)'
POISSON_TEXT = (
    "The same cases, fused both ways from the same single-photo solves and the same placement (the "
    'first half of `fuse`, timed apart): `surface="volume"` (signed distance, marching cubes, as '
    'above) and `surface="poisson"` (screened Poisson reconstruction of the views\' oriented points, '
    "Kazhdan & Hoppe 2013, Open3D {version}, octree depth from the voxel size: one finest cell per "
    "pixel). Scored as above; times median and worst of `--repeats` runs, wall clock, {cores} cores (the Poisson solve on one thread)."
)


def score(mesh, truth):
    got = metrics.surface_scores(
        mesh, truth.surface_points(TRUE_SAMPLES, seed=1)[0], truth.volume, samples=SAMPLES
    )
    return got["chamfer"], got["f_score"], got["volume_error"], got["watertight"]


def disturb(angles, disturbed, rng):
    """The angles, every one but the first moved by up to :data:`DISTURBANCE` degrees if
    ``disturbed``."""
    return [
        a + (rng.uniform(-DISTURBANCE, DISTURBANCE) if disturbed and i else 0.0) for i, a in enumerate(angles)
    ]


def solved(name, angles):
    """Each view's photo solved alone; the solver for ``resolve`` (a view again with extra
    concave regions); the seconds the first solves took."""
    views = synth.render_views(name, angles, size=SIZE)

    def solve(i, extra=()):
        return shadeform.reconstruct(
            views[i].image, mask=views[i].mask, light=(0, 0, 1), concave=list(extra) or None
        )

    start = time.perf_counter()
    recs = [solve(i) for i in range(len(views))]
    return recs, solve, time.perf_counter() - start


def run(name, count, disturbed, repeats, rng, settle=True):
    truth = synth.closed_object(name, size=SIZE)
    angles = ANGLE_SETS[count]
    recs, again, solve = solved(name, angles)
    poses = disturb(angles, disturbed, rng)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        mesh = shadeform.fuse(list(zip(recs, poses)), refine_poses=True, resolve=again if settle else None)
        times.append(time.perf_counter() - start)
    return (*score(mesh, truth), solve, float(np.median(times)), max(times), len(mesh.faces))


def run_both(name, count, disturbed, repeats, rng):
    """One case (settled, as :func:`run` settles by default) fused both ways: per surface, its scores, the placement's and the surface's
    median times, the surface's worst, and the triangles."""
    from shadeform.fusion.poisson import poisson_solid

    truth = synth.closed_object(name, size=SIZE)
    angles = ANGLE_SETS[count]
    recs, again, _ = solved(name, angles)
    poses = disturb(angles, disturbed, rng)
    placing = []
    times = {"volume": [], "poisson": []}
    meshes = {}
    for _ in range(repeats):
        start = time.perf_counter()
        placement = place(list(zip(recs, poses)), refine_poses=True, resolve=again)
        placing.append(time.perf_counter() - start)
        for surface, mesher in (("volume", solid), ("poisson", poisson_solid)):
            start = time.perf_counter()
            meshes[surface] = mesher(placement)
            times[surface].append(time.perf_counter() - start)
    return {
        surface: (
            *score(meshes[surface], truth),
            float(np.median(placing)),
            float(np.median(times[surface])),
            max(times[surface]),
            len(meshes[surface].faces),
        )
        for surface in times
    }


def _case(name, count, disturbed) -> str:
    """A table row's first cells: object, views, poses."""
    return f"{name} | {count} | {'off by up to 10 deg, refined' if disturbed else 'exact'}"


def _scored(chamfer, fscore, volume, tight) -> str:
    """A table row's score cells: Chamfer, F-score, volume error, watertight."""
    return f"{chamfer:.3f} | {fscore:.1f} | {volume:+.2f} % | {'yes' if tight else 'NO'}"


def write_section(path: Path, title: str, lines: list[str]) -> None:
    """``lines`` (starting with ``title``) in place of the section of ``path`` that has that
    title, up to the next heading; appended when there is none. The other sections are kept."""
    old = path.read_text(encoding="utf-8").splitlines() if path.exists() else []
    if title in old:
        start = old.index(title)
        end = next((i for i in range(start + 1, len(old)) if old[i].startswith("#")), len(old))
        new = [*old[:start], *lines, *([""] if end < len(old) else []), *old[end:]]
    else:
        new = [*old, *([""] if old else []), *lines]
    path.write_text("\n".join(new).rstrip("\n") + "\n", encoding="utf-8")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "fusion.md")
    parser.add_argument("--surface", choices=("volume", "poisson"), default="volume")
    parser.add_argument("--views", type=int, nargs="+", choices=tuple(ANGLE_SETS), default=list(ANGLE_SETS))
    parser.add_argument("--poses", choices=("exact", "disturbed", "both"), default="both")
    parser.add_argument(
        "--no-settle",
        action="store_true",
        help="Fuse without resolve (unsure areas stay as each photo read them).",
    )
    args = parser.parse_args()
    disturbances = {"exact": (False,), "disturbed": (True,), "both": (False, True)}[args.poses]
    if args.surface == "poisson":
        poisson_table(args, disturbances)
        return
    rng = np.random.default_rng(0)
    rows = []
    for count in args.views:
        for disturbed in disturbances:
            for name in synth.CLOSED_OBJECTS:
                row = run(name, count, disturbed, args.repeats, rng, settle=not args.no_settle)
                rows.append((name, count, disturbed, *row))
                print(rows[-1], flush=True)
    lines = [
        VOLUME_TITLE,
        "",
        __doc__.split("\n\n")[1].replace("\n", " "),
        "",
        "| object | views | poses | Chamfer (% diag) | F-score @1 % | volume error | watertight | "
        "single-photo solves (s) | fuse median (s) | fuse worst (s) | triangles |",
        "|---|---:|---|---:|---:|---:|:---:|---:|---:|---:|---:|",
    ]
    for name, count, disturbed, chamfer, fscore, volume, tight, solve, median, worst, faces in rows:
        lines.append(
            f"| {_case(name, count, disturbed)} | {_scored(chamfer, fscore, volume, tight)} | {solve:.2f} | "
            f"{median:.2f} | {worst:.2f} | {faces:,} |"
        )
    write_section(args.out, VOLUME_TITLE, lines)
    print("\n".join(lines))


def poisson_table(args, disturbances) -> None:
    import os

    import open3d

    rng = np.random.default_rng(0)
    lines = [
        POISSON_TITLE,
        "",
        POISSON_TEXT.format(version=open3d.__version__, cores=os.cpu_count()),
        "",
        "| object | views | poses | surface | Chamfer (% diag) | F-score @1 % | volume error | watertight | "
        "place median (s) | surface median (s) | surface worst (s) | triangles |",
        "|---|---:|---|---|---:|---:|---:|:---:|---:|---:|---:|---:|",
    ]
    for count in args.views:
        for disturbed in disturbances:
            for name in synth.CLOSED_OBJECTS:
                both = run_both(name, count, disturbed, args.repeats, rng)
                for surface, row in both.items():
                    print((name, count, disturbed, surface, *row), flush=True)
                    chamfer, fscore, volume, tight, placing, median, worst, faces = row
                    lines.append(
                        f"| {_case(name, count, disturbed)} | {surface} | {_scored(chamfer, fscore, volume, tight)} | "
                        f"{placing:.2f} | {median:.2f} | {worst:.2f} | {faces:,} |"
                    )
    write_section(args.out, POISSON_TITLE, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
