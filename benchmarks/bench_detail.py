"""Benchmark: the share of outlying fine detail, renders plus noise against real photographs.

``solver="auto"`` takes the photo solver for a noisy image whose fine detail is not Gaussian
noise (:data:`shadeform.solvers.OUTLIERS`, :func:`shadeform.preprocess.image_detail`). This
measures that share on the two groups it must tell apart and writes
``benchmarks/results/detail.md``:

- renders plus noise: the seven synthetic scenes at 64, 256 and 512 px, under +z and slants 30
  and 45 degrees (tilt 45), with 1 % and 3 % Gaussian noise, as float and as 8-bit images;
- the 18 real photographs of ``real_data.py`` (and, apart, the raw MIT-Berkeley photos with their
  paint), with their masks.

Usage: ``python benchmarks/bench_detail.py [--out benchmarks/results/detail.md]``
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

import real_data
from shadeform import synth
from shadeform.io.atomic import atomic_write
from shadeform.light import light_from_slant_tilt
from shadeform.preprocess import image_detail
from shadeform.solvers import NOISY, OUTLIERS

SIZES = (64, 256, 512)
NOISES = (0.01, 0.03)
SLANTS = (0.0, 30.0, 45.0)


def _row(image: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """Noise over the brightest object value, and the share of outlying detail."""
    detail = image_detail(image, mask)
    return detail.noise / float(image[mask].max()), detail.outliers


def renders() -> list[tuple[str, float, float]]:
    rows = []
    for name in synth.SCENES:
        for size in SIZES:
            for slant in SLANTS:
                for noise in NOISES:
                    scene = synth.scene(
                        name, size=size, light=light_from_slant_tilt(slant, 45.0), noise=noise, seed=0
                    )
                    image = np.clip(scene.image, 0.0, None)
                    label = f"{name} {size} px, slant {slant:.0f}, noise {noise:.0%}"
                    rows.append((label, *_row(image, scene.mask)))
                    rows.append((label + ", 8-bit", *_row(np.round(image * 255) / 255, scene.mask)))
    return rows


def photos(*, raw: bool) -> list[tuple[str, float, float]]:
    cases = [real_data.mit(name, raw=True) for name in real_data.MIT] if raw else real_data.cases()
    return [(f"{case.set} {case.name}", *_row(case.image, case.mask)) for case in cases]


def _summary(label: str, rows) -> str:
    outliers = np.array([r[2] for r in rows])
    noisy = np.array([r[1] > NOISY for r in rows])
    photo = noisy & (outliers >= OUTLIERS)
    return (
        f"| {label} | {len(rows)} | {outliers.min():.4f} | {np.median(outliers):.4f} | {outliers.max():.4f} "
        f"| {int(noisy.sum())} | {int(photo.sum())} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "detail.md")
    args = parser.parse_args()
    started = time.perf_counter()
    groups = [("renders plus noise", renders())]
    if real_data.available():
        groups += [
            ("real photos (bench_real)", photos(raw=False)),
            ("raw MIT-Berkeley photos", photos(raw=True)),
        ]
    lines = [
        "# Outlying detail: renders plus noise against real photographs",
        "",
        f"`python benchmarks/bench_detail.py` on {platform.node()} ({platform.python_version()}), "
        f"{time.strftime('%Y-%m-%d')}, {time.perf_counter() - started:.0f} s. The share of each image's fine "
        "detail (pixel minus its 3x3 mean, more than 2 px inside the object) beyond 4 robust standard "
        f"deviations (`shadeform.preprocess.image_detail`); independent Gaussian noise leaves 6e-5. "
        f"`auto` takes the photo solver where the noise is above {NOISY} of the brightest value and the "
        f"share is at least {OUTLIERS} (`shadeform.solvers.OUTLIERS`).",
        "",
        "| group | images | outliers min | median | max | noisy | photo solver |",
        "|---|---:|---:|---:|---:|---:|---:|",
        *(_summary(label, rows) for label, rows in groups),
    ]
    for label, rows in groups:
        rows = sorted(rows, key=lambda r: r[2])
        shown = rows if len(rows) <= 30 else rows[-10:]
        lines += ["", f"## {label}" + ("" if len(rows) <= 30 else " (the 10 highest)"), ""]
        lines += ["| image | noise | outliers |", "|---|---:|---:|"]
        lines += [f"| {name} | {noise:.4f} | {outliers:.4f} |" for name, noise, outliers in shown]
    text = "\n".join(lines) + "\n"
    with atomic_write(args.out, mode="w") as handle:
        handle.write(text)
    print(text)


if __name__ == "__main__":
    main()
