"""Benchmark: the object mask on real objects over ordinary backgrounds, and on the lab photos.

Every real object of ``../shared/data/real`` (7 DiLiGenT, 12 MIT-Berkeley) is pasted with its true
mask on generated backgrounds (``composites.py``: a grey table, white paper, wood grain, woven
cloth, and granite held out: no rule or constant was chosen looking at it), saved as an 8-bit
sRGB PNG (even seeds) or JPEG of quality 90 (odd seeds) and read back as a user's photo. Each
case is scored by the IoU with the true mask of:

- ``auto``: the automatic mask the command line and the app take when no mask is given: the
  photo's colours to :func:`shadeform.masks.find_object`;
- ``grey``: the same for a grey photo (the colour picture's luma);
- ``click``: the mask grown from one click on the object's interior point
  (:func:`shadeform.masks.segment_from_seeds` on the colours, the app's "Click object");
- ``box``: the mask inside a box drawn round the object (the true mask's bounding box padded by
  5 %; :func:`shadeform.masks.segment_from_box` on the colours).

The mask's confidence (``FoundObject.confidence``, where it exists) is recorded per case; its
warning threshold is chosen on the training families only and reported on the held-out one. The
lab photos as they are (DiLiGenT's frontal photo on black, MIT-Berkeley's ``light01.png`` and
``original.png``) are scored too, in colour and grey: the automatic mask must not get worse there.

Usage: ``python benchmarks/bench_masks.py [--seeds 2] [--objects apple,cat] [--families marble,carpet]
[--methods auto,grey,click,box] [--no-lab] [--out benchmarks/results/masks.md]``
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

import composites
from shadeform import masks
from shadeform.io.atomic import atomic_write
from shadeform.io.images import load_mask, load_pixels, select_channel
from shadeform.preprocess import object_mask

BAR = 0.9


def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b) / union) if union else 1.0


METHODS = ("auto", "grey", "click", "box")


def score(rgb: np.ndarray, truth: np.ndarray, methods=METHODS) -> dict:
    row: dict = dict.fromkeys(METHODS)
    start = time.perf_counter()
    found = masks.find_object(rgb)
    row["auto_s"] = time.perf_counter() - start
    row["auto"] = iou(found.mask, truth)
    row["confidence"] = found.confidence
    if "grey" in methods:
        row["grey"] = iou(masks.find_object(select_channel(rgb, "luma").astype(np.float64)).mask, truth)
    if "click" in methods:
        try:
            row["click"] = iou(masks.segment_from_seeds(rgb, [composites.interior_point(truth)]), truth)
        except Exception as err:  # a refusal (the click looks like the background) scores 0
            row["click"], row["click_error"] = 0.0, str(err)
    if "box" in methods:
        row["box"] = iou(masks.segment_from_box(rgb, composites.padded_box(truth)), truth)
    return row


def composite_rows(objects, seeds: int, families=composites.FAMILIES, methods=METHODS) -> list[dict]:
    rows = []
    for name in objects:
        obj = composites.cutout(name)
        for index, family in enumerate(composites.FAMILIES):
            if family not in families:
                continue
            for seed in range(seeds):
                case_seed = 1000 * index + 10 * seed + objects.index(name) * 100_000
                picture, truth = composites.composite(obj, family, case_seed)
                kind = "png" if seed % 2 == 0 else "jpeg"
                rgb = composites.as_file(picture, kind)
                row = {
                    "object": name,
                    "family": family,
                    "seed": seed,
                    "file": kind,
                    **score(rgb, truth, methods),
                }
                rows.append(row)
                print(json.dumps(row), flush=True)
    return rows


def lab_rows(objects) -> list[dict]:
    rows = []
    for name in objects:
        if name in composites.DILIGENT:
            folder = composites.DATA / "diligent" / name
            lights = np.loadtxt(folder / "light_directions.txt")
            photos = [f"{int(np.argmax(lights[:, 2])) + 1:03d}.png"]
        else:
            folder = composites.DATA / "mit-berkeley" / name
            photos = ["light01.png", "original.png"]
        truth = load_mask(folder / "mask.png")
        for photo in photos:
            pixels = load_pixels(folder / photo, linear=True)
            luma = select_channel(pixels, "luma").astype(np.float64)
            colour = pixels[..., :3] if pixels.shape[2] >= 3 else luma
            row = {
                "object": name,
                "photo": photo,
                "auto": iou(masks.find_object(colour).mask, truth),
                "grey": iou(object_mask(luma), truth),
            }
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def _two(value) -> str:
    return "—" if value is None else f"{value:.2f}"


def summary(values) -> str:
    values = np.asarray([v for v in values if v is not None], dtype=float)
    if not values.size:
        return "n/a | n/a"
    return f"{np.median(values):.3f} | {np.mean(values >= BAR) * 100:.0f} %"


def calibrate(rows) -> tuple[float | None, str]:
    """The warning threshold on the confidence chosen on the training families: the one that best
    separates masks below the bar from the rest (balanced accuracy), and how it does."""
    training = [r for r in rows if r["family"] in composites.TRAINING and r["confidence"] is not None]
    if not training:
        return None, "no confidence measured"
    conf = np.array([r["confidence"] for r in training])
    bad = np.array([r["auto"] < BAR for r in training])
    best, threshold = -1.0, None
    for candidate in np.unique(conf):
        flagged = conf < candidate
        caught = flagged[bad].mean() if bad.any() else 1.0
        spared = (~flagged[~bad]).mean() if (~bad).any() else 1.0
        if (caught + spared) / 2 > best:
            best, threshold = (caught + spared) / 2, float(candidate)
    return threshold, f"balanced accuracy {best:.2f} on the training families"


def warning_lines(rows, threshold) -> list[str]:
    lines = [
        "| cases | masks below the bar | of them warned | masks at or above the bar | of them warned |",
        "|---|---:|---:|---:|---:|",
    ]
    for label, families in (("training", composites.TRAINING), ("held out", composites.HELD_OUT)):
        subset = [r for r in rows if r["family"] in families and r["confidence"] is not None]
        bad = [r for r in subset if r["auto"] < BAR]
        good = [r for r in subset if r["auto"] >= BAR]
        lines.append(
            f"| {label} | {len(bad)} | {sum(r['confidence'] < threshold for r in bad)} | {len(good)} | "
            f"{sum(r['confidence'] < threshold for r in good)} |"
        )
    return lines


def report(rows, lab, seconds: float, seeds: int) -> str:
    shown = [f for f in composites.FAMILIES if any(r["family"] == f for r in rows)]
    lines = [
        "# Object masks on real objects over generated backgrounds",
        "",
        f"`python benchmarks/bench_masks.py{' ' if sys.argv[1:] else ''}{' '.join(sys.argv[1:])}` "
        f"({platform.machine()}, Python {platform.python_version()}, {seconds:.0f} s). "
        f"{len({r['object'] for r in rows})} real objects, {seeds} draw(s) per background "
        "(even draws PNG, odd JPEG q90, 8-bit sRGB). IoU with the true mask; bar 0.9.",
        "",
        "## Summary",
        "",
        "| backgrounds | cases | auto median | auto >= 0.9 | grey photo median | grey >= 0.9 "
        "| click median | click >= 0.9 | box median | box >= 0.9 |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    groups = [
        ("training (table, paper, wood, cloth)", composites.TRAINING),
        ("held out (" + ", ".join(composites.HELD_OUT) + ")", composites.HELD_OUT),
    ]
    groups += [(family, (family,)) for family in composites.FAMILIES]
    groups.append(("all", composites.FAMILIES))
    for label, families in groups:
        subset = [r for r in rows if r["family"] in families]
        if not subset:
            continue
        lines.append(
            f"| {label} | {len(subset)} | "
            + " | ".join(summary(r[m] for r in subset) for m in ("auto", "grey", "click", "box"))
            + " |"
        )
    auto_s = [r["auto_s"] for r in rows]
    lines += [
        "",
        f"Automatic mask time: median {np.median(auto_s):.2f} s, max {np.max(auto_s):.2f} s per photo.",
        "",
    ]
    threshold, how = calibrate(rows)
    if threshold is not None:
        lines += [
            "## The low-confidence warning",
            "",
            f"Threshold {threshold:.3f} chosen on the training families ({how}).",
            "",
            *warning_lines(rows, threshold),
            "",
        ]
    if lab:
        lines += [
            "## Lab photos as they are (automatic mask)",
            "",
            "| object | photo | colour | grey |",
            "|---|---|---:|---:|",
        ]
        lines += [f"| {r['object']} | {r['photo']} | {r['auto']:.3f} | {r['grey']:.3f} |" for r in lab]
    lines += ["", "## Per object and background (auto / grey / click / box; confidence)", ""]
    lines += [
        "| object | " + " | ".join(shown) + " |",
        "|---|" + "---|" * len(shown),
    ]
    for name in dict.fromkeys(r["object"] for r in rows):
        cells = []
        for family in shown:
            parts = []
            for r in (r for r in rows if r["object"] == name and r["family"] == family):
                conf = "" if r["confidence"] is None else f"; {r['confidence']:.2f}"
                parts.append(" / ".join(_two(r[m]) for m in METHODS) + conf)
            cells.append("<br>".join(parts))
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--objects", default=",".join(composites.DILIGENT + composites.MIT))
    parser.add_argument("--families", default=",".join(composites.FAMILIES), help="backgrounds to paste on")
    parser.add_argument("--methods", default=",".join(METHODS), help="auto is always measured")
    parser.add_argument(
        "--lab", action=argparse.BooleanOptionalAction, default=True, help="the lab photos too"
    )
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "masks.md")
    args = parser.parse_args()
    if not composites.available():
        raise SystemExit(f"no real photographs at {composites.DATA}")
    objects = args.objects.split(",")
    start = time.perf_counter()
    rows = composite_rows(objects, args.seeds, args.families.split(","), args.methods.split(","))
    lab = lab_rows(objects) if args.lab else []
    text = report(rows, lab, time.perf_counter() - start, args.seeds)
    with atomic_write(args.out, mode="w") as handle:
        handle.write(text)
    print(text)


if __name__ == "__main__":
    main()
