"""Speed and memory of the ``photo`` solver (the one ``auto`` takes for photographs) by size.

A noisy synthetic ellipsoid under the light (5, 5, 7) at several sizes, and DiLiGenT ``bear``
scaled up where ``../shared/data/real`` is there (a real photo's reflectance curve and
outliers). Prints a Markdown table (median and worst wall time of several runs after a warm-up
that fills the JIT cache, ms per megapixel of object, peak traced memory of one run) and writes
it to ``benchmarks/results/photo.md``.

Run: ``python benchmarks/bench_photo.py [--runs 3]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
from scipy import ndimage as ndi

sys.path.insert(0, str(Path(__file__).resolve().parent))

import real_data
from shadeform import synth
from shadeform.solvers.photo import photo_depth

RESULTS = Path(__file__).resolve().parent / "results" / "photo.md"


def cases():
    """(name, image, mask, light) to time."""
    light = np.array([5.0, 5.0, 7.0]) / np.sqrt(99.0)
    for size in (256, 512, 768):
        scene = synth.scene("ellipsoid", size=size, light=light, noise=0.01, seed=0)
        yield f"ellipsoid {size}², 1 % noise", np.clip(scene.image, 0, None), scene.mask, light
    if real_data.available():
        bear = real_data.diligent("bear")
        for factor in (1.0, 2.7):
            image = ndi.zoom(bear.image, factor, order=1) if factor != 1 else bear.image
            mask = ndi.zoom(bear.mask.astype(float), factor, order=1) > 0.5 if factor != 1 else bear.mask
            yield f"DiLiGenT bear x{factor:g}", image, mask, bear.light


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    lines = [
        "| case | object pixels | median s | worst s | ms / Mpx | peak MiB (traced) |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for name, image, mask, light in cases():
        photo_depth(image, mask, light)  # warm-up: fills the JIT cache
        times = []
        for _ in range(args.runs):
            start = time.perf_counter()
            photo_depth(image, mask, light)
            times.append(time.perf_counter() - start)
        tracemalloc.start()
        photo_depth(image, mask, light)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        pixels = int(mask.sum())
        median = statistics.median(times)
        lines.append(
            f"| {name} | {pixels:,} | {median:.2f} | {max(times):.2f} | "
            f"{median * 1e3 / (pixels / 1e6):,.0f} | {peak / 2**20:,.0f} |"
        )
        print(lines[-1], flush=True)
    text = "\n\n".join(
        [
            "# The photo solver: time and memory by size",
            f"`python benchmarks/bench_photo.py --runs {args.runs}` on {platform.node() or 'this machine'} "
            f"({os.cpu_count()} cores, Python {platform.python_version()}), {time.strftime('%Y-%m-%d')}; "
            "one thread, after a warm-up run.",
            "\n".join(lines),
        ]
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
