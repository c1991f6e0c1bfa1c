"""Benchmark: every reconstruction method on every synthetic scene, light and noise level.

The grid is method x scene x light x noise:

- methods: every registered solver (:func:`shadeform.solvers.solver_names`: the methods less "auto", which
  picks one of them by the light: its choice is reported), read when the script runs (a new
  solver is benchmarked without touching this file), with its default options, plus
  "propagation (2002)": ``solver="propagation", refine=0, integrator="paths"``, the report's
  algorithm exactly;
- scenes: :data:`shadeform.synth.SCENES`, ``--size`` pixels square, true mask, true light, and the
  concave regions a user would draw (:func:`shadeform.synth.concave_regions`);
- lights: +z, and slant 30 and 45 degrees at tilt 45 degrees (from the upper right);
- noise: Gaussian, 0, 1% and 3% of the albedo (seed 0).

Errors are those of ``shadeform evaluate`` (``src/shadeform/cli/tools.py``): RMSE of the depth as a
percent of the true depth range after fitting the free offset
(:func:`shadeform.metrics.depth_error`), and the mean angle between recovered and true normals
(:func:`shadeform.metrics.angular_error`). A method that refuses a light with
:class:`shadeform.InputError` (the eikonal solver needs the light at +z) is "n/a" there, and its
message is printed under the table; any other exception is a bug and stops the run. Time is the
median wall time of ``reconstruct`` over ``--repeats`` runs after a warm-up (fewer runs for a
configuration whose runs have already taken ``--budget`` seconds); memory is measured once per
method on one configuration.

Writes to ``--out`` (default ``benchmarks/results``): ``methods.md`` (summary, best method per
scene and light, speed and memory, full table), ``methods_depth.png`` and ``methods_angle.png``
(heatmaps: rows scene, columns method x light, one panel per noise level),
``methods_noise.png`` (error against noise) and ``showcase.png`` (input, recovered normals and
mesh of the vase at slant 30 degrees by the method with the lowest depth error there).

Usage: ``python benchmarks/bench_methods.py [--size 256] [--repeats 3] [--budget 10] [--quick]``
(``--quick``: 128 pixels, one run per configuration, for a fast check).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
import tracemalloc
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

import shadeform
from shadeform import metrics, solvers, synth
from shadeform.errors import InputError
from shadeform.io.atomic import atomic_write
from shadeform.light import light_from_slant_tilt

RESULTS = Path(__file__).resolve().parent / "results"
#: Tilt of the oblique lights, degrees from +x toward +y: light from the upper right.
TILT = 45.0
LIGHTS = (
    ("+z", (0.0, 0.0, 1.0)),
    ("slant 30°", tuple(light_from_slant_tilt(30.0, TILT))),
    ("slant 45°", tuple(light_from_slant_tilt(45.0, TILT))),
)
NOISES = (0.0, 0.01, 0.03)
SEED = 0
#: The configuration of the showcase picture: an oblique light on a shape with a concave neck.
SHOWCASE = ("vase", "slant 30°", 0.0)
#: Label of the report's algorithm exactly, benchmarked beside every registered solver.
LEGACY = "propagation (2002)"


@dataclass(frozen=True)
class Row:
    """One method on one scene, light and noise level.

    ``depth_pct``, ``angle_deg`` and ``seconds`` are NaN and ``note`` holds the method's
    :class:`InputError` message where the method cannot handle the configuration ("n/a").
    """

    method: str
    scene: str
    light: str
    noise: float
    depth_pct: float
    angle_deg: float
    seconds: float
    runs: int
    object_pixels: int
    note: str = ""

    @property
    def available(self) -> bool:
        return not self.note


@dataclass(frozen=True)
class Memory:
    """Peak memory of one ``reconstruct`` call, in bytes, and the configuration measured."""

    method: str
    scene: str
    light: str
    traced: int
    rss: int | None  # growth of the resident set; None where the OS cannot report it


def methods() -> list[tuple[str, dict]]:
    """(label, keyword arguments of ``reconstruct``) of every solver, read now from the registry.

    The solvers are :func:`shadeform.solvers.solver_names`: the methods less "auto", which only
    picks one of them for the light (its choice is reported, not run again).
    """
    found = []
    for name in solvers.solver_names():
        found.append((name, {"solver": name}))
        if name == "propagation":
            found.append((LEGACY, {"solver": "propagation", "refine": 0, "integrator": "paths"}))
    return found


@functools.cache
def _regions(name: str, size: int) -> dict:
    # built once per scene, outside the timed calls (reconstruct only reads it)
    return synth.concave_regions(name, size=size)


def solve(scene: synth.Scene, kwargs: dict, size: int):
    """``reconstruct`` on a scene as a user would call it: true mask, true light, drawn regions."""
    return shadeform.reconstruct(
        scene.image, mask=scene.mask, light=scene.light, concave=_regions(scene.name, size), **kwargs
    )


def warm_up(chosen: Sequence[tuple[str, dict]], lights: Sequence[tuple[str, tuple]]) -> None:
    """Load (or compile) every method's numba kernels on a tiny scene, so no row pays for it."""
    for _, kwargs in chosen:
        for _, light in lights:
            for name in ("sphere", "bowl"):  # convex and concave code paths
                with contextlib.suppress(InputError):  # a light the method refuses
                    solve(synth.scene(name, size=24, light=light), kwargs, 24)


