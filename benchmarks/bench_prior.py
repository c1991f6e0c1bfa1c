"""The learned shape prior on generated photos of a held-out seed, and its speed.

Two tables, written to ``benchmarks/results/prior.md``:

1. **Generated photos** (:mod:`shadeform.prior.photos`, seed 1000, never trained on; objects of
   every kind, painted, glossy, noisy, sRGB/JPEG or linear, the user's mask off by a pixel or two):
   mean normal error (degrees) of the silhouette-only shape, the network alone (``learned``), the
   photo solver (``photo``) and the photo solver guided by the prior (``guided``) at several prior
   weights (``--weights``), each with the true light and with ``light="estimate"``. This is where
   :data:`shadeform.solvers.learned.PRIOR` is chosen: on the project's own generated photos,
   never on a benchmark's.
2. **Speed**: the network alone (:func:`shadeform.prior.predict`) and the whole single-photo job to
   a mesh (``reconstruct(method=...)`` then ``to_mesh``) at 0.3 Mpx, warm: median and worst of
   ``--repeats`` runs, ms per megapixel, peak memory of the process.

Run: ``python benchmarks/bench_prior.py [--photos 16] [--weights 0.1,0.3,1] [--repeats 5]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import time
from pathlib import Path

import numpy as np

import shadeform
from shadeform.metrics import angular_error, normals_of_height
from shadeform.prior import predict
from shadeform.prior.dataset import CANVAS, shapes
from shadeform.prior.photos import random_photo
from shadeform.prior.shapes import random_shape
from shadeform.solvers import learned
from shadeform.solvers.photo import silhouette_depth

RESULTS = Path(__file__).resolve().parent / "results" / "prior.md"
SEED = 1000  # the training uses seed 0 (docs/prior.md)


def generated(count: int, weights) -> tuple[list[str], list[dict]]:
    """One row per generated photo: ``{column: mean error in degrees}``."""
    size = 160  # photos of 240 px: the network frames them down to its 128
    bank = shapes(SEED, range(count), size=size)
    rows = []
    for index, shape in enumerate(bank):
        rng = np.random.default_rng([SEED, 2, index])
        photo = random_photo(rng, shape)
        valid = photo.mask & shape.mask
        truth = np.nan_to_num(photo.normals).astype(np.float64)
        row = {
            "kind": shape.kind,
            "silhouette": angular_error(normals_of_height(silhouette_depth(photo.mask)), truth, valid),
        }
        row["learned"] = angular_error(predict(photo.image, photo.mask).normals, truth, valid)
        for light_name, light in (("known", photo.light), ("estimate", "estimate")):
            rec = shadeform.reconstruct(photo.image, mask=photo.mask, light=light, solver="photo")
            row[f"photo ({light_name})"] = angular_error(rec.normals, truth, valid)
            for weight in weights:
                learned.PRIOR = weight
                rec = shadeform.reconstruct(photo.image, mask=photo.mask, light=light, solver="guided")
                row[f"guided {weight:g} ({light_name})"] = angular_error(rec.normals, truth, valid)
        rows.append(row)
        print(
            index,
            " ".join(f"{k}={v:.1f}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()),
            flush=True,
        )
    columns = [c for c in rows[0] if c != "kind"]
    return columns, rows


def speed(repeats: int) -> list[tuple[str, list[float], float]]:
    """(what, seconds per run, megapixels) on a generated photo of 480 x 640 (0.31 Mpx)."""
    rng = np.random.default_rng(SEED)
    shape = random_shape(rng, 480, kind="ellipsoid")  # a canvas of 480 x 480, padded to 480 x 640
    photo = random_photo(rng, shape)
    image, mask = (np.pad(a, ((0, 0), (80, 80))) for a in (photo.image, photo.mask))
    print(f"speed: {image.shape[1]} x {image.shape[0]}, {int(mask.sum())} object pixels", flush=True)
    out = []
    runs = [("network alone (predict)", lambda: predict(image, mask))]
    for method in ("learned", "guided", "photo"):
        runs.append(
            (
                f"photo to mesh, method={method}",
                lambda m=method: shadeform.to_mesh(
                    shadeform.reconstruct(image, mask=mask, light="estimate", solver=m)
                ),
            )
        )
    for what, run in runs:
        run()  # warm: the model loaded, the kernels compiled
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            run()
            times.append(time.perf_counter() - start)
        out.append((what, times, image.size / 1e6))
        print(what, f"{np.median(times):.3f} s", flush=True)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--photos", type=int, default=16)
    parser.add_argument("--weights", default="0.1,0.3,1", help="prior weights of 'guided' to measure")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    weights = [float(w) for w in args.weights.split(",")]
    chosen = learned.PRIOR
    columns, rows = generated(args.photos, weights)
    learned.PRIOR = chosen
    timing = speed(args.repeats)
    lines = [
        "# The learned shape prior: generated photos of a held-out seed, and speed",
        f"`python benchmarks/bench_prior.py --photos {args.photos} --weights {args.weights}` on "
        f"{platform.node() or 'this machine'} ({os.cpu_count()} cores, Python {platform.python_version()}), "
        f"{time.strftime('%Y-%m-%d')}. Photos of {round(CANVAS * 160)} px made by `shadeform.prior.photos` "
        f"from seed {SEED} (the shipped network was trained on seed 0). Mean normal error (degrees) over "
        "the object's pixels inside the user's mask.",
        "## Generated photos (degrees)",
        "| photo | kind | " + " | ".join(columns) + " |",
        "|---:|---|" + "---:|" * len(columns),
    ]
    for index, row in enumerate(rows):
        lines.append(f"| {index} | {row['kind']} | " + " | ".join(f"{row[c]:.1f}" for c in columns) + " |")
    lines.append(
        "| **median** | | " + " | ".join(f"**{np.median([r[c] for r in rows]):.1f}**" for c in columns) + " |"
    )
    lines.append("| mean | | " + " | ".join(f"{np.mean([r[c] for r in rows]):.1f}" for c in columns) + " |")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    lines += [
        "## Speed at 0.3 Mpx (640 x 480, warm)",
        f"Peak memory of the benchmark's process: {peak:.0f} MB.",
        "| what | median s | worst s | ms per Mpx (median) |",
        "|---|---:|---:|---:|",
    ]
    for what, times, mpx in timing:
        lines.append(
            f"| {what} | {np.median(times):.3f} | {max(times):.3f} | {1000 * np.median(times) / mpx:.0f} |"
        )
    args.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
