"""Poses off by up to 10 degrees, many draws: does the placement come out at the true poses?

``benchmarks/bench_fusion.py`` disturbs each case's poses once (one seeded draw). Here an object
is rendered from 4 or 8 turntable angles (256x256, light from the camera), every view solved
alone from its photo, and placed (``shadeform.fusion.place`` with ``resolve``: unsure areas
settled by the other views, then tried again from the given poses) from many draws of pose
errors: every pose but the first off by an angle drawn uniformly from [-10, 10] degrees
("uniform"), or by 6 to 10 degrees with a random sign ("harsh"). A draw comes out exact when
every view's refined turn is within 0.35 degrees of the truth (the accuracy of the refinement
with true depths, ``benchmarks/results/fusion.md``). The draws are seeded (seed = draw number).

    .venv/bin/python benchmarks/bench_fusion_draws.py [--objects waisted] [--draws 8] [--out FILE]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import shadeform
from shadeform import synth
from shadeform.fusion import place

SIZE = 256
EXACT_DEGREES = 0.35


def errors(kind: str, count: int, seed: int) -> np.ndarray:
    """Pose errors (degrees) of one draw: 0 for the first view (it fixes the frame)."""
    rng = np.random.default_rng(seed)
    if kind == "harsh":
        return np.array([0.0, *(rng.choice([-1, 1]) * rng.uniform(6, 10) for _ in range(count - 1))])
    return np.array([0.0, *(rng.uniform(-10, 10) for _ in range(count - 1))])


def sweep(name: str, count: int, kind: str, draws: int) -> dict:
    angles = np.arange(count) * 360.0 / count
    views = synth.render_views(name, tuple(angles), size=SIZE)
    light = (0, 0, 1)
    recs = [shadeform.reconstruct(view.image, mask=view.mask, light=light) for view in views]

    def resolve(i, regions):
        return shadeform.reconstruct(views[i].image, mask=views[i].mask, light=light, concave=regions)

    worst, exact, seconds = [], 0, []
    for seed in range(draws):
        given = angles + errors(kind, count, seed)
        start = time.perf_counter()
        placement = place(list(zip(recs, given)), resolve=resolve)
        seconds.append(time.perf_counter() - start)
        turns = np.degrees([np.arctan2(v.rotation[0, 2], v.rotation[0, 0]) for v in placement.views])
        off = float(np.abs((turns - angles + 180) % 360 - 180).max())
        worst.append(off)
        exact += off <= EXACT_DEGREES
    return {"exact": exact, "worst": worst, "seconds": seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--objects", nargs="+", default=["waisted"], choices=synth.CLOSED_OBJECTS)
    parser.add_argument("--draws", type=int, default=8)
    parser.add_argument("--out", type=Path, default=None, help="Write the table to this Markdown file.")
    args = parser.parse_args()
    header = (
        "| object | views | errors | draws exact (within 0.35 deg) | worst view off, per draw (deg) | "
        "place median (s) | place worst (s) |\n|---|---:|---|---:|---|---:|---:|"
    )
    rows = []
    print(header, flush=True)
    for name in args.objects:
        for count in (4, 8):
            for kind in ("uniform", "harsh"):
                got = sweep(name, count, kind, args.draws)
                worst = ", ".join(f"{w:.1f}" for w in got["worst"])
                row = (
                    f"| {name} | {count} | {kind} | {got['exact']} of {args.draws} | {worst} | "
                    f"{np.median(got['seconds']):.1f} | {max(got['seconds']):.1f} |"
                )
                print(row, flush=True)
                rows.append(row)
    if args.out:
        args.out.write_text(header + "\n" + "\n".join(rows) + "\n")


if __name__ == "__main__":
    main()
