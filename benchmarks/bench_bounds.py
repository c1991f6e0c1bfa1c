"""Benchmark: how often the outline's bound on the depth applies, and what it does to the normals.

:func:`shadeform.reconstruct` pulls a depth that strays past what the object's outline allows back
toward it (:func:`shadeform.solvers.bounds.bound_depth`, ``info["depth_bounded"]``). This solves
each case once with that stage left out, bounds the result as the pipeline does, and reports
where it applied (share of the object, how far past the bound) and the mean angle between the
recovered and true normals before and after, over the whole object and over the pixels it
changed:

- the twelve MIT-Berkeley photos as a user has them (``real_data.mit_photo``: the luma of
  ``original.png`` scaled by its 99.9th percentile in the mask), light estimated;
- the synthetic grid of ``bench_methods.py`` (every solver, scene, light and noise level, the
  concave regions a user would draw), where nothing should change.

Usage: ``python benchmarks/bench_bounds.py [--size 128] [--skip-grid] [--out benchmarks/results/bounds.md]``
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path
from unittest import mock

import numpy as np

import real_data
import shadeform
from bench_methods import LIGHTS, NOISES, SEED, methods, solve
from shadeform import metrics, synth
from shadeform.errors import InputError
from shadeform.io.atomic import atomic_write
from shadeform.solvers.bounds import DepthBound, bound_depth


def unbounded(function, *args, **kwargs):
    """``function(*args, **kwargs)`` (a reconstruction) with the pipeline's bound left out, and
    the bound of its result."""
    with mock.patch("shadeform.pipeline.bound_depth", _left_out):
        rec = function(*args, **kwargs)
    return rec, bound_depth(rec.depth, rec.normals, rec.mask)


def _left_out(depth, normals, mask) -> DepthBound:
    return DepthBound(depth, normals, 0.0, 0.0)


def _angles(normals, truth, where) -> float:
    """Mean angle (degrees) between ``normals`` and ``truth`` over ``where``; NaN where empty."""
    return float(metrics.angular_error(normals, truth, where)) if where.any() else float("nan")


def real_rows() -> list[dict]:
    rows = []
    for name in real_data.MIT:
        case = real_data.mit_photo(name)
        start = time.perf_counter()
        rec, bound = unbounded(shadeform.reconstruct, case.image, mask=case.mask, light="estimate")
        changed = case.valid & np.any(bound.normals != rec.normals, axis=-1)
        rows.append(
            {
                "case": name,
                "method": rec.info["solver"],
                "applied": bound.applied,
                "pixels": bound.pixels,
                "max_over": bound.max_over,
                "before": real_data.angular_error(rec.normals, case),
                "after": real_data.angular_error(bound.normals, case),
                "changed": int(np.count_nonzero(changed)),
                "before_changed": _angles(rec.normals, case.normals, changed),
                "after_changed": _angles(bound.normals, case.normals, changed),
                "depth_before": real_data.z_mae(rec.depth, case.depth, case.valid),
                "depth_after": real_data.z_mae(bound.depth, case.depth, case.valid),
                "seconds": time.perf_counter() - start,
            }
        )
        print(_line(rows[-1]), flush=True)
    return rows


def grid_rows(size: int) -> list[dict]:
    rows = []
    for label, kwargs in methods():
        for scene_name in synth.SCENES:
            for light_label, light in LIGHTS:
                for noise in NOISES:
                    scene = synth.scene(scene_name, size=size, light=light, noise=noise, seed=SEED)
                    try:
                        rec, bound = unbounded(solve, scene, kwargs, size)
                    except InputError:
                        continue  # a light the method refuses: n/a in bench_methods
                    row = {
                        "case": f"{label} / {scene_name} / {light_label} / noise {noise:.0%}",
                        "method": label,
                        "applied": bound.applied,
                        "pixels": bound.pixels,
                        "max_over": bound.max_over,
                        "before": metrics.angular_error(rec.normals, scene.normals),
                        "after": metrics.angular_error(bound.normals, scene.normals),
                        "depth_before": metrics.depth_error(rec.depth, scene.depth, scene.mask),
                        "depth_after": metrics.depth_error(bound.depth, scene.depth, scene.mask),
                    }
                    rows.append(row)
                    if row["applied"]:
                        print(_line(row), flush=True)
    return rows


def _line(row: dict) -> str:
    said = f"past {100 * row['pixels']:.1f} %" if row["applied"] else "within"
    return (
        f"{row['case']:50s} {said:13s} max {row['max_over']:.2f}  error {row['before']:.2f} -> "
        f"{row['after']:.2f} deg, depth {row['depth_before']:.1f} -> {row['depth_after']:.1f}"
    )


def report(real: list[dict], grid: list[dict], size: int) -> str:
    lines = [
        "# The outline's bound on the depth",
        "",
        f"`python benchmarks/bench_bounds.py --size {size}`, {platform.platform()}. The bound: "
        "`shadeform.solvers.bounds` (a pixel may stray from the result's fitted shape, a tilt plus "
        "the silhouette's round shape scaled, by half the outline's diameter; past it the excess is "
        "compressed smoothly). Errors: mean angle to the true normals, degrees.",
        "",
        "## MIT-Berkeley photos as a user has them (`original.png`, light estimated)",
        "",
        "Depth error: SIRFS's Z-MAE (mean absolute height error after the median offset, pixels).",
        "",
        "| object | method | bound applied | share past | max / bound | error before | after | "
        "changed pixels | their error before | after | depth error before | after |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in real:
        lines.append(
            f"| {r['case']} | {r['method']} | {'yes' if r['applied'] else 'no'} | "
            f"{100 * r['pixels']:.1f} % | {r['max_over']:.2f} | {r['before']:.2f} | {r['after']:.2f} | "
            f"{r['changed']} | {r['before_changed']:.2f} | {r['after_changed']:.2f} | "
            f"{r['depth_before']:.1f} | {r['depth_after']:.1f} |"
        )
    if grid:
        applied = [r for r in grid if r["applied"]]
        lines += [
            "",
            f"## Synthetic grid of bench_methods.py ({size} px)",
            "",
            f"{len(grid)} results; the bound applied to {len(applied)} (the others are returned as "
            "they are); the largest share of the bound reached by the others: "
            f"{max((r['max_over'] for r in grid if not r['applied']), default=0):.2f}. Depth error: "
            "RMSE as a percent of the true depth range (`shadeform evaluate`).",
        ]
        if applied:
            angle = np.array([r["after"] - r["before"] for r in applied])
            depth = np.array([r["depth_after"] - r["depth_before"] for r in applied])
            lines += [
                "",
                f"Where it applied: smallest normal error before {min(r['before'] for r in applied):.1f} "
                f"degrees; change of the normal error median {np.median(angle):+.2f}, from "
                f"{angle.min():+.2f} to {angle.max():+.2f} degrees; change of the depth error median "
                f"{np.median(depth):+.1f}, from {depth.min():+.1f} to {depth.max():+.1f} points.",
                "",
                "| case | share past | max / bound | error before | after | depth error before | after |",
                "|---|---:|---:|---:|---:|---:|---:|",
            ]
            lines += [
                f"| {r['case']} | {100 * r['pixels']:.1f} % | {r['max_over']:.2f} | {r['before']:.2f} | "
                f"{r['after']:.2f} | {r['depth_before']:.1f} | {r['depth_after']:.1f} |"
                for r in applied
            ]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128, help="side of the synthetic scenes, pixels")
    parser.add_argument("--skip-grid", action="store_true", help="the real photos only")
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results" / "bounds.md")
    args = parser.parse_args()
    if not real_data.available():
        raise SystemExit(f"the real photos are not there: {real_data.DATA}")
    real = real_rows()
    grid = [] if args.skip_grid else grid_rows(args.size)
    text = report(real, grid, args.size)
    with atomic_write(args.out, mode="w") as handle:
        handle.write(text)
    print(text)


if __name__ == "__main__":
    main()
