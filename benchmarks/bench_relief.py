"""Print-ready reliefs: speed at 12 Mpx with a 200,000-triangle budget, and bas-relief compression.

Run with ``make bench`` (or ``python benchmarks/bench_relief.py``; ``--quick`` for a smaller
image). Writes ``benchmarks/results/relief.md`` and the figure ``relief_compress.png``:

1. **12 Mpx to a 200k-triangle solid.** A synthetic 4000 x 3000 depth map (the vase of
   :mod:`shadeform.synth` 3000 pixels tall, in a 4000-pixel-wide frame), made into a relief of
   100 mm, 4 mm deep on a 2 mm base with ``max_triangles=200_000``: the object's outline
   (2.8 Mpx on the object), the whole frame (12 Mpx), the frame with compression. Each row is
   the median of 3 runs after a warm-up, in a fresh process per row (so that the process's peak
   resident memory is that row's); every solid is checked by manifold3d and trimesh.
2. **The whole chain from a 12 Mpx photo**: the same vase rendered (light +z), reconstructed
   (``shadeform.reconstruct``, default method), made into the relief and written as STL; one run,
   the stages timed apart: the reconstruction is most of it.
3. **OVERSAMPLE**: the grid the simplifier starts from, 2, 4 or 8 times the budget (the constant
   :data:`shadeform.solid.OVERSAMPLE` was chosen here).
4. **Compression**: a 60-pixel depth jump with four bumps of 1 pixel (the test's surface,
   ``tests/test_relief.py``): each bump's height above its surroundings as a share of the relief's
   height, under linear scaling (``compress=0``) and compression.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).parent / "results"
BUDGET = 200_000
SIZE = dict(width_mm=100.0, height_mm=4.0, base_mm=2.0)
CASES = {
    "outline": dict(outline="mask"),
    "frame": dict(outline="frame"),
    "frame, compress 0.3": dict(outline="frame", compress=0.3),
}


def vase_depth(rows: int, cols: int) -> np.ndarray:
    """The synthetic vase, ``rows`` tall, centred in a frame ``cols`` wide; NaN off the vase."""
    from shadeform import synth

    depth = np.full((rows, cols), np.nan)
    left = (cols - rows) // 2
    depth[:, left : left + rows] = synth.surface("vase", size=rows)[0]
    return depth


def check(solid) -> str:
    """manifold3d's and trimesh's verdict on a solid."""
    import manifold3d
    import trimesh

    status = manifold3d.Manifold(
        manifold3d.Mesh(
            vert_properties=solid.vertices.astype(np.float32), tri_verts=solid.faces.astype(np.uint32)
        )
    ).status()
    mesh = trimesh.Trimesh(solid.vertices, solid.faces, process=False)
    ok = (
        status == manifold3d.Error.NoError
        and mesh.is_watertight
        and mesh.is_winding_consistent
        and mesh.volume > 0
    )
    return "valid" if ok else f"INVALID ({status}, watertight {mesh.is_watertight})"


def run_case(name: str, rows: int, cols: int, runs: int, oversample: int | None) -> dict:
    """One row of table 1 (or 3), in this process."""
    import shadeform
    import shadeform.solid.options as relief_options

    if oversample is not None:
        relief_options.OVERSAMPLE = oversample  # where grid_step reads it
    depth = vase_depth(rows, cols)
    options = dict(SIZE, max_triangles=BUDGET, **CASES[name])
    middle = np.s_[
        rows // 2 - rows // 8 : rows // 2 + rows // 8, cols // 2 - cols // 8 : cols // 2 + cols // 8
    ]
    shadeform.relief(depth[middle], **options)  # warm-up: numba's cache, imports
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        solid = shadeform.relief(depth, **options)
        times.append(time.perf_counter() - start)
    tracemalloc.start()
    shadeform.relief(depth, **options)
    traced = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    folder = Path(tempfile.mkdtemp())
    writes = {}
    for suffix in (".stl", ".3mf"):
        start = time.perf_counter()
        shadeform.export(solid, folder / f"relief{suffix}")
        writes[suffix] = time.perf_counter() - start
    return {
        "seconds": statistics.median(times),
        "all": times,
        "traced_mib": traced / 2**20,
        "rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "triangles": solid.n_faces,
        "deviation_mm": solid.deviation_mm,
        "size_mm": [float(v) for v in solid.size_mm],
        "check": check(solid),
        "write_stl": writes[".stl"],
        "write_3mf": writes[".3mf"],
        "pixels": (
            pixels := int(np.isfinite(depth).sum()) if CASES[name]["outline"] == "mask" else depth.size
        ),
        # the grid relief() samples before simplifying
        "step": relief_options.grid_step(pixels, BUDGET),
    }


def _heights_mm(depth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Depth scaled as relief() scales it: lowest to highest object point = ``height_mm``."""
    low, high = np.nanmin(depth[mask]), np.nanmax(depth[mask])
    return np.where(mask, (depth - low) / (high - low) * SIZE["height_mm"], np.nan)


