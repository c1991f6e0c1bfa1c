"""Benchmark: the oblique-light solver on the synthetic scenes, accuracy and speed.

Three tables, errors as ``shadeform evaluate`` computes them (``metrics.depth_error`` with the
offset fitted, ``metrics.angular_error``), every scene with its ``synth.concave_regions`` and the
true mask:

1. the issue's bars: light (5, 5, 7), no noise, ``--size`` pixels (256 by default), all scenes,
   beside the 2002 propagation method (``refine=3``, path integration) on the same images;
2. light +z, slant 30 deg (tilt 45 deg) and (5, 5, 7), with 0, 1 % and 3 % noise, at
   ``--report-size`` pixels (128 by default, to keep the run short). Noisy images are smoothed
   inside the mask (Gaussian, sigma 2, ``preprocess.apply_filter``) and solved with ``tol`` and
   ``dark`` set to twice the noise level; noise-free ones with the defaults;
3. the time of one ``--size`` solve of the sphere under (5, 5, 7), median of ``--runs`` after a
   warm-up that loads the compiled kernels, stage by stage.

Writes ``benchmarks/results/oblique.md`` and prints the same tables.

Usage: ``python benchmarks/bench_oblique.py [--size 256] [--report-size 128] [--runs 3]``
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numba
import numpy as np

from shadeform import metrics, reconstruct, synth
from shadeform.light import light_from_slant_tilt
from shadeform.preprocess import apply_filter
from shadeform.regions import concave_masks, parse_regions
from shadeform.solvers.oblique import oblique_depth

BAR_LIGHT = (5.0, 5.0, 7.0)
#: The issue's bars: (depth %, normals deg) at the light (5, 5, 7), 256 px, no noise.
BARS = {"sphere": (3.0, 4.0), "vase": (4.0, 6.0)}


def solve(scene, size, noise):
    concave = concave_masks(parse_regions(synth.concave_regions(scene.name, size=size)),
                            scene.mask.shape)
    if noise > 0:
        image = apply_filter(scene.image, scene.mask, "gaussian:2")
        options = {"tol": 2 * noise, "dark": 2 * noise}
    else:
        image, options = scene.image, {}
    start = time.perf_counter()
    result = oblique_depth(image, scene.mask, light=scene.light, concave=concave, **options)
    seconds = time.perf_counter() - start
    return (metrics.depth_error(result.depth, scene.depth, fit="offset"),
            metrics.angular_error(result.normals, scene.normals), seconds)


def bar_table(size: int) -> str:
    rows = []
    for name in synth.SCENES:
        scene = synth.scene(name, size=size, light=BAR_LIGHT)
        depth, angle, seconds = solve(scene, size, 0.0)
        rec = reconstruct(scene.image, mask=scene.mask, light=scene.light,
                          concave=synth.concave_regions(name, size=size))
        old_depth = metrics.depth_error(rec.depth, scene.depth, fit="offset")
        old_angle = metrics.angular_error(rec.normals, scene.normals)
        bar = BARS.get(name)
        verdict = "" if bar is None else (
            "met" if depth <= bar[0] and angle <= bar[1] else
            f"**not met** (bar {bar[0]:g} % / {bar[1]:g}°)")
        rows.append(f"| {name} | {depth:.2f} | {angle:.2f} | {seconds:.1f} | {old_depth:.2f} | "
                    f"{old_angle:.2f} | {verdict} |")
        print(rows[-1], file=sys.stderr, flush=True)
    header = ("| scene | oblique depth % | oblique normals ° | s | propagation depth % | "
              "propagation normals ° | bar |\n|---|---:|---:|---:|---:|---:|---|")
    return header + "\n" + "\n".join(rows)


def report_table(size: int) -> str:
    lights = [("+z", (0.0, 0.0, 1.0)), ("slant 30°, tilt 45°", tuple(light_from_slant_tilt(30, 45))),
              ("(5, 5, 7)", BAR_LIGHT)]
    rows = []
    for label, light in lights:
        for noise in (0.0, 0.01, 0.03):
            cells = []
            for name in synth.SCENES:
                scene = synth.scene(name, size=size, light=light, noise=noise, seed=0)
                depth, angle, _ = solve(scene, size, noise)
                cells.append(f"{depth:.1f} / {angle:.1f}")
            rows.append(f"| {label} | {noise:.0%} | " + " | ".join(cells) + " |")
            print(rows[-1], file=sys.stderr, flush=True)
    header = ("| light | noise | " + " | ".join(synth.SCENES) + " |\n|---|---:|"
              + "---:|" * len(synth.SCENES))
    return header + "\n" + "\n".join(rows)


def speed_table(size: int, runs: int) -> str:
    scene = synth.scene("sphere", size=size, light=BAR_LIGHT)
    oblique_depth(scene.image, scene.mask, light=scene.light)  # warm-up: compiled kernels
    times = []
    result = None
    for _ in range(runs):
        start = time.perf_counter()
        result = oblique_depth(scene.image, scene.mask, light=scene.light)
        times.append(time.perf_counter() - start)
    rows = [f"| {stage} | {t * 1e3:,.0f} |" for stage, t in result.info["timings"].items()]
    rows.append(f"| **total (median of {runs})** | **{statistics.median(times) * 1e3:,.0f}** |")
    return (f"Sphere {size}x{size} under (5, 5, 7), {int(scene.mask.sum()):,} object pixels, "
            f"{result.info['sweeps']} descent sweeps. Stages of the last run:\n\n"
            "| stage | ms |\n|---|---:|\n" + "\n".join(rows))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--report-size", type=int, default=128)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--out", type=Path,
                        default=Path(__file__).parent / "results" / "oblique.md")
    args = parser.parse_args(argv)

    bars = bar_table(args.size)
    report = report_table(args.report_size)
    speed = speed_table(args.size, args.runs)
    text = (
        "# Oblique-light shape from shading\n\n"
        "`python benchmarks/bench_oblique.py`: synthetic scenes with their concave regions "
        "(`synth.concave_regions`), true mask, `k` = the brightest object pixel. Depth error: RMSE "
        "as % of the true depth range after fitting the offset; normal error: mean angle "
        f"(as `shadeform evaluate`). {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"numpy {np.__version__}, numba {numba.__version__}.\n\n"
        f"## The bars: light (5, 5, 7), no noise, {args.size}x{args.size}\n\n" + bars + "\n\n"
        f"## Other lights and noise, {args.report_size}x{args.report_size} (depth % / normals °)\n\n"
        "Noisy images: Gaussian sigma 2 inside the mask, then `tol` and `dark` at twice the noise "
        "level.\n\n" + report + "\n\n## Speed\n\n" + speed + "\n"
    )
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    temporary = args.out.with_suffix(".md.tmp")
    temporary.write_text(text, encoding="utf-8")
    temporary.replace(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
