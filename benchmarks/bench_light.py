"""Light estimation from one image: accuracy and speed on the synthetic scenes and DiLiGenT's ball.

Run with ``python benchmarks/bench_light.py`` (about two minutes on two cores). For each scene and
slant it estimates the light under eight tilts (one at slant 0), without noise and with 2%
Gaussian noise, and reports the largest slant error, the largest tilt error (slant >= 10 only, as
in the bar of issue 3), the largest albedo error and the median time of one estimate. Rows marked
with a note are the answers one image allows where the light itself cannot be recovered (see
:func:`shadeform.light.estimate_light`). The real-image check runs both methods on the 96 DiLiGenT
ball photos if ``../shared/data/diligent-ball`` exists. Prints Markdown and writes it to
``benchmarks/results/light.md``, ending with the tuning notes: the measured figures behind the
constants and implementation choices of :mod:`shadeform.light`, kept here and not rerun.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from shadeform import synth
from shadeform.errors import InputError
from shadeform.io.atomic import atomic_write
from shadeform.light import estimate_light, light_from_slant_tilt, slant_tilt

SLANTS = (0, 10, 20, 30, 45, 60)
TILTS = tuple(range(0, 360, 45))
NOISES = (0.0, 0.02)
SLANT_BAR, TILT_BAR = 3.0, 5.0
BALL = Path(__file__).resolve().parents[2] / "shared" / "data" / "diligent-ball"


def _tilt_error(estimated: float, true: float) -> float:
    return abs((estimated - true + 180.0) % 360.0 - 180.0)


def _angle(a, b) -> float:
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), float(np.dot(a, b))))


# Each case: (row label, scene, estimate_light keywords, tilts to use or None for all,
# target (slant, tilt) the estimate should reach, given the true slant and tilt).
def _truth(slant, tilt):
    return slant, tilt


def _cylinder_seen(slant, tilt):
    x, _, z = light_from_slant_tilt(slant, tilt)
    return slant_tilt((x, 0.0, z))


def _mirrored(slant, tilt):
    return slant, 180.0 - tilt


CASES = [
    ("sphere", "sphere", {}, None, _truth),
    ("ellipsoid", "ellipsoid", {}, None, _truth),
    ("vase", "vase", {}, None, _truth),
    ("cylinder", "cylinder", {}, None, _truth),
    ("cylinder, light across the axis (tilt 0, 180)", "cylinder", {}, (0, 180), _truth),
    ("cylinder vs the light's projection across the axis [a]", "cylinder", {}, None, _cylinder_seen),
    ("bowl", "bowl", {}, None, _truth),
    ("bowl, convex=False [b]", "bowl", {"convex": False}, None, _truth),
    ("saddle", "saddle", {}, None, _truth),
    ("saddle vs the mirrored tilt 180 - t [c]", "saddle", {}, None, _mirrored),
    ("bumps", "bumps", {}, None, _truth),
]

NOTES = """\
[a] A cylinder seen side-on shows only the light's component across its axis: every light in the
plane through the axis and the viewer gives the same image up to k. The estimate is the least
slanted light that explains the image, the light's projection on the plane across the axis.

[b] A bowl lit from one side gives exactly the image of a dome lit from the other side; the
default (convex) answer is that dome's light, 180 degrees off in tilt; `convex=False` says
"concave".

[c] The saddle z = (x^2 - y^2) / 2s under tilt t gives the image of a dome under tilt 180 - t.
"""


# Measured once, by hand, when the constants and the implementation were chosen (not rerun here).
TUNING_NOTES = """\
## Tuning notes

The figures behind constants and implementation choices in `src/shadeform/light/`; each constant's
comment there names the data it was chosen on.

- **Relief fit: when to stop and what to trust** (`relief._SEARCH_FLOOR`, `_FIT_ACCEPT`,
  `_FIT_FALLBACK`). Five exact features leave about 1e-4 of the variance of the synthetic bumps at
  the search size, so the search stops at 3e-4 of the variance (plus 1.5 noise^2); a final fit is
  trusted below 1e-2 (plus 2 noise^2). When no search reaches that, the best fit is still used
  below 5e-2: the synthetic bumps at slant 60 leave 3.4%, a straight ridge (a chain that round
  features do not fit, `tests/test_light.py`) 12-16%.
- **One BLAS thread for the relief fit** (`relief.read_relief`, threadpoolctl). Its many small
  matrix products ran 10-25x slower with the BLAS thread pool on a busy machine.
