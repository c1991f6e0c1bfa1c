"""Benchmark: the oblique-light solver on the synthetic scenes, accuracy and speed.

Three tables, errors as ``shadeform evaluate`` computes them (``metrics.depth_error`` with the
offset fitted, ``metrics.angular_error``), every scene with its ``synth.concave_regions`` and the
true mask:

1. the issue's bars: light (5, 5, 7), no noise, ``--size`` pixels (256 by default), all scenes,
   beside the 2002 propagation method (``refine=3``, path integration) on the same images;
2. light +z, slant 30 deg (tilt 45 deg) and (5, 5, 7), with 0, 1 % and 3 % noise, at
   ``--report-size`` pixels (256 by default). Noisy images are smoothed inside the mask
   (Gaussian, sigma 2, ``preprocess.apply_filter``) and solved with ``tol`` and ``dark`` set to
   twice the noise level; noise-free ones with the defaults. The last column is the median time
   of one solve over the row's seven scenes;
3. the time of one solve of the sphere and of the vase under (5, 5, 7) at ``--size`` and twice
   that (coarse to fine), median of ``--runs`` after a warm-up that loads the compiled kernels:
   wall time and the process's CPU time (the machine may be shared), stage by stage.

Writes ``benchmarks/results/oblique.md`` and prints the same tables.

Usage: ``python benchmarks/bench_oblique.py [--size 256] [--report-size 256] [--runs 3]``
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

#: The measurements behind the solver's design and constants, as they were taken (by hand, with
#: the solver of the time); kept with the results, not rerun by this script.
TUNING_HISTORY = """\
## Tuning history

The measurements behind the solver's choices, taken when each was made (with the solver of the
time, mostly at 256 px; not rerun by this script). Errors as in the tables above.

- **Marching order and hinge** (`BRIGHTNESS`, `HINGE`). On the vase under (5, 5, 7), marching
  nearest-first reached the neck above the belly-neck saddle from the side and left it in the
  wrong basin: 6.2 % depth, energy 9.6 against 0.02 from the true normals. The brightness term of
  the order and the hinge brought it to 3.0 % / 2.8° (energy 2.9).
- **`HINGE` and `BRIGHTNESS`**, set on the vase at (5, 5, 7) and at slant 30°, checked on the
  other scenes: at (5, 5, 7) the vase's depth error stays within 2.7-3.5 % for `HINGE` 100-1000
  and `BRIGHTNESS` 0.08-0.16 (no hinge: 4.2 %; `HINGE` 10,000: 6.5 %). `HINGE` 300 rather than 100
  made the bumps worse at slant 30° (58 % against 53 %).
- **`SHADOW_NZ`** 0.15 rather than `MIN_NZ` (0.05) took the vase's depth error over `BRIGHTNESS`
  0.11-0.14 from 3.4-4.5 % to 2.9-3.5 %, at the cost of the crescent's worst shadow error (7.4 % to
  8.7 % of the depth range; `test_shadow_is_a_constraint_not_a_cliff`).
- **Convexity tie-break across a concave region's edge** (the mean of the two pixels' signs
  rather than the pixel's own): the vase's mouth above its marked neck at slant 30°, 1252 pixels
  off by more than 10° with the pixel's sign, 1214 with the mean; at slant 45° 3.58 % depth
  error, 3.27 %.
- **One height datum per cap**: the vase under slant 30° has belly and neck caps 53 px apart
  (`d` = 0.021 on the brightest path between them: up to 11 px of height along `L`, in fact 10).
  On one datum their fronts met in a streak of wrong normals across the shoulder: 353 pixels off
  by more than 10° after the polish, 9 with a datum each.
