"""Benchmark: a closed model from a real photo and its mirror image (issue 35's mirror pairs).

For an object that is symmetric front to back, a photo's mirror image is a true photo from
behind. Each DiLiGenT object of ``../shared/data/real`` is taken as such a pair: its photo lit
nearest the camera as the 0-degree view and that photo (and mask) mirrored left to right as the
180-degree view, each solved alone with the light at the camera (DiLiGenT's nearest light is
within 5 degrees of it), then ``place`` and ``solid`` (what ``shadeform fuse a b --angles 0,180
--mask ...`` runs). Only ball and pot1 are close to symmetric front to back; the others still
test what every pair must keep: the outlines.

Per object: each view's silhouette IoU (:func:`shadeform.fusion.outlines.outline_iou`, the fused
model's projection into the view against its mask), the model's width and height against the mask's, its depth against the larger side
(issue 35's bars: IoU >= 0.95, extents within 5 %, depth <= 1.2 x the larger side, watertight),
and the time of the fusion (place and solid).

With ``--closed``, each object's photo alone is closed instead (:func:`shadeform.fusion.close`,
what ``shadeform reconstruct PHOTO --closed`` runs: the photo's reconstruction mirrored as the
back, no second photo solved, no pose refinement); the 180-degree IoU is then the mirror's, the
same by construction, and the time is the closing's.

    .venv/bin/python benchmarks/bench_fusion_pairs.py [--objects ball,pot1] [--closed] [--out FILE.md]
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np
import trimesh

import composites
import shadeform
from shadeform.fusion import close, place, solid
from shadeform.fusion.outlines import outline_iou
from shadeform.io.atomic import atomic_write
from shadeform.io.images import load_mask, read_photo


def pair(name: str):
    """The photo lit nearest the camera and its mirror image, with their masks."""
    folder = composites.DATA / "diligent" / name
    lights = np.loadtxt(folder / "light_directions.txt")
    photo = read_photo(folder / f"{int(np.argmax(lights[:, 2])) + 1:03d}.png").image
    mask = load_mask(folder / "mask.png")
    return [(photo, mask), (photo[:, ::-1].copy(), mask[:, ::-1].copy())]


def run(name: str, *, closed: bool = False) -> dict:
    views = pair(name)
    if closed:
        image, mask = views[0]
        rec = shadeform.reconstruct(image, mask=mask, light=(0.0, 0.0, 1.0))
        start = time.perf_counter()
        mesh = close(rec)
        seconds = time.perf_counter() - start
        ious = [mesh.outline_iou] * 2
    else:
        recs = [shadeform.reconstruct(image, mask=mask, light=(0.0, 0.0, 1.0)) for image, mask in views]
        start = time.perf_counter()
        placement = place(list(zip(recs, (0, 180))))
        mesh = solid(placement)
        seconds = time.perf_counter() - start
        ious = outline_iou(mesh, placement)
    rows, cols = np.nonzero(views[0][1])
    extent = np.ptp(mesh.vertices, axis=0)
    width, height = np.ptp(cols) + 1, np.ptp(rows) + 1
    return {
        "object": name,
        "iou": ious,
        "width": extent[0] / width,
        "height": extent[1] / height,
        "depth": extent[2] / max(width, height),
        "watertight": trimesh.Trimesh(mesh.vertices, mesh.faces).is_watertight,
        "seconds": seconds,
        "size": (width, height, extent),
    }


def report(rows, seconds: float, *, closed: bool = False) -> str:
    title = (
        "# A closed model from one photo, its back the photo mirrored (DiLiGenT, `shadeform.fusion.close`)"
        if closed
        else "# A closed model from a photo and its mirror image (DiLiGenT, 0 and 180 degrees)"
    )
    lines = [
        title,
        "",
        f"`python benchmarks/bench_fusion_pairs.py{' --closed' if closed else ''}` ({platform.machine()}, Python "
        f"{platform.python_version()}, {seconds:.0f} s). Bars (issue 35): IoU >= 0.95 per view, "
        "width and height within 5 % of the mask's, depth <= 1.2 x the larger side, watertight.",
        "",
        "| object | mask w x h | model w x h x d | IoU 0° | IoU 180° | width | height | depth / side | watertight | "
        + ("close s |" if closed else "fusion s |"),
        "|---|---|---|---:|---:|---:|---:|---:|---|---:|",
    ]
    for r in rows:
        w, h, e = r["size"]
        lines.append(
            f"| {r['object']} | {w} x {h} | {e[0]:.0f} x {e[1]:.0f} x {e[2]:.0f} | {r['iou'][0]:.3f} | "
            f"{r['iou'][1]:.3f} | {r['width']:.3f} | {r['height']:.3f} | {r['depth']:.2f} | "
            f"{'yes' if r['watertight'] else 'no'} | {r['seconds']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", default=",".join(composites.DILIGENT))
    parser.add_argument(
        "--closed", action="store_true", help="close each photo alone (shadeform.fusion.close)"
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="default: results/fusion-pairs.md (-closed.md)"
    )
    args = parser.parse_args()
    if args.out is None:
        name = "fusion-closed.md" if args.closed else "fusion-pairs.md"
        args.out = Path(__file__).parent / "results" / name
    if not composites.available():
        raise SystemExit(f"no real photographs at {composites.DATA}")
    start = time.perf_counter()
    rows = []
    for name in args.objects.split(","):
        rows.append(run(name, closed=args.closed))
        print(rows[-1], flush=True)
    text = report(rows, time.perf_counter() - start, closed=args.closed)
    with atomic_write(args.out, mode="w") as handle:
        handle.write(text)
    print(text)


if __name__ == "__main__":
    main()