def timed(fn: Callable[[], object], repeats: int, budget: float):
    """Result of ``fn`` and the median seconds of up to ``repeats`` calls; calls stop early once
    their total passes ``budget`` seconds (at least one call is made)."""
    times = []
    result = None
    while len(times) < repeats and (not times or sum(times) < budget):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return result, statistics.median(times), len(times)


def run_grid(
    *,
    size: int = 256,
    repeats: int = 3,
    budget: float = math.inf,
    scenes: Sequence[str] = synth.SCENES,
    lights: Sequence[tuple[str, tuple]] = LIGHTS,
    noises: Sequence[float] = NOISES,
    chosen: Sequence[tuple[str, dict]] | None = None,
    warm: bool = True,
    progress: Callable[[Row], None] | None = None,
) -> list[Row]:
    """Run every method on every scene, light and noise level.

    Parameters
    ----------
    size : int
        Side of the synthetic images in pixels.
    repeats : int
        Timed runs per configuration (the median is reported); the first is also the result.
    budget : float
        Seconds after which a configuration gets no more timed runs.
    scenes, lights, noises : sequences
        The grid: scene names, (label, light direction) pairs, noise levels (fraction of albedo).
    chosen : sequence of (label, kwargs), optional
        Methods to run; by default :func:`methods`.
    warm : bool
        Run every method on tiny scenes first (:func:`warm_up`), so no timed run loads kernels.
    progress : callable, optional
        Called with each row as soon as it is measured.

    Returns
    -------
    list of Row
        Ordered by scene, light, noise, then method.
    """
    chosen = methods() if chosen is None else list(chosen)
    if warm:
        warm_up(chosen, lights)
    rows = []
    for name in scenes:
        for light_label, light in lights:
            for noise in noises:
                scene = synth.scene(name, size=size, light=light, noise=noise, seed=SEED)
                pixels = int(scene.mask.sum())
                for label, kwargs in chosen:
                    try:
                        rec, seconds, runs = timed(
                            functools.partial(solve, scene, kwargs, size), repeats, budget
                        )
                    except InputError as error:
                        row = Row(
                            label,
                            name,
                            light_label,
                            noise,
                            math.nan,
                            math.nan,
                            math.nan,
                            0,
                            pixels,
                            note=str(error),
                        )
                    else:
                        row = Row(
                            label,
                            name,
                            light_label,
                            noise,
                            depth_pct=metrics.depth_error(rec.depth, scene.depth, fit="offset"),
                            angle_deg=metrics.angular_error(rec.normals, scene.normals),
                            seconds=seconds,
                            runs=runs,
                            object_pixels=pixels,
                        )
                    rows.append(row)
                    if progress is not None:
                        progress(row)
    return rows


