"""Benchmark: the eikonal solver (light at +z) on the synthetic scenes, accuracy and speed.

For every scene (256 x 256 by default, true mask given, no boundary heights) and noise level, one
row: the concave regions the user marked, the depth error (RMSE as a percent of the true depth
range, after fitting the offset; ``shadeform.metrics.depth_error``), the mean angular error of the
normals, the number of sources used and the median wall time of ``eikonal_depth`` over ``--runs``
runs after a warm-up that loads the compiled kernels. Noisy images (1% of the albedo by default)
are first smoothed inside the mask by a Gaussian of sigma 2 (``preprocess.apply_filter``) and
solved with ``tol=2e-2``; the noise-free ones use the defaults, and so do the last rows (sphere
and marked vase, noisy and unfiltered). Then the time of the 1024 x 1024 sphere, stage by stage.

Writes ``benchmarks/results/eikonal.md`` and prints the same tables.

Usage: ``python benchmarks/bench_eikonal.py [--size 256] [--big 1024] [--runs 3] [--noise 0.01]``
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from functools import partial
from pathlib import Path

import numba
import numpy as np

from shadeform import metrics, synth
from shadeform.preprocess import apply_filter
from shadeform.regions import concave_masks, parse_regions
from shadeform.solvers.eikonal import eikonal_depth


def whole(size: int, axis: str) -> dict:
    return {"regions": [{"polygon": [[0, 0], [size, 0], [size, size], [0, size]], "axis": axis}]}


def box(size: int, x0: float, y0: float, x1: float, y1: float, axis: str) -> dict:
    """A rectangle given in fractions of the image, as a user would draw it."""
    corners = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
    return {"regions": [{"polygon": [[x * size, y * size] for x, y in corners], "axis": axis}]}


def cases(size: int):
    """(scene, label of the marking, regions document or None)."""
    # The vase's neck (concave along y between 0.12 and 0.41 of the height from the top), the
    # bumps scene's dent (centred at column 0.28, row 0.67 of the size) and the saddle's
    # concave direction (x).
    neck = box(size, 0.27, 0.125, 0.73, 0.40, "y")
    dent = box(size, 0.16, 0.55, 0.395, 0.785, "both")
    return [
        ("sphere", "", None),
        ("ellipsoid", "", None),
        ("cylinder", "", None),
        ("vase", "neck (y)", neck),
        ("vase", "none", None),
        ("bowl", "whole (both)", whole(size, "both")),
        ("saddle", "whole (x)", whole(size, "x")),
        ("bumps", "dent (both)", dent),
        ("bumps", "none", None),
    ]


def timed(fn, runs: int):
    result = fn()  # warm-up: loads the compiled kernels, and gives the result
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return result, statistics.median(times)


def accuracy_table(size: int, noise: float, runs: int) -> str:
    rows = []
    unfiltered = [case for case in cases(size)
                  if case[0] == "sphere" or (case[0] == "vase" and case[2] is not None)]
    for level, filtered, chosen in [(0.0, True, cases(size)), (noise, True, cases(size)),
                                    (noise, False, unfiltered)]:
        for name, label, document in chosen:
            scene = synth.scene(name, size=size, noise=level, seed=0)
            concave = concave_masks(parse_regions(document), scene.mask.shape) if document else None
            if level > 0 and filtered:
                image = apply_filter(scene.image, scene.mask, "gaussian:2")
                options = {"tol": 2e-2}
            else:
                image, options = scene.image, {}
            solve = partial(eikonal_depth, image, scene.mask, concave=concave, **options)
            result, seconds = timed(solve, runs)
            depth_err = metrics.depth_error(result.depth, scene.depth, scene.mask)
            angle_err = metrics.angular_error(result.normals, scene.normals, scene.mask)
            how = "filter + tol 2e-2" if level > 0 and filtered else "defaults"
            rows.append(f"| {name} | {label} | {level:.0%} | {how} | {depth_err:.3f} | "
                        f"{angle_err:.3f} | {len(result.sources)} | {seconds * 1e3:,.0f} |")
            print(rows[-1], file=sys.stderr, flush=True)
    header = ("| scene | concave regions | noise | settings | depth error % | normal error ° | "
              "sources | ms |\n|---|---|---:|---|---:|---:|---:|---:|")
    return header + "\n" + "\n".join(rows)


def speed_table(size: int, runs: int) -> str:
    scene = synth.scene("sphere", size=size)
    result, seconds = timed(partial(eikonal_depth, scene.image, scene.mask), runs)
    pixels = int(scene.mask.sum())
    rows = [f"| {stage} | {t * 1e3:,.0f} |" for stage, t in result.info["timings"].items()]
    rows.append(f"| **total (median of {runs})** | **{seconds * 1e3:,.0f}** |")
    header = (f"Sphere {size}x{size} ({pixels:,} object pixels): "
              f"{seconds * 1e3 / (pixels / 1e6):,.0f} ms per megapixel of object. Stages of the "
              "last run:\n\n| stage | ms |\n|---|---:|")
    return header + "\n" + "\n".join(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--big", type=int, default=1024)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--noise", type=float, default=0.01)
    parser.add_argument("--out", type=Path,
                        default=Path(__file__).parent / "results" / "eikonal.md")
    args = parser.parse_args(argv)

    accuracy = accuracy_table(args.size, args.noise, args.runs)
    speed = speed_table(args.big, args.runs)
    text = (
        "# Eikonal shape from shading (light at +z)\n\n"
        f"`python benchmarks/bench_eikonal.py`: {args.size}x{args.size} synthetic scenes, true "
        "mask, no boundary heights. Depth error: RMSE as % of the true depth range after fitting "
        "the offset; normal error: mean angle. Settings \"filter + tol 2e-2\": Gaussian sigma 2 "
        "inside the mask (`preprocess.apply_filter`), then `eikonal_depth(..., tol=2e-2)`. "
        f"Median of {args.runs} runs after a warm-up; {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}."
        "\n\n" + accuracy + "\n\n" + speed + "\n"
    )
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    temporary = args.out.with_suffix(".md.tmp")
    temporary.write_text(text, encoding="utf-8")
    temporary.replace(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
