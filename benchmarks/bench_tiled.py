"""Tiled reconstruction of huge reliefs: peak memory, time, depth error against the truth and
against the same scene solved whole, seams.

The scene is :func:`shadeform.synth.bump_relief` (gaussian bumps on a plate, light +z), written
tile by tile to a 16-bit BigTIFF so that making a 100 Mpx input never holds it whole. Each run of
:func:`shadeform.tiled.reconstruct` happens in a fresh subprocess whose process tree (the run and
its worker processes) is sampled with psutil every 0.1 s: "peak" is the largest sum of their
resident sets (shared pages counted once per process: an upper bound). The output BigTIFF is
then read block by block and compared with the analytic depth:

* ``rms``: root-mean-square depth error in pixels after the best offset (shape from shading
  fixes depth up to one);
* ``whole rms``: the same for a ``--whole``-pixel square window at the relief's centre, read
  from the same 16-bit file and solved whole by :func:`shadeform.reconstruct`; ``ratio`` is
  the tiled error over that window divided by it (the bar: <= 1.2);
* ``seam``: the largest height difference of two overlapping tiles after alignment, where they
  are blended (``TiledResult.seam``), against the whole solve's own largest error (``whole max
  err``), and its rms against the whole solve's rms;
* ``jump``: the largest error of the height step between neighbouring pixels across a tile
  border (``|dz - dz_true|``), against the largest such error inside the tiles.

Usage::

    python benchmarks/bench_tiled.py --sizes 2048,10000 [--schedulers]

``--schedulers`` also times threads, processes and one process on a small input (2048^2).
Prints markdown; the results are in ``benchmarks/results/tiled.md``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

#: The bumps' widths as fractions of their spacing (``bump_relief(width=...)``); ``--width``.
WIDTH = (0.06, 0.09)


def write_input(path: Path, size: int, spacing: float, block: int = 512) -> None:
    """The relief's image, 16-bit, written one TIFF tile at a time."""
    import tifffile

    from shadeform.synth import bump_relief

    def tiles():
        for r in range(0, size, block):
            for c in range(0, size, block):
                h, w = min(block, size - r), min(block, size - c)
                image = bump_relief((size, size), window=(r, c, h, w), spacing=spacing, width=WIDTH).image
                out = np.zeros((block, block), dtype=np.uint16)
                out[:h, :w] = np.rint(image * 65535)
                yield out

    tifffile.imwrite(
        path, data=tiles(), shape=(size, size), dtype=np.uint16, tile=(block, block), bigtiff=True
    )


def child(args) -> None:
    """One tiled run (in a fresh process); prints its result as JSON."""
    import resource

    from shadeform import tiled

    start = time.perf_counter()
    result = tiled.reconstruct(
        args.input,
        tile=args.tile,
        overlap=args.overlap,
        out=args.output,
        scheduler=args.scheduler,
        workers=args.workers,
        mesh=args.mesh,
        max_triangles=200_000,
        mask="whole",  # a relief: every pixel is the object
    )
    seconds = time.perf_counter() - start
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(
        json.dumps(
            {
                "seconds": seconds,
                "seam": result.seam,
                "seam_rms": result.seam_rms,
                "tiles": result.tiles,
                "timings": result.info["timings"],
                "main_mb": own,
                "worker_mb": kids,
            }
        )
    )


def run_tiled(input_path: Path, output: Path, *, tile, overlap, scheduler, workers, mesh=None) -> dict:
    """Run :func:`child` in a subprocess, sampling its process tree's memory."""
    import psutil

    command = [sys.executable, __file__, "--child", str(input_path), str(output), str(tile), str(overlap)]
    command += [scheduler or "none", str(workers), str(mesh or "none")]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
    peak = [0.0]

    def sample():
        root = psutil.Process(proc.pid)
        while proc.poll() is None:
            try:
                tree = [root, *root.children(recursive=True)]
                total = 0
                for p in tree:
                    with contextlib.suppress(psutil.Error):  # a worker may end between the two calls
                        total += p.memory_info().rss
                peak[0] = max(peak[0], total / 2**20)
            except psutil.Error:
                pass
            time.sleep(0.1)

    watcher = threading.Thread(target=sample, daemon=True)
    watcher.start()
    out, _ = proc.communicate()
    watcher.join()
    if proc.returncode != 0:
        raise SystemExit(f"tiled run failed ({proc.returncode})")
    result = json.loads(out.strip().splitlines()[-1])
    result["peak_mb"] = peak[0]
    return result


