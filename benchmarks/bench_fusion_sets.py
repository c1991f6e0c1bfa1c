"""Benchmark: fused models whose views are photo sets (photometric stereo per view) against views
of one photo each (issue 35, item 3).

Each closed synthetic object (``shadeform.synth.CLOSED_OBJECTS``) is rendered from 4 turntable
views (0/90/180/270 degrees, ``--size`` pixels); each view is either one photo lit from the camera,
solved alone (``shadeform.reconstruct``, light known), or a photo set under six lights (one at
the camera, five at 30 degrees of slant, 16-bit, ``light_directions.txt``: what a turntable under
a fixed dome of lights takes), solved by photometric stereo
(``shadeform.photometric.reconstruct_stereo``). Both go through ``shadeform fuse`` as a user runs
it (photos or folders, ``--angles``, settling and pose refinement on), and the model is scored
against the true surface (``metrics.surface_scores``: Chamfer % of the diagonal, F-score % at 1 %,
volume error %), with each view's outline kept (``outline_iou``, the worst of the four) and the
command's time (median of ``--runs``, solving and fusing, files written).

    .venv/bin/python benchmarks/bench_fusion_sets.py [--size 128] [--runs 3] [--out FILE.md]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh
from typer.testing import CliRunner

from shadeform import metrics, synth
from shadeform.cli import app
from shadeform.io.atomic import atomic_write
from shadeform.io.maps import save_gray

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from helpers.photosets import write_photo_set

RESULTS = Path(__file__).with_name("results") / "fusion-sets.md"
ANGLES = (0, 90, 180, 270)


def _run(inputs, folder: Path, runs: int) -> tuple[dict, float, Path]:
    model = folder / "model.ply"
    seconds = []
    for _ in range(runs):
        start = time.perf_counter()
        result = CliRunner().invoke(
            app,
            ["fuse", *map(str, inputs), "--angles", ",".join(map(str, ANGLES)), "-o", str(model), "--json"],
        )
        seconds.append(time.perf_counter() - start)
        if result.exit_code != 0:
            raise RuntimeError(result.output)
    return json.loads(result.stdout), float(np.median(seconds)), model


def measure(name: str, size: int, runs: int) -> list[dict]:
    truth = synth.closed_object(name, size=size)
    points = truth.surface_points(200_000, seed=1)[0]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        views = synth.render_views(name, ANGLES, size=size)
        photos, sets = [], []
        for view in views:
            photos.append(tmp / f"view{int(view.angle)}.png")
            save_gray(view.image, photos[-1], bitdepth=16)
            sets.append(tmp / f"set{int(view.angle)}")
            write_photo_set(sets[-1], np.nan_to_num(view.normals), view.mask)
        for label, inputs in (("one photo each", photos), ("a photo set each (6 lights)", sets)):
            report, seconds, model = _run(inputs, tmp, runs)
            mesh = trimesh.load(model)
            got = metrics.surface_scores(mesh, points, truth.volume)
            rows.append(
                {
                    "object": name,
                    "views": label,
                    "chamfer": got["chamfer"],
                    "f_score": got["f_score"],
                    "volume": got["volume_error"],
                    "iou": min(report["outline_iou"]),
                    "watertight": got["watertight"],
                    "seconds": seconds,
                }
            )
            print(rows[-1], flush=True)
    return rows


def table(rows: list[dict], size: int, runs: int) -> str:
    lines = [
        "# Fused models: views of one photo each against photo sets (photometric stereo per view)",
        "",
        f"`benchmarks/bench_fusion_sets.py --size {size} --runs {runs}` on {platform.machine()}, "
        f"{platform.python_version()}; 4 turntable views of {size}x{size}, `shadeform fuse` as a user "
        "runs it. Chamfer % of the diagonal (the scoring's floor about 0.17 %), F-score % at 1 %, "
        "volume error % (signed), worst view's outline IoU, median seconds of the command.",
        "",
        "| object | views | Chamfer | F-score | volume | worst IoU | watertight | s |",
        "|---|---|---:|---:|---:|---:|:---:|---:|",
    ]
    for row in rows:
        lines.append(
            f"| {row['object']} | {row['views']} | {row['chamfer']:.2f} | {row['f_score']:.1f} | "
            f"{row['volume']:+.1f} | {row['iou']:.3f} | {'yes' if row['watertight'] else 'no'} | "
            f"{row['seconds']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--objects", help="comma-separated (default: every closed object)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    names = args.objects.split(",") if args.objects else list(synth.CLOSED_OBJECTS)
    rows = [row for name in names for row in measure(name, args.size, args.runs)]
    text = table(rows, args.size, args.runs)
    print(text)
    with atomic_write(args.out) as out:
        out.write(text.encode())


if __name__ == "__main__":
    main()