- **The relief fit's solver** (`features._levenberg_marquardt`, Levenberg-Marquardt on the normal
  equations, reweighted for the Cauchy loss). Measured against `scipy.optimize.least_squares`
  (`method="trf"`, the same Jacobian, loss, slope bounds and evaluation budget, `x_scale="jac"`)
  on 2 cores, one BLAS thread. On the 93 joint fits of more than 3,000 pixels (up to 13,000 pixels
  x 99 parameters) that three bumps estimates make: 7.7 s against 29.9 s, and least_squares ended
  with a cost more than 5% higher on 28 of them (with `tr_solver="lsmr"`: 17.9 s, 51 higher):
  its trust-region step factors the whole (pixels x parameters) Jacobian by SVD, where
  Levenberg-Marquardt needs only J^T J. Over the 82 bumps estimates of this benchmark it made the
  estimates 4.8x slower in all, moved 5 of them at slant 60 between `relief` and
  `relief-spectrum` (slant by up to 3.5°; 56 of 82 stayed within 0.1°), and read the ridge of
  `tests/test_light.py` as `relief`. The hand-written solver stays; `tests/test_light.py` holds it
  to least_squares' minimum.
- **The compiled relief kernel** (`light/_relief_kernel.py`) against its reference
  (`features._render_features_reference`: the same model vectorised over pixels on
  `scipy.interpolate.BSpline` and its design matrix), on the fits of the same three estimates
  (180 to 13,000 pixels, 1 to 7 features): the image alone 6-30x faster (13,000 pixels, 6
  features: 3.4 ms against 21.8 ms), the image and its Jacobian 3-20x (9.4 ms against 33.5 ms);
  two whole bumps estimates (slant 30 tilt 45, slant 45 tilt 270) took 1.4 s with the kernel and
  4.8 s with the reference in its place, with the same lights.