def evaluate(output: Path, size: int, spacing: float, tile: int, block: int = 1024) -> dict:
    """Error statistics of the written depth against the analytic relief, block by block."""
    import tifffile
    import zarr

    from shadeform.synth import bump_relief

    depth = zarr.open(tifffile.imread(output, aszarr=True), mode="r")
    total = squares = count = 0.0
    jump_border = jump_inside = 0.0
    for r in range(0, size, block):
        for c in range(0, size, block):
            h, w = min(block + 1, size - r), min(block + 1, size - c)  # one more: steps across blocks
            est = np.asarray(depth[r : r + h, c : c + w], dtype=np.float64)
            true = bump_relief((size, size), window=(r, c, h, w), spacing=spacing, width=WIDTH).depth
            diff = est - true
            core = diff[: min(block, h), : min(block, w)]
            total += core.sum()
            squares += (core * core).sum()
            count += core.size
            for axis, start in ((0, r), (1, c)):
                step = np.abs(np.diff(diff, axis=axis))
                crossing = (np.arange(step.shape[axis]) + start + 1) % tile == 0
                at = np.take(step, np.flatnonzero(crossing), axis=axis)
                inside = np.take(step, np.flatnonzero(~crossing), axis=axis)
                jump_border = max(jump_border, float(at.max()) if at.size else 0.0)
                jump_inside = max(jump_inside, float(inside.max()) if inside.size else 0.0)
    mean = total / count
    return {
        "rms": float(np.sqrt(max(squares / count - mean * mean, 0.0))),
        "jump_border": jump_border,
        "jump_inside": jump_inside,
    }


def window_error(output: Path, size: int, spacing: float, side: int) -> float:
    """Tiled rms error (best offset) over the centre window of ``side`` pixels."""
    import tifffile
    import zarr

    from shadeform.synth import bump_relief

    r0 = (size - side) // 2
    est = np.asarray(
        zarr.open(tifffile.imread(output, aszarr=True), mode="r")[r0 : r0 + side, r0 : r0 + side]
    )
    true = bump_relief((size, size), window=(r0, r0, side, side), spacing=spacing, width=WIDTH).depth
    diff = est - true
    return float(np.sqrt(np.mean((diff - diff.mean()) ** 2)))


def whole_child(args) -> None:
    """The centre window solved whole (in a fresh process); prints its rms error and time."""
    import resource

    import tifffile
    import zarr

    import shadeform
    from shadeform.synth import bump_relief

    global WIDTH
    size, spacing, side = int(args[1]), float(args[2]), int(args[3])
    WIDTH = tuple(float(v) for v in args[4].split(","))
    r0 = (size - side) // 2
    raw = np.asarray(
        zarr.open(tifffile.imread(args[0], aszarr=True), mode="r")[r0 : r0 + side, r0 : r0 + side]
    )
    # x 0.99: a mostly flat window is at full brightness almost everywhere, which the pipeline's
    # clipping guard refuses; a constant factor is invisible to the solvers (the tiles do the same)
    image = raw.astype(np.float64) / 65535 * 0.99
    start = time.perf_counter()
    rec = shadeform.reconstruct(image, mask=np.ones(image.shape, dtype=bool))
    seconds = time.perf_counter() - start
    true = bump_relief((size, size), window=(r0, r0, side, side), spacing=spacing, width=WIDTH).depth
    diff = rec.depth - true
    rms = float(np.sqrt(np.mean((diff - diff.mean()) ** 2)))
    largest = float(np.abs(diff - diff.mean()).max())
    mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"rms": rms, "max": largest, "seconds": seconds, "peak_mb": mb}))


