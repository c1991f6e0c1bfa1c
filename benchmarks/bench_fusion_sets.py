"""Benchmark: fused models whose views are photo sets (photometric stereo per view) against views
of one photo each (issue 35, items 3 and 5).

Each closed synthetic object (``shadeform.synth.CLOSED_OBJECTS``) is rendered from turntable views
(``--views``: 2 at 0/180 degrees, 4, or 8 evenly spaced; ``--size`` pixels); each view is either
one photo lit from the camera, solved alone (``shadeform.reconstruct``, light known), or a photo set
under six lights (one at the camera, five at 30 degrees of slant, ``light_directions.txt``: what a
turntable under a fixed dome of lights takes), solved by photometric stereo
(``shadeform.photometric.reconstruct_stereo``). Both go through ``shadeform fuse`` as a user runs
it (photos or folders, ``--angles``, settling and pose refinement on), and the model is scored
against the true surface (``metrics.surface_scores``: Chamfer % of the diagonal, F-score % at 1 %,
volume error %), with each view's outline kept (``outline_iou``, the worst of the views) and the
command's time (median of ``--runs``, solving and fusing, files written).

By default the photos are Lambertian renders saved as 16-bit files, their masks found. With
``--realistic`` they are what a camera gives of a painted, slightly glossy object: an albedo
painted on the object's surface (bands and patches in the object frame, so that every view sees
the same paint; 0.15 to 0.85), a Blinn-Phong highlight (0.25, shininess 60), Gaussian noise of
1 % of white, sRGB-encoded and quantised to 8 bits; the true masks are given (``--mask`` per
photo, ``mask.png`` in each set's folder).

    .venv/bin/python benchmarks/bench_fusion_sets.py [--size 128] [--runs 3] [--views 2,4,8] [--realistic] [--out FILE.md]
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
from helpers.photosets import SIX_LIGHTS, write_photo_set

RESULTS = Path(__file__).with_name("results") / "fusion-sets.md"
REALISTIC = Path(__file__).with_name("results") / "fusion-realistic.md"
SPECULAR, SHININESS, NOISE = 0.25, 60.0, 0.01


def angles_of(count: int) -> tuple[float, ...]:
    """``count`` turntable angles evenly spaced from 0 (2: 0 and 180)."""
    return tuple(360.0 * i / count for i in range(count))


def paint(view) -> np.ndarray:
    """The albedo painted on the object as ``view`` sees it (H, W): bands across the object
    frame's height and patches, from the surface points, so that every view sees the same paint."""
    h, w = view.mask.shape
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float64)
    camera = np.stack([cols - (w - 1) / 2, (h - 1) / 2 - rows, np.nan_to_num(view.depth)], axis=-1)
    rotation, translation = view.pose[:3, :3], view.pose[:3, 3]
    p = (camera - translation) @ rotation / (0.5 * h)  # the object frame, about -1 to 1
    bands = 0.5 + 0.5 * np.sign(np.sin(7.0 * p[..., 1]))
    patches = 0.5 + 0.5 * np.sin(4.0 * p[..., 0] + 2.0) * np.sin(5.0 * p[..., 2] - 1.0)
    return np.where(view.mask, 0.15 + 0.45 * bands + 0.25 * patches, 0.0)


def photograph(normals, mask, albedo, light, seed: int) -> np.ndarray:
    """The painted, slightly glossy object under one light, as an 8-bit sRGB file holds it
    (values in [0, 1], sRGB-encoded, quantised)."""
    n = np.nan_to_num(normals)
    light = np.asarray(light, dtype=np.float64)
    shade = np.maximum(n @ light, 0.0)
    half = (light + [0.0, 0.0, 1.0]) / np.linalg.norm(light + [0.0, 0.0, 1.0])
    gloss = np.where(shade > 0, SPECULAR * np.maximum(n @ half, 0.0) ** SHININESS, 0.0)
    linear = np.where(mask, albedo * shade + gloss, 0.0)
    linear = np.clip(linear + np.random.default_rng(seed).normal(0.0, NOISE, linear.shape) * mask, 0.0, 1.0)
    encoded = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    return np.rint(encoded * 255) / 255


