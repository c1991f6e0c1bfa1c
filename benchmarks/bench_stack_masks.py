"""Masks of photo sets found from their photos: :func:`shadeform.masks.find_object_in_set` against
the old default (a brightness mask of each pixel's brightest reading, holes filled).

On every photo set of ``../shared/data/real`` with a true mask (DiLiGenT's seven objects, 96
photos each; MIT-Berkeley's twelve, 10 photos each), read as a user has them
(:func:`shadeform.photoset.load_photo_set`, the folder's mask not used): IoU with the true mask
before and after, and the time of each. Then the time of one set of 96 photos of 0.3 Mpx
(DiLiGenT's cat, each photo scaled up), and the effect on photometric stereo: the mean angular
error of the default model with the calibrated lights on a few DiLiGenT objects, scored on the
true mask's pixels, with the true mask, the old mask and the new one (pixels of the true mask
the found mask leaves out have no normal: they are counted apart, as "missed").

Writes ``benchmarks/results/stack-masks.md``.

Run: ``python benchmarks/bench_stack_masks.py [--stereo OBJ,OBJ] [--out PATH]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np
import scipy.io
from scipy import ndimage as ndi

from reports import publish
from shadeform.io.images import load_mask
from shadeform.masks import find_object_in_set
from shadeform.masks.graphcut import iou
from shadeform.photometric import photometric_stereo
from shadeform.photoset import load_photo_set
from shadeform.preprocess import object_mask

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "data" / "real"
DILIGENT = ("ball", "bear", "buddha", "cat", "cow", "pot1", "reading")
MIT = (
    "apple", "box", "cup1", "deer", "dinosaur", "frog1",
    "panther", "paper1", "pear", "phone", "raccoon", "sun",
)  # fmt: skip
STEREO = ("buddha", "cow", "pot1", "reading")


def old_mask(images: np.ndarray) -> np.ndarray:
    """The default before: the brightness mask of each pixel's brightest reading, holes filled."""
    brightest = images.max(axis=(0, 3)) if images.ndim == 4 else images.max(axis=0)
    return object_mask(brightest / brightest.max())


def timed(fn, *args):
    start = time.perf_counter()
    out = fn(*args)
    return out, time.perf_counter() - start


def mask_rows():
    """Per set: name, photos, pixels, IoU before, after, seconds before, after, confidence."""
    rows = []
    for group, names in (("diligent", DILIGENT), ("mit-berkeley", MIT)):
        for name in names:
            folder = REAL / group / name
            photos = load_photo_set([folder])
            truth = load_mask(folder / "mask.png", shape=photos.images.shape[1:3])
            before, seconds_before = timed(old_mask, photos.images)
            found, seconds_after = timed(find_object_in_set, photos.images)
            rows.append(
                (name, len(photos.paths), truth.size, iou(before, truth), iou(found.mask, truth),
                 seconds_before, seconds_after, found.confidence)
            )  # fmt: skip
            print(rows[-1], flush=True)
    return rows


def large_set_seconds() -> tuple[tuple[int, int], float]:
    """Seconds for DiLiGenT's cat, 96 photos scaled up to about 0.3 Mpx each."""
    photos = load_photo_set([REAL / "diligent" / "cat"]).images
    factor = np.sqrt(300_000 / (photos.shape[1] * photos.shape[2]))
    large = ndi.zoom(photos, (1, factor, factor, 1), order=1)
    _, seconds = timed(find_object_in_set, large)
    return large.shape[1:3], seconds


def stereo_rows(names):
    """Per object and mask: mean angular error (degrees) over the true mask's pixels that have a
    normal, and the share of the true mask without one."""
    rows = []
    for name in names:
        folder = REAL / "diligent" / name
        photos = load_photo_set([folder])
        truth = load_mask(folder / "mask.png", shape=photos.images.shape[1:3])
        normals_true = scipy.io.loadmat(folder / "Normal_gt.mat")["Normal_gt"]
        masks = {
            "true": truth,
            "old": old_mask(photos.images),
            "new": find_object_in_set(photos.images).mask,
        }
        for label, mask in masks.items():
            result = photometric_stereo(photos.images, photos.lights, mask, intensities=photos.intensities)
            solved = truth & np.isfinite(result.normals[..., 0])
            cosines = np.clip(np.sum(result.normals[solved] * normals_true[solved], axis=1), -1, 1)
            error = float(np.degrees(np.arccos(cosines)).mean())
            missed = 1.0 - solved.sum() / truth.sum()
            rows.append((name, label, error, missed))
            print(rows[-1], flush=True)
    return rows


def main(argv=None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stereo", default=",".join(STEREO), help="DiLiGenT objects for the stereo check")
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "stack-masks.md"))
    args = parser.parse_args(argv)
    rows = mask_rows()
    shape, seconds = large_set_seconds()
    stereo = stereo_rows([n for n in args.stereo.split(",") if n])
    lines = [
        "# Masks of photo sets from their photos",
        "",
        f"`python benchmarks/bench_stack_masks.py`; {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores, OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}.",
        "",
        "Before: the brightness mask of each pixel's brightest reading over the photos, holes filled "
        "(the default of `reconstruct_stereo` until now). After: `find_object_in_set` (each pixel's "
        "median over at most 32 photos, `find_object` on it, enclosed parts no brighter than the "
        "outline's threshold left open). The photos as the folders hold them; the true mask only scores.",
        "",
        "| set | object | photos | IoU before | IoU after | s before | s after | confidence |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, count, _, before, after, s_before, s_after, confidence in rows:
        group = "DiLiGenT" if name in DILIGENT else "MIT-Berkeley"
        lines.append(
            f"| {group} | {name} | {count} | {before:.3f} | {after:.3f} | {s_before:.2f} | {s_after:.2f} "
            f"| {confidence:.3f} |"
        )
    afters = [row[4] for row in rows]
    befores = [row[3] for row in rows]
    lines += [
        "",
        f"Lowest IoU: before {min(befores):.3f}, after {min(afters):.3f} (bar: 0.95 on every object); "
        f"mean before {np.mean(befores):.3f}, after {np.mean(afters):.3f}.",
        "",
        f"One set of 96 photos of {shape[1]}x{shape[0]} ({shape[0] * shape[1] / 1e6:.2f} Mpx; DiLiGenT's "
        f"cat scaled up): {seconds:.2f} s.",
        "",
        "## Photometric stereo with each mask",
        "",
        "Default model, calibrated lights and strengths; mean angular error in degrees over the true "
        "mask's pixels that have a normal; missed: the share of the true mask the mask leaves out.",
        "",
        "| object | mask | mean error ° | missed |",
        "|---|---|---:|---:|",
    ]
    lines += [f"| {name} | {label} | {error:.2f} | {missed:.1%} |" for name, label, error, missed in stereo]
    lines += [
        "",
        "Each row is scored on the pixels its mask solves: a mask that leaves out the hardest pixels "
        "(the dim rim, dark insides) scores lower without being better, hence the missed column.",
    ]
    return publish(lines, args.out)


if __name__ == "__main__":
    main()