def run_whole(input_path: Path, size: int, spacing: float, side: int) -> dict:
    command = [sys.executable, __file__, "--whole-child", str(input_path), str(size), str(spacing), str(side)]
    command.append(",".join(map(str, WIDTH)))
    out = subprocess.run(command, stdout=subprocess.PIPE, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="2048", help="relief sides in pixels, comma-separated")
    parser.add_argument("--spacing", type=float, default=256.0)
    parser.add_argument("--width", default="0.06,0.09", help="least,largest bump sigma / spacing")
    parser.add_argument("--tile", type=int, default=512)
    parser.add_argument("--overlap", type=int, default=128)
    parser.add_argument("--whole", type=int, default=1024, help="side of the window solved whole")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--scheduler", default=None)
    parser.add_argument("--schedulers", action="store_true", help="also compare the local schedulers")
    parser.add_argument(
        "--folder", default=None, help="where inputs and outputs go (default: a temporary one)"
    )
    args = parser.parse_args()
    global WIDTH
    WIDTH = tuple(float(v) for v in args.width.split(","))
    folder = Path(args.folder or tempfile.mkdtemp(prefix="bench-tiled-"))
    folder.mkdir(parents=True, exist_ok=True)
    load = os.getloadavg()[0]
    print(
        f"load average (1 min) at start: {load:.2f}; spacing {args.spacing:g}, tile {args.tile}, overlap {args.overlap}"
    )
    print()
    print(
        "| pixels | time s | ms/Mpx | peak MB (tree) | main MB | rms px | whole rms px (side) | ratio | seam px | whole max err px | seam rms | jump border | jump inside | load |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for size in (int(s) for s in args.sizes.split(",") if s):
        source = folder / f"relief_{size}_{args.spacing:g}_{args.width}.tif"
        if not source.exists():
            write_input(source, size, args.spacing)
        output = folder / f"depth_{size}_{args.spacing:g}_{args.width}.tif"
        run = run_tiled(
            source, output, tile=args.tile, overlap=args.overlap, scheduler=args.scheduler,
            workers=args.workers, mesh=folder / f"relief_{size}.glb",
        )  # fmt: skip
        print(f"<!-- {size} tiled run: {json.dumps(run)} -->", flush=True)
        stats = evaluate(output, size, args.spacing, args.tile)
        side = min(args.whole, size)
        whole = run_whole(source, size, args.spacing, side)
        tiled_window = window_error(output, size, args.spacing, side)
        mpx = size * size / 1e6
        print(
            f"| {size}x{size} ({mpx:.1f} Mpx) | {run['seconds']:.0f} | {1000 * run['seconds'] / mpx:.0f} "
            f"| {run['peak_mb']:.0f} | {run['main_mb']:.0f} | {stats['rms']:.4f} "
            f"| {whole['rms']:.4f} ({side}) | {tiled_window / whole['rms']:.2f} | {run['seam']:.4f} "
            f"| {whole['max']:.4f} | {run['seam_rms']:.5f} | {stats['jump_border']:.4f} | {stats['jump_inside']:.4f} "
            f"| {os.getloadavg()[0]:.2f} |",
            flush=True,
        )
        print(
            f"<!-- {size}: {json.dumps({'run': run, 'whole': whole, 'tiled_window_rms': tiled_window})} -->",
            flush=True,
        )
    if args.schedulers:
        size = 2048  # 16 tiles of 512
        source = folder / f"relief_{size}_{args.spacing:g}_{args.width}.tif"
        if not source.exists():
            write_input(source, size, args.spacing)
        print()
        print("| scheduler (2048x2048, 16 tiles) | time s | peak MB (tree) | load |")
        print("|---|---|---|---|")
        for scheduler, workers in (("synchronous", 1), ("threads", 2), ("processes", 2)):
            out = folder / f"sched_{scheduler}_{args.spacing:g}_{args.width}.tif"
            run = run_tiled(
                source, out, tile=args.tile, overlap=args.overlap, scheduler=scheduler, workers=workers
            )
            print(
                f"| {scheduler} ({workers}) | {run['seconds']:.1f} | {run['peak_mb']:.0f} | {os.getloadavg()[0]:.2f} |",
                flush=True,
            )


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        a = sys.argv[2:]
        child(
            argparse.Namespace(
                input=a[0], output=a[1], tile=int(a[2]), overlap=int(a[3]),
                scheduler=None if a[4] == "none" else a[4], workers=int(a[5]),
                mesh=None if a[6] == "none" else a[6],
            )
        )  # fmt: skip
    elif len(sys.argv) > 1 and sys.argv[1] == "--whole-child":
        whole_child(sys.argv[2:])
    else:
        main()