def _write_views(views, folder: Path, realistic: bool):
    """Each view as a photo and as a photo set's folder; the masks to give (realistic only)."""
    photos, sets, masks = [], [], []
    for k, view in enumerate(views):
        stem = f"view{int(round(view.angle))}"
        photos.append(folder / f"{stem}.png")
        sets.append(folder / f"set_{stem}")
        if not realistic:
            save_gray(view.image, photos[-1], bitdepth=16)
            write_photo_set(sets[-1], np.nan_to_num(view.normals), view.mask)
            continue
        albedo = paint(view)
        save_gray(
            photograph(view.normals, view.mask, albedo, (0.0, 0.0, 1.0), seed=k), photos[-1], bitdepth=8
        )
        sets[-1].mkdir()
        for i, light in enumerate(SIX_LIGHTS):
            image = photograph(view.normals, view.mask, albedo, light, seed=100 * k + i)
            save_gray(image, sets[-1] / f"{i:03d}.png", bitdepth=8)
        np.savetxt(sets[-1] / "light_directions.txt", SIX_LIGHTS)
        masks.append(folder / f"{stem}_mask.png")
        save_gray(view.mask.astype(float), masks[-1], bitdepth=8)
        save_gray(view.mask.astype(float), sets[-1] / "mask.png", bitdepth=8)
    return photos, sets, masks


def _run(inputs, folder: Path, runs: int, angles, extra=()) -> tuple[dict, float, Path]:
    model = folder / "model.ply"
    command = ["fuse", *map(str, inputs), "--angles", ",".join(f"{a:g}" for a in angles)]
    command += ["-o", str(model), "--json", *map(str, extra)]
    seconds = []
    for _ in range(runs):
        start = time.perf_counter()
        result = CliRunner().invoke(app, command)
        seconds.append(time.perf_counter() - start)
        if result.exit_code != 0:
            raise RuntimeError(result.output)
    return json.loads(result.stdout), float(np.median(seconds)), model


def measure(name: str, size: int, runs: int, *, count: int = 4, realistic: bool = False) -> list[dict]:
    angles = angles_of(count)
    truth = synth.closed_object(name, size=size)
    points = truth.surface_points(200_000, seed=1)[0]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        photos, sets, masks = _write_views(synth.render_views(name, angles, size=size), tmp, realistic)
        given = [arg for path in masks for arg in ("--mask", path)]
        for label, inputs, extra in (("one photo", photos, given), ("a photo set (6 lights)", sets, ())):
            report, seconds, model = _run(inputs, tmp, runs, angles, extra)
            got = metrics.surface_scores(trimesh.load(model), points, truth.volume)
            rows.append(
                {
                    "object": name,
                    "count": count,
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


def table(rows: list[dict], command: str, realistic: bool) -> str:
    photos = (
        "painted, glossy, noisy photos saved as 8-bit sRGB, the true masks given"
        if realistic
        else "Lambertian renders saved as 16-bit files, masks found"
    )
    lines = [
        "# Fused models: views of one photo each against photo sets (photometric stereo per view)",
        "",
        f"`{command}` on {platform.machine()}, Python {platform.python_version()}; turntable views, "
        f"{photos}; `shadeform fuse` as a user runs it. Chamfer % of the diagonal (the scoring's floor "
        "about 0.17 %), F-score % at 1 %, volume error % (signed), the worst view's outline IoU, "
        "median seconds of the command.",
        "",
        "| object | views | each view | Chamfer | F-score | volume | worst IoU | watertight | s |",
        "|---|---:|---|---:|---:|---:|---:|:---:|---:|",
    ]
    for row in rows:
        lines.append(
            f"| {row['object']} | {row['count']} | {row['views']} | {row['chamfer']:.2f} | "
            f"{row['f_score']:.1f} | {row['volume']:+.1f} | {row['iou']:.3f} | "
            f"{'yes' if row['watertight'] else 'no'} | {row['seconds']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--objects", help="comma-separated (default: every closed object)")
    parser.add_argument("--views", default="4", help="comma-separated view counts (default 4)")
    parser.add_argument("--realistic", action="store_true", help="painted, glossy, noisy 8-bit sRGB photos")
    parser.add_argument("--out", type=Path, help="default results/fusion-sets.md, or fusion-realistic.md")
    args = parser.parse_args(argv)
    names = args.objects.split(",") if args.objects else list(synth.CLOSED_OBJECTS)
    counts = [int(v) for v in args.views.split(",")]
    rows = [
        row
        for name in names
        for count in counts
        for row in measure(name, args.size, args.runs, count=count, realistic=args.realistic)
    ]
    given = " ".join(sys.argv[1:] if argv is None else argv)
    text = table(rows, f"benchmarks/bench_fusion_sets.py {given}".strip(), args.realistic)
    print(text)
    with atomic_write(args.out or (REALISTIC if args.realistic else RESULTS)) as out:
        out.write(text.encode())


if __name__ == "__main__":
    main()