"""


def _measure(case, size, noise):
    """Rows of one case at one noise level: per slant, the largest errors and the median time."""
    label, name, keywords, tilts, target = case
    rows = {}
    for slant in SLANTS:
        slant_errors, tilt_errors, albedo_errors, times, evidence = [], [], [], [], set()
        for i, tilt in enumerate((0,) if slant == 0 else (tilts or TILTS)):
            scene = synth.scene(
                name, size=size, light=light_from_slant_tilt(slant, tilt), noise=noise, seed=i
            )
            start = time.perf_counter()
            est = estimate_light(scene.image, scene.mask, **keywords)
            times.append(time.perf_counter() - start)
            want_slant, want_tilt = target(slant, tilt)
            slant_errors.append(abs(est.slant - want_slant))
            if want_slant >= 10:
                tilt_errors.append(_tilt_error(est.tilt, want_tilt))
            albedo_errors.append(abs(est.albedo - scene.albedo) / scene.albedo)
            evidence.add(est.evidence)
        rows[slant] = (
            max(slant_errors),
            max(tilt_errors) if tilt_errors else None,
            100.0 * max(albedo_errors),
            1e3 * statistics.median(times),
            "/".join(sorted(evidence)),
        )
    return label, rows


def _fmt(value, bar=None):
    if value is None:
        return "-"
    text = f"{value:.1f}"
    return f"**{text}**" if bar is not None and value > bar else text


def synthetic_tables(size):
    header = (
        "| scene | slant | slant err ° | tilt err ° | albedo err % | slant err ° (2%) "
        "| tilt err ° (2%) | albedo err % (2%) | ms | evidence |\n"
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"
    )
    lines, summary = [header], []
    for case in CASES:
        label, clean = _measure(case, size, NOISES[0])
        _, noisy = _measure(case, size, NOISES[1])
        for slant in SLANTS:
            a, b = clean[slant], noisy[slant]
            lines.append(
                f"| {label} | {slant} | {_fmt(a[0], SLANT_BAR)} | {_fmt(a[1], TILT_BAR)} | "
                f"{a[2]:.1f} | {_fmt(b[0])} | {_fmt(b[1])} | {b[2]:.1f} | {a[3]:.0f} | {a[4]} |"
            )
        worst = [
            max(clean[s][0] for s in SLANTS),
            max((clean[s][1] for s in SLANTS if clean[s][1] is not None), default=0.0),
            max(noisy[s][0] for s in SLANTS),
            max((noisy[s][1] for s in SLANTS if noisy[s][1] is not None), default=0.0),
        ]
        meets = worst[0] <= SLANT_BAR and worst[1] <= TILT_BAR
        summary.append(
            f"| {label} | {worst[0]:.1f} | {worst[1]:.1f} | {'yes' if meets else 'no'} "
            f"| {worst[2]:.1f} | {worst[3]:.1f} |"
        )
    summary_table = (
        "| scene | max slant err ° | max tilt err ° | bar (3° / 5°) met "
        "| max slant err ° (2%) | max tilt err ° (2%) |\n|---|---:|---:|---|---:|---:|\n" + "\n".join(summary)
    )
    return summary_table, "\n".join(lines)


def round_table(size):
    """``method="round"`` on the synthetic scenes, noise-free: exact only for round objects."""
    lines = ["| scene | max slant err ° | max tilt err ° |", "|---|---:|---:|"]
    for name in synth.SCENES:
        try:
            label, rows = _measure((name, name, {"method": "round"}, None, _truth), size, 0.0)
        except InputError:
            lines.append(f"| {name} | refused (no rings to read) | |")
            continue
        slant = max(rows[s][0] for s in SLANTS)
        tilt = max((rows[s][1] for s in SLANTS if rows[s][1] is not None), default=0.0)
        lines.append(f"| {label} | {slant:.1f} | {tilt:.1f} |")
    return "\n".join(lines)


def ball_table(folder: Path):
    """Both methods on the 96 DiLiGenT ball photos (each channel over its light's intensity)."""
    from shadeform.io.images import load_image_rgb, load_mask

    names = (folder / "filenames.txt").read_text().split()
    directions = np.loadtxt(folder / "light_directions.txt")
    intensities = np.loadtxt(folder / "light_intensities.txt")
    mask = load_mask(folder / "mask.png")
    found = {"contour": [], "round": []}
    for i, name in enumerate(names):
        gray = (load_image_rgb(folder / name) / intensities[i]).mean(axis=2)
        truth = directions[i] / np.linalg.norm(directions[i])
        true_slant, true_tilt = slant_tilt(truth)
        for method, rows in found.items():
            start = time.perf_counter()
            est = estimate_light(gray, mask, method=method)
            seconds = time.perf_counter() - start
            rows.append(
                (_angle(est.light, truth), est.slant - true_slant, _tilt_error(est.tilt, true_tilt), seconds)
            )
    lines = [
        "| method | mean ° | median ° | max ° | mean slant err ° (signed) | mean tilt err ° | ms |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for method, rows in found.items():
        rows = np.array(rows)
        lines.append(
            f"| {method} | {rows[:, 0].mean():.2f} | {np.median(rows[:, 0]):.2f} | "
            f"{rows[:, 0].max():.2f} | {rows[:, 1].mean():+.2f} | "
            f"{rows[:, 2].mean():.2f} | {1e3 * np.median(rows[:, 3]):.0f} |"
        )
    return len(names), "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--ball", type=Path, default=BALL)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "light.md")
    args = parser.parse_args(argv)

    estimate_light(*_warm_up(args.size))  # imports and caches off the clock
    summary, detail = synthetic_tables(args.size)
    text = [
        "# Light estimation from one image",
        "",
        f'`shadeform.estimate_light` (default `method="contour"`) on the synthetic scenes, '
        f"{args.size}x{args.size}, albedo 1; per row the largest error over 8 tilts (0, 45, ..., "
        "315; one at slant 0), tilt errors only where the slant is at least 10°; noise-free and "
        "with 2% Gaussian noise; median time of one estimate. Bold: over the bar of issue 3 "
        f"(slant {SLANT_BAR:g}°, tilt {TILT_BAR:g}°). {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, numpy {np.__version__}.",
        "",
        "## Summary",
        "",
        summary,
        "",
        NOTES,
        "## Per slant",
        "",
        detail,
        "",
        '## `method="round"` on the synthetic scenes',
        "",
        "Rings inside the silhouette, meant for photos of round objects (see the DiLiGenT ball "
        "below); noise-free, 8 tilts. Exact on the sphere, biased where cross-sections are not "
        "round (the vase); the cylinder, bowl and saddle have the same ambiguities as above, and "
        "a relief has no rings to read.",
        "",
        round_table(args.size),
        "",
    ]
    if (args.ball / "light_directions.txt").is_file():
        count, table = ball_table(args.ball)
        text += [
            "## Real photos: DiLiGenT ball",
            "",
            f"Angle between the estimated and the calibrated light over the {count} photos (each "
            "channel divided by its light's intensity, then averaged). The ball's glossy paint "
            "darkens toward the occluding contour, so `contour` reads too little of the light "
            "across the image (slant biased low); `round` reads rings inside the silhouette.",
            "",
            table,
            "",
        ]
    else:
        text += [f"(DiLiGenT ball not found at {args.ball}: real-image check skipped.)", ""]
    text += [TUNING_NOTES]
    markdown = "\n".join(text)
    print(markdown)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, mode="w") as handle:
        handle.write(markdown)
    return 0


def _warm_up(size):
    scene = synth.scene("sphere", size=size, light=light_from_slant_tilt(30, 45))
    return scene.image, scene.mask


if __name__ == "__main__":
    raise SystemExit(main())
