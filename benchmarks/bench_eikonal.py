"""Benchmark: the eikonal solver (light at +z) on the synthetic scenes, accuracy and speed.

For every scene (256 x 256 by default, true mask given, no boundary heights) and noise level, one
row: the concave regions the user marked, the depth error (RMSE as a percent of the true depth
range, after fitting the offset; ``shadeform.metrics.depth_error``), the mean angular error of the
normals, the number of singular points used and the median wall time of ``eikonal_depth`` over
``--runs`` runs after a warm-up that loads the compiled kernels. Noisy images (1% of the albedo by
default) are first smoothed inside the mask by a Gaussian of sigma 2 (``preprocess.apply_filter``)
and solved with ``tol=2e-2``; the noise-free ones use the defaults, and so do the last rows (sphere
and marked vase, noisy and unfiltered). Then the time of the 1024 x 1024 sphere, stage by stage,
and sweeps of ``steep`` and ``tol`` around the defaults ``STEEP`` and ``TOL`` (and the ``tol``
advised for noisy images) on the scenes whose marks decide them, one run each.

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
from shadeform.io.atomic import atomic_write
from shadeform.preprocess import apply_filter
from shadeform.regions import concave_masks, parse_regions
from shadeform.solvers.eikonal import STEEP, TOL, eikonal_depth


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


def markdown(columns: list[str], align: str, rows: list[list[str]]) -> str:
    """A markdown table; ``align`` has one letter per column, ``l`` or ``r``."""
    rule = "|".join("---:" if a == "r" else "---" for a in align)
    lines = ["| " + " | ".join(columns) + " |", f"|{rule}|"]
    return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in rows])


def prepared(scene, document, *, smooth: bool) -> tuple[np.ndarray, dict]:
    """The image to solve (Gaussian sigma 2 inside the mask if ``smooth``) and the concave masks of
    ``document`` as ``eikonal_depth`` options."""
    options = {}
    if document:
        concave_x, concave_y = concave_masks(parse_regions(document), scene.mask.shape)
        options = {"concave_x": concave_x, "concave_y": concave_y}
    image = apply_filter(scene.image, scene.mask, "gaussian:2") if smooth else scene.image
    return image, options


def errors(result, scene) -> tuple[float, float]:
    """Depth error % and mean normal error in degrees."""
    return (
        metrics.depth_error(result.depth, scene.depth, scene.mask),
        metrics.angular_error(result.normals, scene.normals, scene.mask),
    )


def accuracy_table(size: int, noise: float, runs: int) -> str:
    rows = []
    unfiltered = [case for case in cases(size) if case[0] == "sphere" or (case[0] == "vase" and case[2])]
    for level, filtered, chosen in [
        (0.0, True, cases(size)),
        (noise, True, cases(size)),
        (noise, False, unfiltered),
    ]:
        smooth = level > 0 and filtered
        for name, label, document in chosen:
            scene = synth.scene(name, size=size, noise=level, seed=0)
            image, options = prepared(scene, document, smooth=smooth)
            if smooth:
                options["tol"] = 2e-2
            result, seconds = timed(partial(eikonal_depth, image, scene.mask, **options), runs)
            depth_err, angle_err = errors(result, scene)
            how = "filter + tol 2e-2" if smooth else "defaults"
            cells = [name, label, f"{level:.0%}", how, f"{depth_err:.3f}", f"{angle_err:.3f}"]
            rows.append([*cells, str(len(result.singular_points)), f"{seconds * 1e3:,.0f}"])
            print(" | ".join(rows[-1]), file=sys.stderr, flush=True)
    columns = ["scene", "concave regions", "noise", "settings", "depth error %", "normal error °"]
    return markdown([*columns, "singular points", "ms"], "llrlrrrr", rows)


def speed_table(size: int, runs: int) -> str:
    scene = synth.scene("sphere", size=size)
    result, seconds = timed(partial(eikonal_depth, scene.image, scene.mask), runs)
    pixels = int(scene.mask.sum())
    rows = [[stage, f"{t * 1e3:,.0f}"] for stage, t in result.info["timings"].items()]
    rows.append([f"**total (median of {runs})**", f"**{seconds * 1e3:,.0f}**"])
    return (
        f"Sphere {size}x{size} ({pixels:,} object pixels): {seconds * 1e3 / (pixels / 1e6):,.0f} ms "
        "per megapixel of object. Stages of the last run:\n\n" + markdown(["stage", "ms"], "lr", rows)
    )


def sweep_table(size: int, noise: float, option: str, values, default) -> str:
    """Depth error % / normal error ° of each well-marked scene for each value of ``option``."""
    chosen = [
        case
        for case in cases(size)
        if case[0] in ("sphere", "ellipsoid", "cylinder", "bowl")
        or (case[0] in ("vase", "bumps") and case[2])
    ]
    problems = []
    for name, _, document in chosen:
        scene = synth.scene(name, size=size, noise=noise, seed=0)
        problems.append((scene, *prepared(scene, document, smooth=noise > 0)))
    rows = []
    for value in values:
        shown = "no arc update" if value >= 1e9 else f"{value:g}"
        row = [f"**{shown}** (default)" if value == default else shown]
        for scene, image, options in problems:
            depth_err, angle_err = errors(
                eikonal_depth(image, scene.mask, **options, **{option: value}), scene
            )
            row.append(f"{depth_err:.3f} / {angle_err:.3f}")
        rows.append(row)
        print(" | ".join(rows[-1]), file=sys.stderr, flush=True)
    names = [f"{name}, {label}" if label else name for name, label, _ in chosen]
    return markdown([option, *names], "l" + "r" * len(names), rows)


def constants_section(size: int, noise: float) -> str:
    steep = sweep_table(size, 0.0, "steep", [0.5, 1.0, STEEP, 2.0, 3.0, 5.0, 1e9], STEEP)
    clean = sweep_table(size, 0.0, "tol", [1e-4, TOL, 1e-2], TOL)
    noisy = sweep_table(size, noise, "tol", [5e-3, 1e-2, 2e-2, 3e-2, 5e-2], None)
    return (
        "## Constants\n\n"
        f"The defaults of `eikonal_depth` against other values ({size}x{size} scenes whose marks "
        "decide the surface, one run each; cells: depth error % / normal error °).\n\n"
        "`steep` (`STEEP`), the slope above which the arc update replaces finite differences, "
        "noise-free. Without it (last row) the finite differences overshoot near the occluding contour; "
        "set low, accuracy drops on the gentler slopes, where the arc update interpolates the "
        "angle linearly.\n\n" + steep + "\n\n"
        "`tol` (`TOL`), the tolerance of the singular regions on `I / albedo`, noise-free:\n\n"
        + clean
        + f"\n\n`tol` at {noise:.0%} noise after a Gaussian of sigma 2 inside the mask (the advice in "
        "the docstrings: 2e-2). Lower, the bumps scene fails; higher, the marked vase does.\n\n" + noisy
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--big", type=int, default=1024)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--noise", type=float, default=0.01)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "eikonal.md")
    args = parser.parse_args(argv)

    accuracy = accuracy_table(args.size, args.noise, args.runs)
    speed = speed_table(args.big, args.runs)
    constants = constants_section(args.size, args.noise)
    text = (
        "# Eikonal shape from shading (light at +z)\n\n"
        f"`python benchmarks/bench_eikonal.py`: {args.size}x{args.size} synthetic scenes, true "
        "mask, no boundary heights. Depth error: RMSE as % of the true depth range after fitting "
        'the offset; normal error: mean angle. Settings "filter + tol 2e-2": Gaussian sigma 2 '
        "inside the mask (`preprocess.apply_filter`), then `eikonal_depth(..., tol=2e-2)`. "
        f"Median of {args.runs} runs after a warm-up; {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}."
        "\n\n" + accuracy + "\n\n" + speed + "\n\n" + constants + "\n"
    )
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, mode="w") as file:
        file.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
