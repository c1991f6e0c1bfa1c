"""Material mode (``shadeform.texture.material``) against what texture-map tools do, on rendered
rough surfaces whose normals are known.

Each case: a periodic rough surface (``synth.material_surface``, 256x256, slopes 0.25 RMS, three
seeds), rendered Lambertian (albedo 0.7, 1 % noise) under one light, times a lighting gradient
across the frame (``exp(0.4 x - 0.3 y - 0.5 r^2)``, the frame spanning -0.5..0.5), and in the
"occlusion and albedo" variant also times its ambient occlusion (0.3 + 0.7 AO: cavities darker)
and a blotchy albedo (+-20 %). Compared, by the mean angle between recovered and true normals:

- **material, light given**: ``material(photo, light=...)``;
- **material, light read**: ``material(photo)`` (the light's axis from the photo, its side the
  one nearer above, slant 45 degrees);
- **brightness as height**: what texture tools do (GIMP's normal-map filter, CrazyBump-style):
  the photo's brightness, less its large-scale part, taken for height, normals from its
  differences; its strength chosen *with the ground truth*: among 0.3 ... 100 the best (which
  is nearly flat), and the one whose slopes are as steep as the truth's (what a user would dial
  in to see the relief);
- **flat**: every normal straight up.

Writes ``benchmarks/results/material.md`` and ``material.png`` (photo; normal maps: material,
brightness as height, truth). Run: ``python benchmarks/bench_material.py``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

from shadeform import synth, texture
from shadeform.io.atomic import atomic_write
from shadeform.light import light_from_slant_tilt

ROOT = Path(__file__).resolve().parents[1]
LIGHTS = ((20, 100), (30, 60), (45, 135), (45, 100), (60, 80), (45, 300))
STRENGTHS = (0.3, 1, 3, 10, 30, 100)


def angles(normals, truth):
    return np.degrees(np.arccos(np.clip(np.sum(normals * truth, axis=-1), -1, 1)))


def brightness_slopes(photo):
    """Texture tools' slopes at strength 1: brightness (less a wide blur) as height, central
    differences."""
    height = photo / ndimage.gaussian_filter(photo, sigma=min(photo.shape) / 8, mode="wrap") - 1
    dx = (np.roll(height, -1, axis=1) - np.roll(height, 1, axis=1)) / 2
    dy = -(np.roll(height, -1, axis=0) - np.roll(height, 1, axis=0)) / 2
    return dx, dy


def brightness_as_height(photo, strength):
    """Texture-tool normals at ``strength``."""
    dx, dy = brightness_slopes(photo)
    normals = np.stack([-strength * dx, -strength * dy, np.ones_like(dx)], axis=-1)
    return normals / np.linalg.norm(normals, axis=-1, keepdims=True)


def matched_strength(photo, truth):
    """The strength whose slopes' RMS is the truth's."""
    dx, dy = brightness_slopes(photo)
    true_slopes = (truth[..., 0] ** 2 + truth[..., 1] ** 2) / truth[..., 2] ** 2
    return np.sqrt(np.mean(true_slopes) / np.mean(dx * dx + dy * dy))


def photo_of(normals, height, light, *, seed, hard):
    size = normals.shape[0]
    mask = np.ones((size, size), dtype=bool)
    image = synth.render(normals, mask, light=light, albedo=0.7, noise=0.01, seed=seed)
    y, x = np.mgrid[:size, :size] / (size - 1) - 0.5
    image = image * np.exp(0.4 * x - 0.3 * y - 0.5 * (x * x + y * y))
    if hard:
        image = image * (0.3 + 0.7 * texture.ambient_occlusion(height, mask, reach=size / 16))
        blotches = ndimage.gaussian_filter(
            np.random.default_rng(seed + 7).normal(size=(size, size)), 6, mode="wrap"
        )
        image = image * (1 + 0.2 * blotches / np.abs(blotches).max())
    return image


def run(seeds=(0, 1, 2)):
    rows, figure = [], None
    for hard in (False, True):
        for slant, tilt in LIGHTS:
            light = light_from_slant_tilt(slant, tilt)
            errors = {"given": [], "read": [], "brightness": [], "matched": [], "flat": []}
            seconds = []
            for seed in seeds:
                height, truth = synth.material_surface(256, seed=seed)
                photo = photo_of(truth, height, light, seed=seed, hard=hard)
                start = time.perf_counter()
                given = texture.material(photo, light=light)
                seconds.append(time.perf_counter() - start)
                read = texture.material(photo)
                errors["given"].append(angles(given.maps["normal_opengl"] * 2 - 1, truth).mean())
                errors["read"].append(angles(read.maps["normal_opengl"] * 2 - 1, truth).mean())
                errors["brightness"].append(
                    min(angles(brightness_as_height(photo, k), truth).mean() for k in STRENGTHS)
                )
                matched = brightness_as_height(photo, matched_strength(photo, truth))
                errors["matched"].append(angles(matched, truth).mean())
                errors["flat"].append(angles(np.array([0.0, 0.0, 1.0]), truth).mean())
                if figure is None and hard and (slant, tilt) == (45, 135):
                    figure = (photo, given.maps["normal_opengl"], (matched + 1) / 2, (truth + 1) / 2)
            rows.append(
                (hard, slant, tilt, {k: float(np.mean(v)) for k, v in errors.items()}, np.median(seconds))
            )
            print(rows[-1], flush=True)
    return rows, figure


def write(rows, figure, out: Path):
    lines = [
        "# Material mode against brightness as height",
        "",
        "`benchmarks/bench_material.py`: rendered rough surfaces (256x256, three seeds each), mean "
        "angular error of the normals (degrees), mean over the seeds. *brightness as height* is "
        "what texture tools do, its strength chosen with the ground truth (its best). The light's "
        "side, when read, is the one nearer above (tilt 102 degrees): the tilt 300 light comes "
        "from below-right, so its relief comes out inverted there.",
        "",
        "| photo | light slant / tilt | material, light given | material, light read | brightness as height, best | brightness as height, as steep as the truth | flat | material s |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for hard, slant, tilt, errors, seconds in rows:
        kind = "occlusion and albedo" if hard else "shading only"
        lines.append(
            f"| {kind} | {slant} / {tilt} | {errors['given']:.2f} | {errors['read']:.2f} | "
            f"{errors['brightness']:.2f} | {errors['matched']:.2f} | {errors['flat']:.2f} | {seconds:.2f} |"
        )
    lines += [
        "",
        "`material.png`: the photo (occlusion and albedo, light 45 / 135), then normal maps: "
        "material (light given), brightness as height (as steep as the truth), the truth.",
        "",
    ]
    with atomic_write(out, mode="w") as f:
        f.write("\n".join(lines))
    if figure is not None:
        from PIL import Image

        photo, *maps = figure
        tiles = [np.repeat((photo / photo.max())[..., None], 3, axis=2), *maps]
        strip = np.concatenate([np.clip(t, 0, 1) for t in tiles], axis=1)
        with atomic_write(out.with_suffix(".png")) as f:
            Image.fromarray((strip * 255).round().astype(np.uint8)).save(f, format="PNG")
    print("\n".join(lines))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "material.md")
    args = parser.parse_args()
    rows, figure = run()
    write(rows, figure, args.out)


if __name__ == "__main__":
    main()