def framed_regions(rows: int, left: int) -> dict:
    """The vase's concave neck as a user draws it (``synth.concave_regions``), moved into the frame."""
    from shadeform import synth

    regions = synth.concave_regions("vase", size=rows)
    for region in regions["regions"]:
        region["polygon"] = [[x + left, y] for x, y in region["polygon"]]
    return regions


def run_chain(rows: int, cols: int) -> dict:
    """Table 2: photo -> reconstruct -> relief -> STL, the stages timed apart: once solving every
    pixel, once only the grid the budget samples (what ``shadeform relief`` does); and the two
    reliefs' surfaces compared with each other and with the true depth, in mm."""
    import shadeform
    from shadeform import synth
    from shadeform.coarse import reconstruct_on_grid
    from shadeform.preprocess import object_mask
    from shadeform.solid import grid_step

    scene = synth.scene("vase", size=rows)
    image = np.zeros((rows, cols))
    truth = np.full((rows, cols), np.nan)
    left = (cols - rows) // 2
    image[:, left : left + rows] = scene.image
    truth[:, left : left + rows] = np.where(scene.mask, scene.depth, np.nan)
    concave = framed_regions(rows, left)
    shadeform.relief(vase_depth(rows // 4, cols // 4), **SIZE, max_triangles=BUDGET // 16)  # warm-up
    reconstruct_on_grid(synth.scene("vase", size=128).image, step=2)
    found: dict = {}
    surfaces = {}
    for how in ("full", "grid"):
        timings = {}
        start = time.perf_counter()
        mask = object_mask(image)
        step = grid_step(int(mask.sum()), BUDGET) if how == "grid" else 1
        rec = reconstruct_on_grid(image, mask=mask, step=step, concave=concave)
        timings["reconstruct"] = time.perf_counter() - start
        lap = time.perf_counter()
        solid = shadeform.relief(rec, **SIZE, max_triangles=BUDGET)
        timings["relief"] = time.perf_counter() - lap
        lap = time.perf_counter()
        shadeform.export(solid, Path(tempfile.mkdtemp()) / "relief.stl")
        timings["write"] = time.perf_counter() - lap
        timings["total"] = time.perf_counter() - start
        surfaces[how] = (_heights_mm(rec.depth, rec.mask), step)
        found[how] = {
            **timings,
            "step": step,
            "method": rec.info["solver"],
            "triangles": solid.n_faces,
            "deviation_mm": solid.deviation_mm,
            "check": check(solid),
        }
    # on the grid's points: the grid solve against the full one, and each against the truth
    grid_heights, step = surfaces["grid"]
    full_heights = surfaces["full"][0][::step, ::step]
    true_heights = _heights_mm(truth, np.isfinite(truth))[::step, ::step]
    both = np.isfinite(grid_heights) & np.isfinite(full_heights) & np.isfinite(true_heights)
    gap = np.abs(grid_heights - full_heights)[both]
    for how, heights in (("full", full_heights), ("grid", grid_heights)):
        error = np.abs(heights - true_heights)[both]
        found[how]["error_mean_mm"] = float(error.mean())
        found[how]["error_p99_mm"] = float(np.percentile(error, 99))
    found["gap_mean_mm"] = float(gap.mean())
    found["gap_p99_mm"] = float(np.percentile(gap, 99))
    found["rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return found


def run_cli(rows: int, cols: int, runs: int) -> dict:
    """The user's command on a 16-bit PNG of the rendered vase: wall time of fresh processes."""
    import imagecodecs

    from shadeform import synth

    scene = synth.scene("vase", size=rows)
    image = np.zeros((rows, cols), dtype=np.uint16)
    left = (cols - rows) // 2
    image[:, left : left + rows] = np.round(np.clip(scene.image, 0, 1) * 65535).astype(np.uint16)
    folder = Path(tempfile.mkdtemp())
    photo = folder / "vase.png"
    photo.write_bytes(imagecodecs.png_encode(image))
    (folder / "neck.json").write_text(json.dumps(framed_regions(rows, left)))
    shadeform = Path(sys.executable).with_name("shadeform")
    command = [
        str(shadeform),
        "relief",
        str(photo),
        "-o",
        str(folder / "relief.stl"),
        "--max-triangles",
        str(BUDGET),
        "--concave",
        str(folder / "neck.json"),
    ]
    subprocess.run(command, check=True, capture_output=True)  # warm: numba's cache, the OS's file cache
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True)
        times.append(time.perf_counter() - start)
    return {"median": statistics.median(times), "all": times}


def run_real() -> list[dict]:
    """Table 5: the budget's grid on the real photos of ``../shared/data/real`` (``real_data.cases``,
    their known lights and masks): each relief's top solved at every pixel and on the grid a budget
    of a sixteenth of the object's pixels samples (grid step 2), compared where both are defined."""
    import real_data
    import shadeform
    from shadeform.coarse import reconstruct_on_grid
    from shadeform.metrics import angular_error
    from shadeform.solid import grid_step

    rows = []
    for case in real_data.cases():
        budget = max(int(case.mask.sum()) // 16, 12)
        step = grid_step(int(case.mask.sum()), budget)
        found = {"name": case.name, "pixels": int(case.mask.sum()), "step": step}
        heights = {}
        for how, k in (("full", 1), ("grid", step)):
            rec = reconstruct_on_grid(case.image, light=case.light, mask=case.mask, step=k)
            solid = shadeform.relief(rec, **SIZE, max_triangles=budget)
            found[f"deviation_{how}_mm"] = solid.deviation_mm
            heights[how] = _heights_mm(rec.depth, rec.mask)
            # the normals against the measured ones, on the grid's points
            normals = rec.normals[::step, ::step] if k == 1 else rec.normals
            valid = case.valid[::step, ::step] & np.isfinite(normals).all(axis=-1)
            found[f"angle_{how}"] = angular_error(normals, case.normals[::step, ::step], valid)
        full = heights["full"][::step, ::step]
        both = np.isfinite(full) & np.isfinite(heights["grid"])
        gap = np.abs(full - heights["grid"])[both]
        found["gap_mean_mm"], found["gap_p99_mm"] = float(gap.mean()), float(np.percentile(gap, 99))
        rows.append(found)
    return rows


def real_table() -> str:
    """Table 5 as Markdown."""
    lines = [
        "\n## 5. The budget's grid on real photos\n",
        "The real photos of `../shared/data/real` (6 DiLiGenT objects, 12 MIT-Berkeley; known lights, their masks, "
        "default method), each made into the relief (100 mm, 4 mm deep) with a budget of one triangle per 16 "
        "object pixels, so that relief() samples every 2nd pixel: its top solved at every pixel, and only on "
        "that grid (what `shadeform relief --max-triangles` does). *gap*: the two surfaces' difference at the "
        "grid's points, mm; *deviation*: what the budget's simplification moved each surface by, mm; *normals*: "
        "mean angle to the measured normals on the grid's points, degrees.\n",
        "| photo | object pixels | gap mean mm | gap p99 mm | deviation, every pixel mm | deviation, grid mm "
        "| normals, every pixel deg | normals, grid deg |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in run_real():
        lines.append(
            f"| {row['name']} | {row['pixels']:,} | {row['gap_mean_mm']:.3f} | {row['gap_p99_mm']:.3f} | "
            f"{row['deviation_full_mm']:.3f} | {row['deviation_grid_mm']:.3f} | {row['angle_full']:.1f} | "
            f"{row['angle_grid']:.1f} |"
        )
    return "\n".join(lines)


def in_fresh_process(*args: str) -> dict:
    done = subprocess.run(
        [sys.executable, __file__, *args],
        capture_output=True,
        text=True,
        check=False,
        cwd=Path(__file__).parent,
    )
    if done.returncode != 0:
        raise RuntimeError(done.stderr)
    return json.loads(done.stdout.strip().splitlines()[-1])


def step_with_bumps(bumps: bool = True):
    """The test's surface: a 60-pixel jump (a logistic ramp, scale 1.5 pixels) and four gaussian
    bumps of height 1, sigma 4 pixels; 96 x 192."""
    rows, cols = np.mgrid[:96, :192].astype(float)
    depth = 60.0 / (1 + np.exp(-(cols - 96) / 1.5))
    centres = [(30, 40), (66, 60), (30, 140), (66, 160)]
    if bumps:
        depth += sum(np.exp(-((rows - r) ** 2 + (cols - c) ** 2) / (2 * 4.0**2)) for r, c in centres)
    return depth, centres


def bump_shares(height: np.ndarray, centres) -> np.ndarray:
    rows, cols = np.indices(height.shape)
    height = (height - height.min()) / np.ptp(height)
    out = []
    for r, c in centres:
        ring = (np.hypot(rows - r, cols - c) > 12) & (np.hypot(rows - r, cols - c) < 16)
        out.append(height[r, c] - height[ring].mean())
    return np.array(out)


def compression(figure: Path) -> str:
    """Table 4 and the figure: bump shares under linear scaling and compression."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import shadeform

    depth, centres = step_with_bumps()
    heights = {}
    for compress in (0.0, 0.3, 0.5, 1.0):
        solid = shadeform.relief(
            depth, width_mm=100, height_mm=5, base_mm=2, outline="frame", compress=compress
        )
        heights[compress] = solid.vertices[solid.vertices[:, 2] > 0, 2].reshape(depth.shape) - 2.0
    linear = bump_shares(heights[0.0], centres).mean()
    lines = [
        "| compress | bump height / relief height | vs linear | jump / bump height |",
        "|---:|---:|---:|---:|",
    ]
    for compress, height in heights.items():
        share = bump_shares(height, centres).mean()
        jump = np.median(height[:, 120:]) - np.median(height[:, :70])
        bump = share * np.ptp(height)
        lines.append(f"| {compress:g} | {100 * share:.2f} % | x{share / linear:.1f} | {jump / bump:.1f} |")

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 3.6), gridspec_kw=dict(width_ratios=[1.6, 1]))
    x = np.arange(depth.shape[1]) * 100 / (depth.shape[1] - 1)
    for compress, height in heights.items():
        label = "linear (compress 0)" if compress == 0 else f"compress {compress:g}"
        left.plot(x, height[30], label=label)
    left.set_xlabel("x, mm (row through two bumps)")
    left.set_ylabel("relief height, mm")
    left.set_title("a 60-pixel jump and two 1-pixel bumps, scaled to 5 mm")
    left.legend(fontsize=8)
    for compress, height in heights.items():
        right.plot(x[:80], (height[30] - height[30, 0])[:80], label=f"{compress:g}")
    right.set_xlabel("x, mm (left half)")
    right.set_title("the bump on the low side, mm")
    right.legend(title="compress", fontsize=8)
    fig.tight_layout()
    fig.savefig(figure, dpi=110)
    plt.close(fig)
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1000 x 750 instead of 4000 x 3000")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--case", help=argparse.SUPPRESS)  # one row, in this process
    parser.add_argument("--oversample", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--chain", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--real", action="store_true", help="only table 5 (the real photos), printed")
    parser.add_argument("--out", type=Path, default=RESULTS / "relief.md")
    args = parser.parse_args(argv)
    rows, cols = (750, 1000) if args.quick else (3000, 4000)
    if args.case:
        print(json.dumps(run_case(args.case, rows, cols, args.runs, args.oversample)))
        return 0
    if args.chain:
        print(json.dumps(run_chain(rows, cols)))
        return 0
    if args.real:
        print(real_table())
        return 0

    size = ["--quick"] if args.quick else []
    megapixels = rows * cols / 1e6
    load = os.getloadavg()[0]
    out = [
        f"# Reliefs\n\n{cols} x {rows} ({megapixels:.0f} Mpx) synthetic vase depth, relief 100 mm wide, 4 mm "
        f"deep, 2 mm base, budget {BUDGET:,} triangles; {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, numpy {np.__version__}, load average {load:.1f} when started "
        "(other work on the machine slows every row alike).\n",
        "## 1. Depth map to a 200k-triangle solid (`shadeform.relief`)\n",
        f"Median of {args.runs} runs after a warm-up; a fresh process per row. Peak resident memory is "
        f"the process's (the {megapixels:.0f} Mpx depth map and Python included); traced is numpy's and Python's "
        "allocations in one call (the simplifier's C++ memory is not traced).\n",
        "| case | median s | runs, s | ms / Mpx | peak RSS MiB | traced MiB | grid step | triangles "
        "| deviation mm | size mm | checks | write .stl s | write .3mf s |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---|---|---:|---:|",
    ]
    notes = [
        "\nThe frame's deviation is larger than the outline's: there the vase's cut-off top and "
        f"bottom stand as cliffs above the background, and its coarser grid ({megapixels:.0f} Mpx for the same "
        f"budget) moves a cliff sideways by up to a grid step ({100 / (cols - 1):.3f} mm per pixel). "
        f"Compression solves a least-squares problem over all {megapixels:.0f} Mpx "
        "(`compress_depth`): the extra seconds and memory of the last row.",
    ]
    for name in CASES:
        found = in_fresh_process("--case", name, "--runs", str(args.runs), *size)
        row = (
            f"| {name} ({found['pixels'] / 1e6:.1f} Mpx inside) | {found['seconds']:.2f} | "
            f"{', '.join(f'{t:.2f}' for t in found['all'])} | {1e3 * found['seconds'] / megapixels:,.0f} | "
            f"{found['rss_mib']:,.0f} | {found['traced_mib']:,.0f} | {found['step']} | {found['triangles']:,} | "
            f"{found['deviation_mm']:.3f} | {' x '.join(f'{v:.2f}' for v in found['size_mm'])} | "
            f"{found['check']} | {found['write_stl']:.2f} | {found['write_3mf']:.2f} |"
        )
        out.append(row)
        print(row, file=sys.stderr)

    out += notes
    chain = in_fresh_process("--chain", *size)
    cli = run_cli(rows, cols, args.runs)
    full, grid = chain["full"], chain["grid"]
    out += [
        f"\n## 2. From a {megapixels:.0f} Mpx photo\n",
        f"The vase rendered (light +z) in the same frame, reconstructed (`{full['method']}`), made into the "
        f"relief (outline) and written as STL; one run each. *every pixel*: `shadeform.reconstruct` on all "
        f"{megapixels:.0f} Mpx; *budget's grid*: only the rows and columns at multiples of {grid['step']} solved "
        "(`reconstruct_on_grid` at `grid_step`, the grid the budget samples the surface on anyway: what "
        "`shadeform relief --max-triangles` does unless `--full-resolution`).\n",
        "| stage, s | every pixel | budget's grid |",
        "|---|---:|---:|",
        f"| reconstruct | {full['reconstruct']:.2f} | {grid['reconstruct']:.2f} |",
        f"| relief, {BUDGET:,} triangles | {full['relief']:.2f} | {grid['relief']:.2f} |",
        f"| write .stl | {full['write']:.2f} | {grid['write']:.2f} |",
        f"| **total** | **{full['total']:.2f}** | **{grid['total']:.2f}** |",
        f"| simplification's deviation, mm | {full['deviation_mm']:.3f} | {grid['deviation_mm']:.3f} |",
        f"| surface vs true depth, mean / p99 mm | {full['error_mean_mm']:.3f} / {full['error_p99_mm']:.3f} "
        f"| {grid['error_mean_mm']:.3f} / {grid['error_p99_mm']:.3f} |",
        f"| checks | {full['check']} | {grid['check']} |",
        f"\nThe two surfaces differ by {chain['gap_mean_mm']:.4f} mm on average ({chain['gap_p99_mm']:.4f} mm at the "
        "99th percentile) at the grid's points, both scaled as the relief scales them (4 mm deep). "
        f"Peak resident memory {chain['rss_mib']:,.0f} MiB (both runs in one process).",
        f"\n**The command** `shadeform relief vase.png -o relief.stl --max-triangles {BUDGET:,}` on the 16-bit "
        f"PNG, fresh processes after a warm one: median **{cli['median']:.2f} s** "
        f"(runs {', '.join(f'{t:.2f}' for t in cli['all'])}), loading the photo and start-up included.",
    ]
    print("\n".join(out[-14:]), file=sys.stderr)

    out += [
        "\n## 3. The grid the simplifier starts from (OVERSAMPLE), outline case\n",
        "| OVERSAMPLE | median s | deviation mm |",
        "|---:|---:|---:|",
    ]
    for oversample in (2, 4, 8):
        found = in_fresh_process(
            "--case", "outline", "--runs", str(args.runs), "--oversample", str(oversample), *size
        )
        out.append(f"| {oversample} | {found['seconds']:.2f} | {found['deviation_mm']:.3f} |")
        print(out[-1], file=sys.stderr)

    figure = args.out.parent / "relief_compress.png"
    out += [
        "\n## 4. Bas-relief compression keeps fine detail\n",
        "A 60-pixel depth jump (a logistic ramp, scale 1.5 pixels) with four gaussian bumps of "
        "height 1 pixel (sigma 4), 192 x 96, made into a 100 mm relief 5 mm deep, frame outline. "
        "The bump's height above the ring 12-16 pixels around it, as a share of the relief's "
        "height (mean of the four bumps), and the depth jump left between the two sides:\n",
        compression(figure),
        f"\n![profiles]({figure.name})\n",
        "Linear scaling gives the bumps 1/61 of the height (1.6 %), the jump 60 times a bump's height; "
        "compression shrinks the jump, whose slopes are far above the mean slope, much more than the "
        "bumps, whose slopes are near it, so the bumps keep a larger share of the same 5 mm and "
        "their shape (`tests/test_relief.py`: correlation above 0.95 with the true bumps at 0.5).",
    ]
    text = "\n".join(out) + "\n"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