def _rss_now() -> int | None:
    """Resident set size in bytes (Linux), after resetting the peak so the next one is fresh."""
    try:
        with open("/proc/self/clear_refs", "w") as handle:
            handle.write("5")  # resets VmHWM, the kernel's peak resident set
        return _status_bytes("VmRSS")
    except OSError:
        return None


def _status_bytes(field: str) -> int | None:
    with open("/proc/self/status") as handle:
        for line in handle:
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    return None


def peak_memory(
    label: str, kwargs: dict, light_label: str, *, size: int, scene_name: str = "sphere"
) -> Memory | None:
    """Peak memory of one method on one scene (noise 0) under one light of :data:`LIGHTS`; None
    if the method refuses the light.

    Two measures, from two calls: the peak of what Python and numpy allocate (``tracemalloc``;
    it does not see buffers numba kernels allocate internally), and the growth of the process's
    peak resident set over its size before the call (Linux only; it sees everything, but memory
    freed earlier and kept by the allocator is reused without showing: hence
    :func:`peak_memory_fresh`). Only a tiny scene runs before the measured calls.
    """
    light = dict(LIGHTS)[light_label]
    try:  # loads the kernels, and tells whether the method takes this light
        solve(synth.scene(scene_name, size=24, light=light), kwargs, 24)
    except InputError:
        return None
    scene = synth.scene(scene_name, size=size, light=light)
    before = _rss_now()
    solve(scene, kwargs, size)
    rss = None if before is None else max(0, _status_bytes("VmHWM") - before)
    tracemalloc.start()
    try:
        solve(scene, kwargs, size)
        traced = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return Memory(label, scene_name, light_label, traced, rss)