- **Coarse to fine** (`COARSE`, `REFINE_ITERATIONS`). Sphere at 512 px with the first marching:
  1.41 % depth marched at full size, 0.22 % from the half-size start; with the present marching
  0.25 % and 0.24 %, but the full-size route took 14.6 s against 3.5 s. `COARSE = 320` keeps
  256 px images on the marching at full size: with the first marching the vase's depth error rose
  from 6.2 % to 7.3 % when a 128 px solution started it; with the present one the half-size start
  gives about the same errors (vase 3.0 %, sphere 0.23 %) in about 55-60 % of the time (not yet
  adopted).
- **Speed constants** (`SWEEP_SAMPLES`, `REBUILD`, `COARSE`, `REFINE_ITERATIONS`) were set on the
  sphere and the vase under (5, 5, 7) by their time at 256 and 512 px, with their errors at 256 px
  unchanged. `REBUILD`: a new preconditioner costs about 50 CG iterations, but letting the count
  grow costs more over the sweeps (at 256 px, thresholds of 10 to 40 were as fast or slower).
- **The descent on one thread**: spread over threads on a shared machine, a depth block of about
  10 ms (256 px, one core) took 0.4 s.
"""


def solve(scene, size, noise):
    concave_x, concave_y = concave_masks(
        parse_regions(synth.concave_regions(scene.name, size=size)), scene.mask.shape
    )
    if noise > 0:
        image = apply_filter(scene.image, scene.mask, "gaussian:2")
        options = {"tol": 2 * noise, "dark": 2 * noise}
    else:
        image, options = scene.image, {}
    start = time.perf_counter()
    result = oblique_depth(
        image, scene.mask, light=scene.light, concave_x=concave_x, concave_y=concave_y, **options
    )
    seconds = time.perf_counter() - start
    return (
        metrics.depth_error(result.depth, scene.depth, fit="offset"),
        metrics.angular_error(result.normals, scene.normals),
        seconds,
    )


def bar_table(size: int) -> str:
    rows = []
    for name in synth.SCENES:
        scene = synth.scene(name, size=size, light=BAR_LIGHT)
        depth, angle, seconds = solve(scene, size, 0.0)
        # named: "auto" may pick the oblique solver itself for this light
        rec = reconstruct(
            scene.image,
            mask=scene.mask,
            light=scene.light,
            solver="propagation",
            refine=3,
            integrator="paths",
            concave=synth.concave_regions(name, size=size),
        )
        old_depth = metrics.depth_error(rec.depth, scene.depth, fit="offset")
        old_angle = metrics.angular_error(rec.normals, scene.normals)
        bar = BARS.get(name)
        verdict = (
            ""
            if bar is None
            else (
                "met"
                if depth <= bar[0] and angle <= bar[1]
                else f"**not met** (bar {bar[0]:g} % / {bar[1]:g}°)"
            )
        )
        rows.append(
            f"| {name} | {depth:.2f} | {angle:.2f} | {seconds:.1f} | {old_depth:.2f} | "
            f"{old_angle:.2f} | {verdict} |"
        )
        print(rows[-1], file=sys.stderr, flush=True)
    header = (
        "| scene | oblique depth % | oblique normals ° | s | propagation depth % | "
        "propagation normals ° | bar |\n|---|---:|---:|---:|---:|---:|---|"
    )
    return header + "\n" + "\n".join(rows)


def report_table(size: int) -> str:
    lights = [
        ("+z", (0.0, 0.0, 1.0)),
        ("slant 30°, tilt 45°", tuple(light_from_slant_tilt(30, 45))),
        ("(5, 5, 7)", BAR_LIGHT),
    ]
    rows = []
    for label, light in lights:
        for noise in (0.0, 0.01, 0.03):
            cells = []
            times = []
            for name in synth.SCENES:
                scene = synth.scene(name, size=size, light=light, noise=noise, seed=0)
                depth, angle, seconds = solve(scene, size, noise)
                cells.append(f"{depth:.1f} / {angle:.1f}")
                times.append(seconds)
            rows.append(
                f"| {label} | {noise:.0%} | " + " | ".join(cells) + f" | {statistics.median(times):.2f} |"
            )
            print(rows[-1], file=sys.stderr, flush=True)
    header = (
        "| light | noise | "
        + " | ".join(synth.SCENES)
        + " | s per solve |\n|---|---:|"
        + "---:|" * (len(synth.SCENES) + 1)
    )
    return header + "\n" + "\n".join(rows)


def speed_rows(name: str, size: int, runs: int) -> tuple[str, str]:
    scene = synth.scene(name, size=size, light=BAR_LIGHT)
    concave_x, concave_y = concave_masks(
        parse_regions(synth.concave_regions(name, size=size)), scene.mask.shape
    )
    oblique_depth(
        scene.image, scene.mask, light=scene.light, concave_x=concave_x, concave_y=concave_y
    )  # warm-up
    walls, cpus = [], []
    result = None
    for _ in range(runs):
        wall, cpu = time.perf_counter(), time.process_time()
        result = oblique_depth(
            scene.image, scene.mask, light=scene.light, concave_x=concave_x, concave_y=concave_y
        )
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    depth = metrics.depth_error(result.depth, scene.depth, fit="offset")
    angle = metrics.angular_error(result.normals, scene.normals)
    stages = ", ".join(f"{stage} {t * 1e3:,.0f}" for stage, t in result.info["timings"].items())
    row = (
        f"| {name} | {size} | {int(scene.mask.sum()):,} | {result.info['sweeps']} | "
        f"{statistics.median(walls):.2f} | {statistics.median(cpus):.2f} | {depth:.2f} | "
        f"{angle:.2f} |"
    )
    print(row, file=sys.stderr, flush=True)
    return row, f"- {name} {size}: {stages}"


def speed_table(size: int, runs: int) -> str:
    rows, stages = [], []
    for n in (size, 2 * size):
        for name in ("sphere", "vase"):
            row, stage = speed_rows(name, n, runs)
            rows.append(row)
            stages.append(stage)
    return (
        f"Light (5, 5, 7), concave regions given; median of {runs} runs after a warm-up. "
        "Sizes above `oblique.COARSE` px start from the half-size solution (coarse to fine) "
        "and take at most `oblique.REFINE_ITERATIONS` sweeps at full size.\n\n"
        "| scene | px | object pixels | sweeps (last level) | wall s | CPU s | depth % | "
        "normals ° |\n|---|---:|---:|---:|---:|---:|---:|---:|\n"
        + "\n".join(rows)
        + "\n\nStages of the last run (ms, wall):\n\n"
        + "\n".join(stages)
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--report-size", type=int, default=256)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "oblique.md")
    args = parser.parse_args(argv)

    bars = bar_table(args.size)
    report = report_table(args.report_size)
    speed = speed_table(args.size, args.runs)
    text = (
        "# Oblique-light shape from shading\n\n"
        "`python benchmarks/bench_oblique.py`: synthetic scenes with their concave regions "
        "(`synth.concave_regions`), true mask, `albedo` = the brightest object pixel. Depth error: RMSE "
        "as % of the true depth range after fitting the offset; normal error: mean angle "
        f"(as `shadeform evaluate`). {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"numpy {np.__version__}, numba {numba.__version__}. The solver runs on one thread "
        "(its descent pins numba to one; the marching is serial).\n\n"
        f"## The bars: light (5, 5, 7), no noise, {args.size}x{args.size}\n\n" + bars + "\n\n"
        f"## Other lights and noise, {args.report_size}x{args.report_size} (depth % / normals °)\n\n"
        "Noisy images: Gaussian sigma 2 inside the mask, then `tol` and `dark` at twice the noise "
        "level.\n\n" + report + "\n\n## Speed\n\n" + speed + "\n\n" + TUNING_HISTORY
    )
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    temporary = args.out.with_suffix(".md.tmp")
    temporary.write_text(text, encoding="utf-8")
    temporary.replace(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
