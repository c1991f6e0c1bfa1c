"""Speed of the 2002 pipeline, stage by stage, on a 1024x1024 synthetic sphere (light +z).

Run with ``make bench``. Prints a Markdown table (median wall time of several runs after a warm-up
that fills the JIT cache, ms per megapixel of image, peak traced memory) and writes it to
``benchmarks/results/pipeline.md``.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

import shadeform
from shadeform import synth
from shadeform.integration.paths import integrate_paths
from shadeform.solvers.propagation import propagate_normals, refine_by_integrability


def measure(fn, runs):
    """Median seconds over ``runs`` calls (after one warm-up), and peak traced bytes of one call."""
    fn()
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return statistics.median(times), peak


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=1024)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "pipeline.md")
    args = parser.parse_args(argv)

    scene = synth.scene("sphere", size=args.size)
    image, mask, light = scene.image, scene.mask, np.asarray(scene.light)
    ref = np.unravel_index(np.argmax(np.where(mask, image, -1)), mask.shape)
    albedo = float(image[ref])
    cos_theta = np.clip(image / albedo, 0, 1)
    normals = propagate_normals(image, mask, light=light, reference=ref, albedo=albedo)
    refined = refine_by_integrability(normals, cos_theta, mask, light=light, iterations=3)
    rec = shadeform.reconstruct(image, mask=mask, solver="propagation", refine=0)
    mesh = shadeform.to_mesh(rec, step=1)
    tmp = Path(tempfile.mkdtemp())
    glb = tmp / "model.glb"

    stages = [
        (
            "normals: propagation (2002)",
            lambda: propagate_normals(image, mask, light=light, reference=ref, albedo=albedo),
        ),
        (
            "normals: integrability refinement x3",
            lambda: refine_by_integrability(normals, cos_theta, mask, light=light, iterations=3),
        ),
        ("depth: averaged paths", lambda: integrate_paths(refined, mask, origin=ref)),
        ("mesh (step 1)", lambda: shadeform.to_mesh(rec, step=1)),
        ("export .glb", lambda: shadeform.export(mesh, glb)),
        (
            "total, 2002 (propagation, refine=0): reconstruct + mesh + .glb",
            lambda: shadeform.export(
                shadeform.to_mesh(shadeform.reconstruct(image, mask=mask, solver="propagation", refine=0)),
                glb,
            ),
        ),
        (
            "total, propagation (refine=3): reconstruct + mesh + .glb",
            lambda: shadeform.export(
                shadeform.to_mesh(shadeform.reconstruct(image, mask=mask, solver="propagation")), glb
            ),
        ),
        (
            "total, default (auto: eikonal at +z): reconstruct + mesh + .glb",
            lambda: shadeform.export(shadeform.to_mesh(shadeform.reconstruct(image, mask=mask)), glb),
        ),
    ]
    megapixels = image.size / 1e6
    rows = []
    for name, fn in stages:
        seconds, peak = measure(fn, args.runs)
        rows.append(
            f"| {name} | {seconds * 1e3:,.0f} | {seconds * 1e3 / megapixels:,.0f} | {peak / 2**20:,.0f} |"
        )
        print(rows[-1], file=sys.stderr)

    header = (
        f"Sphere {args.size}x{args.size} ({int(mask.sum()):,} object pixels, mesh {mesh.n_vertices:,} vertices / "
        f"{mesh.n_faces:,} triangles), light +z; median of {args.runs} runs after a warm-up; "
        f"{os.cpu_count()} cores, Python {platform.python_version()}, numpy {np.__version__}.\n\n"
        "| stage | median ms | ms / Mpx | peak MiB (traced) |\n|---|---:|---:|---:|"
    )
    table = header + "\n" + "\n".join(rows) + "\n"
    print(table)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
