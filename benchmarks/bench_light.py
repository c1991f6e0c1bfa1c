"""Light estimation from one image: accuracy and speed on the synthetic scenes and real photos.

Run with ``python benchmarks/bench_light.py`` (about ten minutes on two cores). For each scene
and slant it estimates the light under eight tilts (one at slant 0), without noise and with 2%
Gaussian noise, and reports the largest slant error, the largest tilt error (slant >= 10 only, as
in the bar of issue 3), the largest albedo error and the median time of one estimate. Rows marked
with a note are the answers one image allows where the light itself cannot be recovered (see
:func:`shadeform.light.estimate_light`). The same with the automatic mask (``mask=None``), the
bar of issue 11 (sphere, ellipsoid and bumps at slants 0, 20, 40 and 60, slant within 3 degrees).

Real photos, where ``../shared/data`` has them: both cues on the 96 DiLiGenT ball photos; the
frontal photo of each object of ``../shared/data/real`` (``real_data.py``), with its mask and with
the automatic one: light error, confidence, medians and worst (the bars of issue 11: median <= 8,
worst <= 30); and a held-out check (no constant tuned on it): every MIT-Berkeley photo and every
sixth DiLiGenT one (from the 21st on for ``bear``), whose lights are up to 70 degrees from the
viewer, by slant and by confidence. Prints Markdown and writes it to
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

import real_data
from shadeform import synth
from shadeform.errors import InputError
from shadeform.io.atomic import atomic_write
from shadeform.light import estimate_light, light_from_slant_tilt, slant_tilt

SLANTS = (0, 10, 20, 30, 45, 60)
AUTO_SLANTS = (0, 20, 40, 60)
AUTO_SCENES = ("sphere", "ellipsoid", "bumps")
TILTS = tuple(range(0, 360, 45))
NOISES = (0.0, 0.02)
SLANT_BAR, TILT_BAR = 3.0, 5.0
REAL_MEDIAN_BAR, REAL_WORST_BAR = 8.0, 30.0
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

### Issue 11: the automatic mask, real photos, the confidence

- **Why the automatic mask failed** (before issue 11: worst slant error 6.6° at slant 20, 14.4° at
  40, 18.6° at 60 on the sphere; 7.8°, 15.0°, 21.8° on the ellipsoid). The threshold mask stops at
  the attached shadow's edge: its far-side edge pixels are dim but lit (1-5% of k) where the
  outline would be dark, and the outline fit took them for a limb (sphere at slant 60: k L_xy read
  0.62 for 0.87), and the mask's deepest point lies toward the light (its level 0.70 for a
  k L_z of 0.50).
- **Reading the lit side alone always** was tried first: it fixes the synthetic scenes, but on
  real outlines (MIT-Berkeley frontal photos) the lit half alone cannot tell the inset term
  `kappa sqrt(d)` from `b . A` (deer 0.6° -> 11.9°, panther 6.4° -> 20.1°, frog 4.7° -> 17.4°). So
  it is read alone only where the far side is shown to be a shadow's edge (`_shadow_edge`) or,
  where the shadow is too thin to test, only its dim but lit pixels are left out.
- **`contour._BAND_SLACK` = 2.5.** The lit side's fit predicts the attached-shadow band on the far
  side too deep where the inset term varies along the outline: on the synthetic ellipsoid at slant
  20, tilt 180, 4.9 pixels at the far point for a true 2.1 (ratio 2.3).
- **`contour._EDGE_MAJORITY` = 0.75.** Tested far-side pixels lit inside / dark inside: threshold
  masks on the synthetic sphere and ellipsoid, noise-free, slants 20-60: 45-239 / 0-31 (at least
  85% lit); with 2% noise (where the mask also takes some noisy shadow): 66-97% at slants 40 and
  60, 19-27% at 20; masks drawn on the outline: 0-8 / 57-287 (at most 3% lit). A plain majority
  flipped a held-out MIT photo (paper1, light 9: 84 / 78) onto the lit side's fit (38° off); at
  three quarters it is left undecided.
- **`contour._top_too_dark`, the lower quartile.** DiLiGenT `reading` (frontal photo): the top
  reads 0.007 in the dark robe, `|(k L_xy, top)|` = 0.007, while the lit pixels' lower quartile is
  far above it; the old fallback read slant 89° (85° off). The median was tried first: it also set
  aside a right top on a held-out MIT photo (dinosaur, light 2, slant 64°: 0.260 against a median
  of 0.263; 6° off with the top, 41° without); the lower quartile keeps it.
- **`_evidence._SURVIVAL_BAND` = (0.02, 0.10)** (the brightest level from the distribution of the
  levels). On the synthetic sphere, ellipsoid and vase at slants 0-60, 4 tilts: median error of
  the level 0.0% noise-free, +0.4% with 2% noise, within +0.7% / +1.3%, except -11% where the
  vase's normals miss the light. Blinn-Phong highlights broad enough to cover 2% of the object
  (shininess 40) still raise it by 30-60%, as they raise the quadratic peak.
- **`_evidence._PEAK_PASSES` = 20** (the Lambertian peak's fit without the highlights). Sphere,
  albedo 0.6, Blinn-Phong highlight of strength 1.0 and shininess 200 clipped at 1, automatic mask,
  slants 20-60: the level 0.600-0.603 with 20 passes, 0.64-0.66 with the 3 of the top's fit; the
  slant error 4.3-6.4° against 10-27°.
- **`_evidence._PLATEAU_PIXELS` = 5, inside a solid plateau.** The brightest value of a smooth
  float image is one pixel (up to four on the symmetric synthetic scenes); a camera's clipping
  makes a plateau of hundreds (sphere at albedo 1.15: 4,400-8,300 pixels; a Blinn-Phong highlight
  of strength 1.0 and shininess 200 on albedo 0.6: 230-320). Counting the pixels at the brightest
  value alone took the top line of the synthetic cylinder for a plateau (light across its axis:
  0.4° -> 2.1°) and the pixels 2% noise pushes past the clipping level at 1 for one (cylinder at
  slant 0: 0.0° -> 8.5°); so the plateau must have that many connected pixels whose neighbours are
  all at the brightest value.
- **`estimate._MIN_DEPTH` = 3 pixels**, from the pixel grid (the outline is read from the mask
  smoothed over 2 pixels); no data.
- **The spread's parts** (the confidence). On the held-out photos of the table above, with the
  jackknife over the outline and the top-against-brightest-point angle only, the Spearman
  correlation of confidence and error was -0.35 (MIT-Berkeley) and -0.19 (DiLiGenT, where the
  outline's darkening biases every outline reading alike: 42 photos at confidence >= 0.95, 26%
  of them within 10°); adding the angle to the rings' reading made it -0.37 and -0.28, and 4
  DiLiGenT photos at >= 0.95.
"""


