"""Material mode (``shadeform.texture.material``) on real photos, against measured normals.

There is no frame-filling material photo with measured normals in ``../shared/data``; the
closest are square patches inside the seven DiLiGenT objects (the largest inside each object's
mask eroded by 8 pixels, at most 96 px), photographed under calibrated lights. For every 8th of
each object's 96 photos (slant at least 15 degrees, under 20 % black) the patch goes to
``material(photo, light=the calibrated light)``, and the fine-scale slope along the light's tilt
(the one slope a single photo tells; both high-passed by a Gaussian of 6 px) is correlated with
the measured normals'; the same for brightness taken as height, as texture tools do. Median over
the photos. Writes ``benchmarks/results/material-real.md``.

Run: ``python benchmarks/bench_material_real.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.io
from scipy import ndimage

from shadeform import texture
from shadeform.io.atomic import atomic_write
from shadeform.photoset import load_photo_set

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "data" / "real" / "diligent"
OBJECTS = ("ball", "bear", "buddha", "cat", "cow", "pot1", "reading")


def slopes(normals):
    """``(dz/dx, dz/dy)`` of unit normals (x = column, y = -row)."""
    return -normals[..., 0] / normals[..., 2], -normals[..., 1] / normals[..., 2]


def high_pass(values, sigma=6.0):
    return values - ndimage.gaussian_filter(values, sigma)


def along(slope_x, slope_y, tilt):
    return high_pass(slope_x * tilt[0] + slope_y * tilt[1])


def correlation(a, b):
    inner = (slice(6, -6), slice(6, -6))  # away from the high-pass's edges
    return float(np.corrcoef(a[inner].ravel(), b[inner].ravel())[0, 1])


def object_row(name: str):
    photos = load_photo_set([REAL / name])
    truth = scipy.io.loadmat(REAL / name / "Normal_gt.mat")["Normal_gt"]
    inside = ndimage.distance_transform_edt(ndimage.binary_erosion(photos.mask, iterations=8))
    row, col = np.unravel_index(np.argmax(inside), inside.shape)
    half = int(min(inside.max() / 1.5, 48))
    patch = (slice(row - half, row + half), slice(col - half, col + half))
    true_x, true_y = slopes(truth[patch])
    ours, bright = [], []
    for j in range(0, len(photos.lights), 8):
        light = photos.lights[j] / np.linalg.norm(photos.lights[j])
        image = photos.images[j][patch]
        image = (image.mean(axis=2) if image.ndim == 3 else image) / np.mean(photos.intensities[j])
        if (image <= 0).mean() > 0.2 or np.degrees(np.arccos(light[2])) < 15:
            continue
        tilt = light[:2] / np.linalg.norm(light[:2])
        truth_along = along(true_x, true_y, tilt)
        found = texture.material(image, light=light).maps["normal_opengl"] * 2 - 1
        ours.append(correlation(truth_along, along(*slopes(found), tilt)))
        height = image / image.mean()  # texture tools: brightness is height
        bright.append(
            correlation(truth_along, along(np.gradient(height, axis=1), -np.gradient(height, axis=0), tilt))
        )
    return name, 2 * half, len(ours), float(np.median(ours)), float(np.median(bright))


def main():
    rows = []
    for name in OBJECTS:
        rows.append(object_row(name))
        print(rows[-1], flush=True)
    lines = [
        "# Material mode on real photos",
        "",
        "`benchmarks/bench_material_real.py`: square patches inside the DiLiGenT objects (8-bit), photos with "
        "the calibrated light; correlation of the fine-scale slope along the light's tilt with the measured "
        "normals' (median over the photos; 1 perfect, 0 unrelated).",
        "",
        "| object | patch px | photos | material mode | brightness as height |",
        "|---|---:|---:|---:|---:|",
        *(
            f"| {name} | {size} | {count} | {ours:.2f} | {bright:.2f} |"
            for name, size, count, ours, bright in rows
        ),
        "",
    ]
    with atomic_write(ROOT / "benchmarks" / "results" / "material-real.md", mode="w") as f:
        f.write("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