def peak_memory_fresh(label: str, light_label: str, *, size: int) -> Memory | None:
    """:func:`peak_memory` in a new Python process, whose heap no earlier run has grown."""
    probe = subprocess.run(
        [
            sys.executable,
            str(Path(__file__).resolve()),
            "--memory-of",
            label,
            light_label,
            "--size",
            str(size),
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    found = json.loads(probe.stdout)
    return None if found is None else Memory(**found)


# --- tables ------------------------------------------------------------------------------------


def fmt(value: float) -> str:
    """Three significant figures at most, "inf" for a method that left holes."""
    if math.isinf(value):
        return "inf"
    if 0 < abs(value) < 0.01:
        return f"{value:.1g}"
    if abs(value) >= 100:
        return f"{value:,.0f}"
    if abs(value) >= 10:
        return f"{value:.1f}"
    return f"{value:.2f}"


def _labels(rows: Sequence[Row], field: str) -> list:
    """Distinct values of a field in first-seen order."""
    return list(dict.fromkeys(getattr(row, field) for row in rows))


def _index(rows: Sequence[Row]) -> dict:
    return {(row.method, row.scene, row.light, row.noise): row for row in rows}


def best_by_scene(rows: Sequence[Row], noise: float) -> dict:
    """{(scene, light): row with the lowest depth error} among the methods that ran there."""
    best = {}
    for row in rows:
        if row.noise != noise or not row.available:
            continue
        key = (row.scene, row.light)
        if key not in best or (row.depth_pct, row.angle_deg) < (best[key].depth_pct, best[key].angle_deg):
            best[key] = row
    return best


def best_method(rows: Sequence[Row], light: str, noise: float) -> str | None:
    """The method with the lowest median depth error over the scenes, among those that ran on all."""
    scenes = _labels(rows, "scene")
    medians = {}
    for method in _labels(rows, "method"):
        errors = [
            row.depth_pct
            for row in rows
            if row.method == method and row.light == light and row.noise == noise and row.available
        ]
        if len(errors) == len(scenes):
            medians[method] = statistics.median(errors)
    return min(medians, key=medians.get) if medians else None


def summary_table(rows: Sequence[Row], noise: float) -> str:
    """Per method and light: median and mean errors over the scenes, and scenes won."""
    best = best_by_scene(rows, noise)
    lines = [
        "| method | light | depth % median | depth % mean | angle ° median | angle ° mean | best depth on |",
        "|---|---|---:|---:|---:|---:|---|",
    ]
    for light in _labels(rows, "light"):
        for method in _labels(rows, "method"):
            chosen = [
                row for row in rows if row.method == method and row.light == light and row.noise == noise
            ]
            if not all(row.available for row in chosen):
                lines.append(f"| {method} | {light} | n/a | n/a | n/a | n/a | |")
                continue
            depth = [row.depth_pct for row in chosen]
            angle = [row.angle_deg for row in chosen]
            won = [scene for (scene, where), row in best.items() if where == light and row.method == method]
            lines.append(
                f"| {method} | {light} | {fmt(statistics.median(depth))} | {fmt(statistics.fmean(depth))} | "
                f"{fmt(statistics.median(angle))} | {fmt(statistics.fmean(angle))} | "
                f"{len(won)}/{len(chosen)}{': ' + ', '.join(won) if won else ''} |"
            )
    return "\n".join(lines)


def best_table(rows: Sequence[Row], noise: float) -> str:
    """Rows scene, columns light: the method with the lowest depth error and its errors."""
    best = best_by_scene(rows, noise)
    lights = _labels(rows, "light")
    lines = ["| scene | " + " | ".join(lights) + " |", "|---|" + "---|" * len(lights)]
    for scene in _labels(rows, "scene"):
        cells = []
        for light in lights:
            row = best.get((scene, light))
            cells.append(
                "—" if row is None else f"{row.method} ({fmt(row.depth_pct)} %, {fmt(row.angle_deg)}°)"
            )
        lines.append(f"| {scene} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def speed_table(rows: Sequence[Row], memory: Sequence[Memory]) -> str:
    """Per method: median time and ms per megapixel of object over its configurations, memory."""
    peaks = {(item.method, item.light): item for item in memory}
    lines = [
        "| method | light | configurations | median ms | max ms | median ms / Mpx | peak MiB traced | "
        "peak RSS growth MiB | memory measured on |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for method in _labels(rows, "method"):
        for light in _labels(rows, "light"):
            ran = [row for row in rows if row.method == method and row.light == light and row.available]
            if not ran:
                lines.append(f"| {method} | {light} | 0 | n/a | n/a | n/a | | | |")
                continue
            ms = [row.seconds * 1e3 for row in ran]
            per_mpx = [row.seconds * 1e3 / (row.object_pixels / 1e6) for row in ran]
            item = peaks.get((method, light))
            traced = f"{item.traced / 2**20:,.0f}" if item else ""
            rss = (f"{item.rss / 2**20:,.0f}" if item.rss is not None else "n/a") if item else ""
            where = f"{item.scene}, noise 0" if item else ""
            lines.append(
                f"| {method} | {light} | {len(ran)} | {statistics.median(ms):,.0f} | {max(ms):,.0f} | "
                f"{statistics.median(per_mpx):,.0f} | {traced} | {rss} | {where} |"
            )
    return "\n".join(lines)


def full_table(rows: Sequence[Row], light: str) -> str:
    """Rows scene x noise, three columns (depth %, angle °, ms) per method, for one light."""
    table = _index(rows)
    names = _labels(rows, "method")
    head = "| scene | noise | " + " | ".join(f"{m}: depth % | angle ° | ms" for m in names) + " |"
    lines = [head, "|---|---:|" + "---:|---:|---:|" * len(names)]
    for scene in _labels(rows, "scene"):
        for noise in _labels(rows, "noise"):
            cells = []
            for method in names:
                row = table[(method, scene, light, noise)]
                if row.available:
                    cells += [fmt(row.depth_pct), fmt(row.angle_deg), f"{row.seconds * 1e3:,.0f}"]
                else:
                    cells += ["n/a", "n/a", ""]
            lines.append(f"| {scene} | {noise:.0%} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _auto_choice(light: str, best: str | None) -> str:
    """What ``solver="auto"`` picks for a light of :data:`LIGHTS`, and whether it is the best."""
    directions = dict(LIGHTS)
    if light not in directions:
        return ""
    picked = solvers.choose(np.asarray(directions[light])).name
    return f'; `solver="auto"` picks {picked}' + (
        "" if picked == best else " (**not** the best measured here)"
    )


def report(
    rows: Sequence[Row],
    memory: Sequence[Memory],
    *,
    size: int,
    repeats: int,
    budget: float,
    wall: float,
    showcase: str | None,
) -> str:
    """The whole ``methods.md``."""
    noises = _labels(rows, "noise")
    lights = _labels(rows, "light")
    clean = noises[0]
    bests = {light: best_method(rows, light, clean) for light in lights}
    short = [row for row in rows if row.available and row.runs < repeats]
    notes = sorted({f"{row.method}: {row.note}" for row in rows if not row.available})
    parts = [
        "# Methods on the synthetic scenes",
        "",
        f"`python benchmarks/bench_methods.py --size {size} --repeats {repeats}"
        + (f" --budget {budget:g}" if math.isfinite(budget) else "")
        + "` "
        f"(`make bench`). Scenes {size}x{size} from `shadeform.synth` with the true mask and the true "
        f"light; **the concave regions a user would draw are given** "
        "(`synth.concave_regions`: the bowl and the saddle whole, the vase's neck, the bumps' dent). "
        f"Lights: +z, and slant 30° and 45° at tilt {TILT:g}° (from the upper right). Noise: Gaussian, "
        f"a fraction of the albedo, seed {SEED}. Depth error: RMSE as % of the true depth range after "
        "fitting the free offset; angle: mean angular error of the normals (both as `shadeform "
        "evaluate`). Methods: every registered solver (`shadeform solvers`) with its defaults (the "
        'default `solver="auto"` picks one of them by the light), and '
        f'"{LEGACY}" = propagation with `refine=0`, `integrator="paths"` (the report\'s algorithm). '
        "n/a: the method refuses that light (its message is below).",
        "",
        f"Time: median wall time of `reconstruct` over {repeats} run{'s' if repeats > 1 else ''} after a warm-up"
        + (f" (fewer where the runs had taken {budget:g} s: {len(short)} configurations)" if short else "")
        + f". Machine: {os.cpu_count()} cores shared with other work while this ran, so times are "
        f"approximate; Python {platform.python_version()}, numpy {np.__version__}. Whole run "
        f"{wall / 60:.1f} min.",
        "",
        "## Summary",
        "",
    ]
    for light in lights:
        parts.append(
            f"- Best measured for {light} (lowest median depth error over the "
            f"{len(_labels(rows, 'scene'))} scenes, noise {clean:.0%}): **{bests[light] or 'none'}**"
            + _auto_choice(light, bests[light])
        )
    parts += [
        "",
        "Best measured (lowest median depth error over the scenes) at every noise level:",
        "",
        "| light | " + " | ".join(f"noise {noise:.0%}" for noise in noises) + " |",
        "|---|" + "---|" * len(noises),
    ]
    parts += [
        f"| {light} | " + " | ".join(best_method(rows, light, noise) or "none" for noise in noises) + " |"
        for light in lights
    ]
    for noise in noises:
        parts += [
            "",
            f"Noise {noise:.0%}: errors over the scenes per method and light, and the scenes "
            "on which the method has the lowest depth error.",
            "",
            summary_table(rows, noise),
        ]
    parts += [
        "",
        f"## Best method per scene (lowest depth error, noise {clean:.0%})",
        "",
        best_table(rows, clean),
        "",
        "## Speed and memory",
        "",
        "Times over all scenes and noise levels of a light; milliseconds per megapixel of "
        "object pixels. Memory: one call on the scene named, each in a fresh Python process "
        'after a tiny warm-up; "traced" is the peak of Python and numpy allocations '
        '(tracemalloc; it misses buffers numba kernels allocate inside), "RSS growth" the '
        "rise of the process's peak resident memory over its size before the call (Linux).",
        "",
        speed_table(rows, memory),
    ]
    if notes:
        parts += ["", "Messages of the n/a cells:", ""] + [f"- {note}" for note in notes]
    parts += [
        "",
        "Plots: `methods_depth.png`, `methods_angle.png` (heatmaps), `methods_noise.png` "
        "(error against noise)" + (f"; `showcase.png`: {showcase}." if showcase else "."),
        "The DiLiGenT normal-integration table is `diligent.md` (`benchmarks/bench_diligent.py`).",
    ]
    for light in lights:
        parts += ["", f"## Full table, light {light}", "", full_table(rows, light)]
    return "\n".join(parts) + "\n"


# --- plots -------------------------------------------------------------------------------------


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(figure, path: Path) -> None:
    with atomic_write(path) as handle:
        figure.savefig(handle, format="png", dpi=110)


def heatmap(rows: Sequence[Row], field: str, title: str, path: Path) -> None:
    """Rows scene, columns method x light, one panel per noise level; log colour scale."""
    from matplotlib.colors import LogNorm

    plt = _pyplot()
    scenes, lights, names, noises = (_labels(rows, f) for f in ("scene", "light", "method", "noise"))
    table = _index(rows)
    columns = [(method, light) for method in names for light in lights]
    values = [row_value for row in rows if row.available and math.isfinite(row_value := getattr(row, field))]
    top = max(values, default=1.0)
    norm = LogNorm(vmin=0.01, vmax=max(top, 0.1))
    cmap = plt.get_cmap("viridis").with_extremes(bad="#d9d9d9")
    figure, axes = plt.subplots(
        len(noises),
        1,
        figsize=(1.05 * len(columns) + 2.6, 3.3 * len(noises) + 1.0),
        squeeze=False,
        layout="constrained",
    )
    for axis, noise in zip(axes[:, 0], noises):
        grid = np.full((len(scenes), len(columns)), np.nan)
        for i, scene in enumerate(scenes):
            for j, (method, light) in enumerate(columns):
                row = table[(method, scene, light, noise)]
                if row.available:
                    grid[i, j] = getattr(row, field)
        shown = np.ma.masked_invalid(np.where(np.isinf(grid), top, grid).clip(0.01))
        image = axis.imshow(shown, cmap=cmap, norm=norm, aspect="auto")
        for i in range(len(scenes)):
            for j in range(len(columns)):
                value = grid[i, j]
                text = "n/a" if np.isnan(value) else fmt(value)
                dark = np.isnan(value) or norm(min(max(value, 0.01), top)) > 0.6
                axis.text(
                    j, i, text, ha="center", va="center", fontsize=8, color="black" if dark else "white"
                )
        axis.set_yticks(range(len(scenes)), scenes)
        axis.set_ylabel(f"noise {noise:.0%}", fontsize=11, fontweight="bold")
        axis.set_xticks(range(len(columns)), [light for _, light in columns], fontsize=8)
        # one block of lights per method, named above it
        for j in range(len(lights), len(columns), len(lights)):
            axis.axvline(j - 0.5, color="white", linewidth=3)
        top_axis = axis.secondary_xaxis("top")
        top_axis.set_xticks(
            [k * len(lights) + (len(lights) - 1) / 2 for k in range(len(names))],
            names,
            fontsize=10,
            fontweight="bold",
        )
        top_axis.tick_params(length=0)
    figure.colorbar(image, ax=axes[:, 0], shrink=0.6, label=title)
    figure.suptitle(
        f"{title}: methods x lights on the synthetic scenes (grey: n/a, the method refuses the light)"
    )
    _save(figure, path)
    plt.close(figure)


def noise_plot(rows: Sequence[Row], path: Path) -> None:
    """Median over scenes of each error against the noise level, one panel per light and measure."""
    plt = _pyplot()
    from matplotlib.ticker import FuncFormatter, LogFormatter

    lights, names, noises = (_labels(rows, f) for f in ("light", "method", "noise"))
    measures = (
        ("depth_pct", "depth error, % of range (median over scenes)"),
        ("angle_deg", "angular error, ° (median over scenes)"),
    )
    figure, axes = plt.subplots(
        len(measures),
        len(lights),
        figsize=(4.3 * len(lights), 7.0),
        sharex=True,
        squeeze=False,
        layout="constrained",
    )
    markers = "osD^v<>"
    for i, (field, label) in enumerate(measures):
        for j, light in enumerate(lights):
            axis = axes[i, j]
            for k, method in enumerate(names):
                chosen = [
                    [row for row in rows if row.method == method and row.light == light and row.noise == n]
                    for n in noises
                ]
                if not all(row.available for group in chosen for row in group):
                    continue
                medians = [statistics.median(getattr(row, field) for row in group) for group in chosen]
                # one colour and marker per method in every panel, whichever methods a panel lacks
                axis.plot(
                    [100 * n for n in noises],
                    medians,
                    marker=markers[k % len(markers)],
                    color=f"C{k % 10}",
                    label=method,
                )
            axis.set_yscale("log")
            # plain numbers (40, not 4 x 10^1); minor ticks labelled when the axis spans little
            axis.yaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
            axis.yaxis.set_minor_formatter(LogFormatter(labelOnlyBase=False))
            axis.set_xticks([100 * n for n in noises])
            axis.grid(True, which="both", alpha=0.3)
            if i == 0:
                axis.set_title(f"light {light}")
            if i == len(measures) - 1:
                axis.set_xlabel("noise, % of albedo")
            if j == 0:
                axis.set_ylabel(label)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    for axis in axes.ravel():  # the first panel may lack a method that refuses +z
        for handle, label in zip(*axis.get_legend_handles_labels()):
            if label not in labels:
                handles.append(handle)
                labels.append(label)
    figure.legend(handles, labels, loc="outside lower center", ncol=len(labels))
    figure.suptitle("Error against noise (methods missing from a panel refuse that light)")
    _save(figure, path)
    plt.close(figure)


def showcase(rows: Sequence[Row], size: int, path: Path) -> str:
    """Input | recovered normals | mesh of the showcase configuration by its best method."""
    from PIL import Image

    from shadeform.render import result_picture

    name, light_label, noise = SHOWCASE
    best = best_by_scene(rows, noise).get((name, light_label))
    if best is None:
        raise RuntimeError(f"no method ran on the showcase configuration {SHOWCASE}")
    kwargs = dict(methods())[best.method]
    light = dict(LIGHTS)[light_label]
    scene = synth.scene(name, size=size, light=light, noise=noise, seed=SEED)
    rec = solve(scene, kwargs, size)
    picture = result_picture(scene.image, rec.normals, shadeform.to_mesh(rec, step=max(1, size // 128)))
    with atomic_write(path) as handle:
        Image.fromarray(picture).save(handle, format="PNG")
    return (
        f"{name}, light {light_label} (tilt {TILT:g}°), noise {noise:.0%}, method {best.method} "
        f"(depth error {fmt(best.depth_pct)} %, angle {fmt(best.angle_deg)}°)"
    )


def write_results(
    rows: Sequence[Row],
    memory: Sequence[Memory],
    out: Path,
    *,
    size: int,
    repeats: int,
    budget: float,
    wall: float,
    pictures: bool = True,
) -> str:
    """Write ``methods.md`` (and the plots unless ``pictures`` is false) to ``out``; returns the text."""
    out.mkdir(parents=True, exist_ok=True)
    about = None
    if pictures:
        heatmap(rows, "depth_pct", "depth error, % of range", out / "methods_depth.png")
        heatmap(rows, "angle_deg", "mean angular error, °", out / "methods_angle.png")
        noise_plot(rows, out / "methods_noise.png")
        if (
            SHOWCASE[0] in _labels(rows, "scene")
            and SHOWCASE[1] in _labels(rows, "light")
            and SHOWCASE[2] in _labels(rows, "noise")
        ):
            about = showcase(rows, size, out / "showcase.png")
    text = report(rows, memory, size=size, repeats=repeats, budget=budget, wall=wall, showcase=about)
    with atomic_write(out / "methods.md", mode="w") as handle:
        handle.write(text)
    return text


def save_rows(path: Path, rows: Sequence[Row], memory: Sequence[Memory], run: dict) -> None:
    """Measurements as JSON, for ``--replot``; ``run`` holds the keywords of :func:`write_results`."""
    # NaN and inf go out as JSON's common extensions, which json.loads reads back
    saved = {"run": run, "rows": [asdict(row) for row in rows], "memory": [asdict(item) for item in memory]}
    with atomic_write(path, mode="w") as handle:
        json.dump(saved, handle, indent=1)


def load_rows(path: Path) -> tuple[list[Row], list[Memory], dict]:
    """What :func:`save_rows` wrote."""
    saved = json.loads(Path(path).read_text(encoding="utf-8"))
    return [Row(**item) for item in saved["rows"]], [Memory(**item) for item in saved["memory"]], saved["run"]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256, help="image side in pixels (default 256)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per configuration (default 3)")
    parser.add_argument(
        "--budget",
        type=float,
        default=10.0,
        help="seconds after which a configuration gets no more timed runs (default 10)",
    )
    parser.add_argument("--quick", action="store_true", help="128 pixels, one run: a fast check")
    parser.add_argument("--out", type=Path, default=RESULTS, help="folder for methods.md and the PNGs")
    parser.add_argument(
        "--save-rows", type=Path, metavar="JSON", help="also write the measured rows to this JSON file"
    )
    parser.add_argument(
        "--replot",
        type=Path,
        metavar="JSON",
        help="rewrite methods.md and the PNGs from rows saved by --save-rows, without measuring",
    )
    parser.add_argument(
        "--memory-of", nargs=2, metavar=("METHOD", "LIGHT"), help=argparse.SUPPRESS
    )  # the memory probe's own process
    args = parser.parse_args(argv)
    if args.quick:
        args.size, args.repeats = 128, 1
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")

    if args.memory_of is not None:
        label, light_label = args.memory_of
        found = peak_memory(label, dict(methods())[label], light_label, size=args.size)
        print(json.dumps(None if found is None else asdict(found)))
        return 0
    if args.replot is not None:
        rows, memory, run = load_rows(args.replot)
        print(write_results(rows, memory, args.out, **run))
        return 0

    start = time.perf_counter()
    chosen = methods()
    print(
        f"methods: {', '.join(label for label, _ in chosen)}; {args.size}x{args.size}, {args.repeats} runs",
        file=sys.stderr,
        flush=True,
    )

    def progress(row: Row) -> None:
        shown = (
            f"{fmt(row.depth_pct)} %  {fmt(row.angle_deg)}°  {row.seconds * 1e3:,.0f} ms x{row.runs}"
            if row.available
            else "n/a"
        )
        print(
            f"  {row.scene:9} {row.light:9} {row.noise:4.0%}  {row.method:20} {shown}",
            file=sys.stderr,
            flush=True,
        )

    rows = run_grid(
        size=args.size, repeats=args.repeats, budget=args.budget, chosen=chosen, progress=progress
    )
    measured = (peak_memory_fresh(label, light, size=args.size) for label, _ in chosen for light, _ in LIGHTS)
    memory = [item for item in measured if item is not None]
    run = {
        "size": args.size,
        "repeats": args.repeats,
        "budget": args.budget,
        "wall": time.perf_counter() - start,
    }
    if args.save_rows is not None:
        save_rows(args.save_rows, rows, memory, run)
    text = write_results(rows, memory, args.out, **run)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