def _measure(case, size, noise, *, slants=SLANTS, automatic=False):
    """Rows of one case at one noise level: per slant, the largest errors, the median time, the
    evidence and the lowest confidence; with the automatic mask if ``automatic``."""
    label, name, keywords, tilts, target = case
    rows = {}
    for slant in slants:
        slant_errors, tilt_errors, albedo_errors, times, evidence, confidence = [], [], [], [], set(), []
        for i, tilt in enumerate((0,) if slant == 0 else (tilts or TILTS)):
            scene = synth.scene(
                name, size=size, light=light_from_slant_tilt(slant, tilt), noise=noise, seed=i
            )
            start = time.perf_counter()
            est = estimate_light(scene.image, None if automatic else scene.mask, **keywords)
            times.append(time.perf_counter() - start)
            confidence.append(est.confidence)
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
            min(confidence),
        )
    return label, rows


def _fmt(value, bar=None):
    if value is None:
        return "-"
    text = f"{value:.1f}"
    return f"**{text}**" if bar is not None and value > bar else text


def synthetic_tables(size):
    header = (
        "| scene | slant | slant err ° | tilt err ° | albedo err % | confidence (lowest) | slant err ° (2%) "
        "| tilt err ° (2%) | albedo err % (2%) | ms | evidence |\n"
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"
    )
    lines, summary = [header], []
    for case in CASES:
        label, clean = _measure(case, size, NOISES[0])
        _, noisy = _measure(case, size, NOISES[1])
        for slant in SLANTS:
            a, b = clean[slant], noisy[slant]
            lines.append(
                f"| {label} | {slant} | {_fmt(a[0], SLANT_BAR)} | {_fmt(a[1], TILT_BAR)} | "
                f"{a[2]:.1f} | {a[5]:.2f} | {_fmt(b[0])} | {_fmt(b[1])} | {b[2]:.1f} | {a[3]:.0f} | {a[4]} |"
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


def automatic_mask_table(size):
    """The bar of issue 11: the scenes with the automatic mask, which stops where the shading
    fades out (at the attached shadow's edge under an oblique light)."""
    lines = [
        "| scene | slant | slant err ° | tilt err ° | confidence (lowest) | slant err ° (2%) "
        "| tilt err ° (2%) | confidence (2%) | ms | evidence |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    worst = {}
    for name in AUTO_SCENES:
        case = (name, name, {}, None, _truth)
        _, clean = _measure(case, size, NOISES[0], slants=AUTO_SLANTS, automatic=True)
        _, noisy = _measure(case, size, NOISES[1], slants=AUTO_SLANTS, automatic=True)
        for slant in AUTO_SLANTS:
            a, b = clean[slant], noisy[slant]
            lines.append(
                f"| {name} | {slant} | {_fmt(a[0], SLANT_BAR)} | {_fmt(a[1])} | {a[5]:.2f} | {_fmt(b[0])} | "
                f"{_fmt(b[1])} | {b[5]:.2f} | {a[3]:.0f} | {a[4]} |"
            )
        worst[name] = max(clean[s][0] for s in AUTO_SLANTS)
    summary = ", ".join(f"{name} {value:.1f}°" for name, value in worst.items())
    met = "met" if max(worst.values()) <= SLANT_BAR else "**not met**"
    return f"Worst slant error, noise-free: {summary} (bar {SLANT_BAR:g}°: {met}).", "\n".join(lines)


def real_table():
    """The frontal photo of each real object, with its mask and the automatic one."""
    lines = [
        "| set | object | true slant ° | error °, mask | confidence | evidence | error °, automatic mask "
        "| confidence | evidence |",
        "|---|---|---:|---:|---:|---|---:|---:|---|",
    ]
    given_errors, auto_errors = [], []
    for case in real_data.cases():
        given = estimate_light(case.image, case.mask)
        given_errors.append(real_data.light_error(given.light, case))
        try:
            auto = estimate_light(case.image)
        except InputError as error:  # a refusal is reported, and counts as the worst error
            auto_errors.append(90.0)
            auto_text = f"refused ({error}) | - | -"
        else:
            auto_errors.append(real_data.light_error(auto.light, case))
            auto_text = f"{auto_errors[-1]:.1f} | {auto.confidence:.2f} | {auto.evidence}"
        lines.append(
            f"| {case.set} | {case.name} | {slant_tilt(case.light)[0]:.1f} | {given_errors[-1]:.1f} | "
            f"{given.confidence:.2f} | {given.evidence} | {auto_text} |"
        )
    summary = []
    for label, errors in (("its mask", given_errors), ("the automatic mask", auto_errors)):
        errors = np.array(errors)
        meets = np.median(errors) <= REAL_MEDIAN_BAR and errors.max() <= REAL_WORST_BAR
        summary.append(
            f"- with {label}: median {np.median(errors):.1f}°, worst {errors.max():.1f}° "
            f"(bars {REAL_MEDIAN_BAR:g}° / {REAL_WORST_BAR:g}°: {'met' if meets else '**not met**'}); "
            f"DiLiGenT median {np.median(errors[:6]):.1f}°, MIT-Berkeley median {np.median(errors[6:]):.1f}°"
        )
    return "\n".join(summary), "\n".join(lines)


def _held_out_photos():
    """Every MIT-Berkeley photo (each divided by its reflectance) and every sixth DiLiGenT one
    (each channel over its light's strength), with lights toward the viewer, as cases."""
    from shadeform.io.images import load_mask, load_pixels

    for name in real_data.DILIGENT:
        folder = real_data.DATA / "diligent" / name
        lights = np.loadtxt(folder / "light_directions.txt", comments="#", ndmin=2)
        strengths = np.loadtxt(folder / "light_intensities.txt", ndmin=2)
        names = (folder / "filenames.txt").read_text().split()
        mask = load_mask(folder / "mask.png")
        for i in range(20 if name == "bear" else 0, len(names), 6):
            image = (load_pixels(folder / names[i]).astype(np.float64) / strengths[i]) @ real_data.LUMA
            yield "diligent", image, mask, lights[i] / np.linalg.norm(lights[i])
    for name in real_data.MIT:
        folder = real_data.DATA / "mit-berkeley" / name
        lights = np.loadtxt(folder / "light_directions.txt", comments="#", ndmin=2)
        names = (folder / "filenames.txt").read_text().split()
        albedo = load_pixels(folder / "reflectance.png").astype(np.float64) @ real_data.LUMA
        mask = load_mask(folder / "mask.png", shape=albedo.shape) & (albedo > 0)
        for i, file in enumerate(names):
            light = lights[i] / np.linalg.norm(lights[i])
            if light[2] <= 0.05:
                continue  # at or behind the horizon: no estimate can be right
            image = load_pixels(folder / file).astype(np.float64) @ real_data.LUMA
            yield "mit", np.where(mask, image / np.where(albedo > 0, albedo, 1.0), 0.0), mask, light


def held_out_tables():
    """Light error by true slant, and the share within the confidence's angle by confidence."""
    from shadeform.light import CONFIDENCE_ANGLE

    found = []
    for dataset, image, mask, light in _held_out_photos():
        est = estimate_light(image, mask)
        found.append((dataset, slant_tilt(light)[0], _angle(est.light, light), est.confidence))
    lines = [
        "| set | true slant ° | photos | median error ° | 90th percentile ° | worst ° |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for dataset in ("diligent", "mit"):
        for low, high in ((0, 20), (20, 40), (40, 90)):
            errors = np.array([e for d, s, e, _ in found if d == dataset and low <= s < high])
            if errors.size:
                lines.append(
                    f"| {dataset} | {low}-{high} | {errors.size} | {np.median(errors):.1f} | "
                    f"{np.percentile(errors, 90):.1f} | {errors.max():.1f} |"
                )
    calibration = [
        f"| confidence | photos | mean confidence | share within {CONFIDENCE_ANGLE:g}° | median error ° |",
        "|---|---:|---:|---:|---:|",
    ]
    errors = np.array([e for *_, e, _ in found])
    confidence = np.array([c for *_, c in found])
    for low, high in ((0.0, 0.25), (0.25, 0.5), (0.5, 0.75), (0.75, 0.95), (0.95, 1.0001)):
        pick = (confidence >= low) & (confidence < high)
        if pick.any():
            calibration.append(
                f"| {low:g}-{min(high, 1.0):g} | {pick.sum()} | {confidence[pick].mean():.2f} | "
                f"{np.mean(errors[pick] < CONFIDENCE_ANGLE):.2f} | {np.median(errors[pick]):.1f} |"
            )
    from scipy.stats import spearmanr

    rank = float(spearmanr(confidence, errors).statistic)
    return len(found), rank, "\n".join(lines), "\n".join(calibration)


def round_table(size):
    """``cue="round"`` on the synthetic scenes, noise-free: exact only for round objects."""
    lines = ["| scene | max slant err ° | max tilt err ° |", "|---|---:|---:|"]
    for name in synth.SCENES:
        try:
            label, rows = _measure((name, name, {"cue": "round"}, None, _truth), size, 0.0)
        except InputError:
            lines.append(f"| {name} | refused (no rings to read) | |")
            continue
        slant = max(rows[s][0] for s in SLANTS)
        tilt = max((rows[s][1] for s in SLANTS if rows[s][1] is not None), default=0.0)
        lines.append(f"| {label} | {slant:.1f} | {tilt:.1f} |")
    return "\n".join(lines)


def ball_table(folder: Path):
    """Both cues on the 96 DiLiGenT ball photos (each channel over its light's intensity)."""
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
        for cue, rows in found.items():
            start = time.perf_counter()
            est = estimate_light(gray, mask, cue=cue)
            seconds = time.perf_counter() - start
            rows.append(
                (_angle(est.light, truth), est.slant - true_slant, _tilt_error(est.tilt, true_tilt), seconds)
            )
    lines = [
        "| cue | mean ° | median ° | max ° | mean slant err ° (signed) | mean tilt err ° | ms |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for cue, rows in found.items():
        rows = np.array(rows)
        lines.append(
            f"| {cue} | {rows[:, 0].mean():.2f} | {np.median(rows[:, 0]):.2f} | "
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
        f'`shadeform.estimate_light` (default `cue="contour"`) on the synthetic scenes, '
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
        '## `cue="round"` on the synthetic scenes',
        "",
        "Rings inside the silhouette, meant for photos of round objects (see the DiLiGenT ball "
        "below); noise-free, 8 tilts. Exact on the sphere, biased where cross-sections are not "
        "round (the vase); the cylinder, bowl and saddle have the same ambiguities as above, and "
        "a relief has no rings to read.",
        "",
        round_table(args.size),
        "",
    ]
    auto_summary, auto_detail = automatic_mask_table(args.size)
    text += [
        "## The automatic mask (issue 11)",
        "",
        "`estimate_light(image)` with no mask: `shadeform.preprocess.object_mask` finds the object "
        "by thresholding, so under an oblique light it stops at the edge of the attached shadow, "
        "not at the outline. Same scenes and tilts; bold: over the slant bar. " + auto_summary,
        "",
        auto_detail,
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
    if real_data.available():
        real_summary, real_detail = real_table()
        count, rank, by_slant, by_confidence = held_out_tables()
        text += [
            "## Real photos: the frontal photo of each object (issue 11)",
            "",
            "`../shared/data/real` through `benchmarks/real_data.py`: the photo of each object whose "
            "light is nearest the viewer (DiLiGenT: each channel over its light's strength, then "
            "luma, albedo, highlights and shadows kept; MIT-Berkeley: luma over the reflectance's "
            "luma). Angle between the estimated and the calibrated (DiLiGenT) or fitted "
            "(MIT-Berkeley) light, with the object's mask and with the automatic one; the "
            "confidence is the estimate's own (the chance of being within 10°).",
            "",
            real_summary,
            "",
            real_detail,
            "",
            "## Real photos: held out",
            "",
            f"{count} photos beyond the bars' frontal ones: every MIT-Berkeley photo with its light "
            "in front of the object's horizon and every sixth DiLiGenT one (from the 21st on for "
            "`bear`), each with its object's mask; lights up to 70° from the viewer. No constant was "
            "tuned on them; two rules were checked against them where they misfired (the tuning "
            "notes: `_top_too_dark`'s quartile, `_EDGE_MAJORITY`). DiLiGenT's painted, glossy "
            "objects darken toward the outline, which biases the outline's reading low.",
            "",
            by_slant,
            "",
            f"The confidence against the error (Spearman rank correlation {rank:.2f}; a calibrated "
            "confidence would match the share within 10° in each row):",
            "",
            by_confidence,
            "",
        ]
    else:
        text += [f"(Real photos not found at {real_data.DATA}: those checks skipped.)", ""]
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
