"""Photometric stereo benchmark: every photometric model of the registry, real and synthetic.

Real: the seven DiLiGenT objects of ``../shared/data/real/diligent`` (8-bit crops, all 96
photos, calibrated lights) and the 16-bit ball of ``../shared/data/diligent-ball``, each
channel divided by its light's strength, against the measured normals and the published mean
angular errors on the full-precision photos (Shi et al., TPAMI 2019: least squares, and the
best classical method there, Shi et al. 2014). Synthetic: the sphere at 128x128 under 40
lights (slants 5-50 degrees, random tilts, seed 1), albedo 0.7, Lambertian or with a
Blinn-Phong highlight, with and without noise; the robust fit's thresholds were chosen on these.
Reports mean angular error, pixels of the mask without a normal, the photos rescaled or left
out, the median and worst time of several runs and the peak traced memory of one. Writes
``benchmarks/results/stereo.md``.

Run: ``python benchmarks/bench_stereo.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import tracemalloc
from functools import partial
from pathlib import Path

import numpy as np

from reports import publish
from shadeform import synth
from shadeform.light import light_from_slant_tilt
from shadeform.photometric import MODELS, photometric_stereo

ROOT = Path(__file__).resolve().parents[1]
BALL = ROOT.parent / "shared" / "data" / "diligent-ball"
REAL = ROOT.parent / "shared" / "data" / "real" / "diligent"
OBJECTS = ("ball", "bear", "buddha", "cat", "cow", "pot1", "reading")
#: Mean angular errors on the full-precision photos, DiLiGenT paper (Shi et al., TPAMI 2019):
#: least squares, and the best classical method there (Shi et al. 2014, bi-polynomial).
PUBLISHED_OBJECTS = {
    "least squares": {
        "ball": 4.10,
        "bear": 8.39,
        "buddha": 14.92,
        "cat": 8.41,
        "cow": 25.60,
        "pot1": 8.89,
        "reading": 19.80,
    },
    "Shi et al. 2014": {
        "ball": 1.74,
        "bear": 6.12,
        "buddha": 10.60,
        "cat": 6.12,
        "cow": 13.93,
        "pot1": 6.51,
        "reading": 13.63,
    },
}
#: (label, specular, shininess, noise) of the synthetic cases.
CASES = (
    ("Lambertian", 0.0, 50.0, 0.0),
    ("Lambertian, noise 1 %", 0.0, 50.0, 0.01),
    ("Lambertian, noise 3 %", 0.0, 50.0, 0.03),
    ("highlight, shininess 50", 0.5, 50.0, 0.0),
    ("highlight, shininess 50, noise 1 %", 0.5, 50.0, 0.01),
    ("highlight, shininess 20 (broad)", 0.5, 20.0, 0.0),
)
PUBLISHED = {"least_squares": 4.10, "best classical (Shi et al. 2014)": 1.74}


def angles(normals, truth, mask):
    cos = np.clip(np.sum(normals[mask] * truth[mask], axis=1), -1, 1)
    return np.degrees(np.arccos(cos))


def timed(fn, repeats):
    """The result, the median and worst time of ``repeats`` runs, and the peak traced memory (MiB)
    of one more."""
    times, out = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    return out, float(np.median(times)), float(max(times)), peak


def synthetic_rows(repeats):
    rng = np.random.default_rng(1)
    lights = np.array(
        [light_from_slant_tilt(s, t) for s, t in zip(rng.uniform(5, 50, 40), rng.uniform(0, 360, 40))]
    )
    scene = synth.scene("sphere", size=128)
    rows = []
    for label, specular, shininess, noise in CASES:
        images = np.stack(
            [
                synth.render(
                    scene.normals,
                    scene.mask,
                    light=light,
                    albedo=0.7,
                    specular=specular,
                    shininess=shininess,
                    noise=noise,
                    seed=i,
                )
                for i, light in enumerate(lights)
            ]
        )
        cells = []
        for model in MODELS:
            result, seconds, _, _ = timed(
                partial(photometric_stereo, images, lights, scene.mask, model=model), repeats
            )
            errors = angles(result.normals, scene.normals, scene.mask)
            cells.append((float(np.nanmean(errors)), float(np.nanmedian(errors)), seconds))
        rows.append((label, int(scene.mask.sum()), cells))
        print(label, cells, flush=True)
    return rows, len(lights)


#: The default model with the lights and their strengths unknown (read from the photos).
UNKNOWN = "bivariate, unknown lights"


def solve_set(photos, model, repeats):
    """``timed`` photometric stereo of a loaded photo set with its calibrated lights, or (the
    model :data:`UNKNOWN`) with none."""
    if model == UNKNOWN:
        return timed(partial(photometric_stereo, photos.images, None, photos.mask), repeats)
    return timed(
        partial(
            photometric_stereo,
            photos.images,
            photos.lights,
            photos.mask,
            intensities=photos.intensities,
            model=model,
        ),
        repeats,
    )


def real_rows(repeats):
    """Per object and model: mean error, pixels without a normal, photos rescaled and dropped,
    median and worst seconds, peak MiB, object pixels."""
    import scipy.io

    from shadeform.photoset import load_photo_set

    rows, light_errors = [], {}
    for name in OBJECTS:
        folder = REAL / name
        photos = load_photo_set([folder])
        truth = scipy.io.loadmat(folder / "Normal_gt.mat")["Normal_gt"]
        for model in (*MODELS, UNKNOWN):
            result, median, worst, peak = solve_set(photos, model, repeats)
            errors = angles(result.normals, truth, photos.mask)
            if model == UNKNOWN:
                given = photos.lights / np.linalg.norm(photos.lights, axis=1, keepdims=True)
                cosines = np.clip(np.sum(result.lights * given, axis=1), -1, 1)
                light_errors[name] = float(np.median(np.degrees(np.arccos(cosines))))
            holes = int(np.count_nonzero(~np.isfinite(result.normals[photos.mask][:, 0])))
            rows.append(
                (name, model, float(np.nanmean(errors)), holes, len(result.photos_rescaled),
                 len(result.photos_dropped), median, worst, peak, int(photos.mask.sum()))
            )  # fmt: skip
            print(rows[-1], flush=True)
    return rows, light_errors


def ball_rows(repeats):
    import scipy.io

    from shadeform.photoset import load_photo_set

    ball = load_photo_set([BALL])
    truth = scipy.io.loadmat(BALL / "Normal_gt.mat")["Normal_gt"]
    rows = []
    for model in MODELS:
        result, median, worst, peak = solve_set(ball, model, repeats)
        errors = angles(result.normals, truth, ball.mask)
        rows.append(
            (
                model,
                float(np.nanmean(errors)),
                float(np.nanmedian(errors)),
                median,
                worst,
                peak,
                int(ball.mask.sum()),
            )
        )
        print(rows[-1], flush=True)
    return rows, len(ball.paths)


def main(argv=None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "stereo.md")
    args = parser.parse_args(argv)
    warm = synth.scene("sphere", size=32)  # first-use (compiling) costs outside the timings
    directions = np.array([light_from_slant_tilt(30, t) for t in range(0, 360, 10)])
    warm_images = np.stack([synth.render(warm.normals, warm.mask, light=d) for d in directions])
    for model in MODELS:
        photometric_stereo(warm_images, directions, warm.mask, model=model)
    synthetic, count = synthetic_rows(args.repeats)
    lines = [
        "# Photometric stereo",
        "",
        f"`shadeform.photometric_stereo`; times are medians of {args.repeats} runs, wall clock, "
        f"{os.cpu_count()} CPUs, {platform.processor() or platform.machine()}; ms/Mpx per "
        "megapixel of object pixels.",
        "",
    ]
    if REAL.is_dir():
        rows, light_errors = real_rows(args.repeats)
        columns = (*MODELS, UNKNOWN)
        lines += [
            "## DiLiGenT, seven objects (8-bit crops, 96 calibrated photos each)",
            "",
            'Mean angular error of the normals (degrees) over the mask; "unknown lights": the lights and '
            "their strengths read from the photos (uncalibrated), with the median angle between those and "
            'the calibrated lights; "holes": pixels of the mask '
            'without a normal; "rescaled" / "dropped": photos whose light strength was found '
            "wrong and corrected, or that nothing explained. Published: on the full-precision photos "
            "(DiLiGenT paper, Shi et al. TPAMI 2019).",
            "",
            "| object | "
            + " | ".join(columns)
            + " | "
            + " | ".join(f"published {k}" for k in PUBLISHED_OBJECTS)
            + " | lights read, median error | holes | rescaled / dropped | "
            + " | ".join(f"{m} s (worst)" for m in columns)
            + " |",
            "|---|" + "---:|" * (2 * len(columns) + len(PUBLISHED_OBJECTS) + 3),
        ]
        table = {(name, model): row for row in rows for name, model in [row[:2]]}
        means = {m: [] for m in columns}
        for name in OBJECTS:
            cells = []
            for model in columns:
                means[model].append(table[name, model][2])
                cells.append(f"{table[name, model][2]:.2f}")
            cells += [f"{PUBLISHED_OBJECTS[k][name]:.2f}" for k in PUBLISHED_OBJECTS]
            holes = "/".join(str(table[name, m][3]) for m in columns)
            default = table[name, MODELS[0]]
            cells += [f"{light_errors[name]:.1f}", holes, f"{default[4]} / {default[5]}"]
            cells += [f"{table[name, m][6]:.2f} ({table[name, m][7]:.2f})" for m in columns]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        lines.append(
            "| **mean** | "
            + " | ".join(f"**{np.mean(means[m]):.2f}**" for m in columns)
            + " | "
            + " | ".join(f"{np.mean(list(PUBLISHED_OBJECTS[k].values())):.2f}" for k in PUBLISHED_OBJECTS)
            + f" | {np.median(list(light_errors.values())):.1f} (median) | |"
            + " |" * (len(columns) + 1)
        )
        peak = max(row[8] for row in rows)
        lines += [
            "",
            f"Holes per model in the order of the columns; peak traced memory of one solve at most {peak:,.0f} MiB.",
            "",
        ]
    if BALL.is_dir():
        ball, photos = ball_rows(args.repeats)
        lines += [
            f"## DiLiGenT ball, 16-bit ({photos} calibrated photos, glossy)",
            "",
            "Mean and median angular error against the ground truth, degrees. Published: least "
            f"squares {PUBLISHED['least_squares']:.2f}, the benchmark's best classical method "
            f"(Shi et al. 2014) {PUBLISHED['best classical (Shi et al. 2014)']:.2f}.",
            "",
            "| model | mean ° | median ° | time (s) | worst (s) | ms / Mpx | peak MiB |",
            "|---|---:|---:|---:|---:|---:|---:|",
        ]
        for model, mean, median, seconds, worst, peak, pixels in ball:
            lines.append(
                f"| {model} | {mean:.2f} | {median:.2f} | {seconds:.2f} | {worst:.2f} "
                f"| {seconds * 1e3 / (pixels / 1e6):,.0f} | {peak:,.0f} |"
            )
        lines.append("")
    lines += [
        f"## Synthetic sphere, 128x128, {count} lights (slant 5-50°), albedo 0.7",
        "",
        "Mean / median angular error, degrees, over the object (shadowed pixels included); time "
        "of one solve (ms).",
        "",
        "| case | " + " | ".join(f"{m} mean ° | {m} median ° | {m} ms" for m in MODELS) + " |",
        "|---|" + "---:|" * (3 * len(MODELS)),
    ]
    for label, _, cells in synthetic:
        lines.append(
            f"| {label} | "
            + " | ".join(f"{mean:.2f} | {median:.2f} | {t * 1e3:.0f}" for mean, median, t in cells)
            + " |"
        )
    return publish(lines, args.out)


if __name__ == "__main__":
    main()
