"""Single-photo shape from shading on real photographs with measured ground truth.

For every object of ``../shared/data/real`` (``real_data.py``) one photo as a user has it:

- DiLiGenT: the photo lit nearest the camera, divided by its light's strength (albedo, highlights
  and shadows kept), with its calibrated light;
- MIT-Berkeley: ``original.png`` (the object's own albedo, print and gloss), its luma scaled by
  its 99.9th percentile in the mask (``real_data.mit_photo``), with the light of
  ``shading_light.txt`` (fitted to the ground truth);

and reports, for

- the constant normal (0, 0, 1) and the silhouette-only shape
  (:func:`shadeform.solvers.photo.silhouette_depth`), which use no shading;
- every registered solver and ``solver="auto"``, with the known light and with
  ``light="estimate"`` (the blind run);
- on MIT-Berkeley, ``auto`` with the estimated light on the older benchmark's cleaned image (the
  photo lit nearest the camera divided by the reflectance: the shading, which no user has), the
  column ``auto (estimate) on shading``;

SIRFS's scores (Barron & Malik, TPAMI 2015): per object the mean angle of the normals (N-MAE,
radians; the tables give it in degrees) and the mean absolute height error after the median offset
(Z-MAE, pixels; MIT only: the DiLiGenT crops have no aligned depth); per set the median degrees,
the geometric mean N-MAE, the mean Z-MAE and how many objects end worse than the constant normal.
Also the estimated light's error (degrees) and its confidence. The solvers that need the light at
the camera are run only where it is (none of these photos). Writes ``benchmarks/results/real.md``
and the rows beside it (``real.jsonl``).

``--slant 30`` measures each object's photo lit nearest 30 degrees off the camera instead (MIT:
that light photo as taken, scaled the same way, and its cleaned version), into
``benchmarks/results/real-slant30.md``.

Run: ``python benchmarks/bench_real.py [--objects cat,apple] [--slant 30]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import real_data
import shadeform
from shadeform.solvers import get_solver, solver_names
from shadeform.solvers.photo import silhouette_depth

RESULTS = Path(__file__).resolve().parent / "results" / "real.md"
#: The column measured on the reflectance-divided MIT image (the older benchmark's input).
SHADING = "auto (estimate) on shading"


def cases(slant, wanted=None):
    """The objects' photos, DiLiGenT first, each loaded when it is to be measured.

    Parameters
    ----------
    slant : float
        Degrees off the camera of the photo's light; 0: DiLiGenT's most frontal photo and MIT's
        ``original.png``.
    wanted : set of str, optional
        Object names (default: all).

    Yields
    ------
    (real_data.Case, real_data.Case or None)
        The photo as taken (``real_data.diligent``, ``real_data.mit_photo``) and, for MIT, the
        reflectance-divided photo (``real_data.mit``); DiLiGenT has no cleaned version.
    """
    for name in real_data.DILIGENT:
        if not wanted or name in wanted:
            yield real_data.diligent(name, slant=slant), None
    for name in real_data.MIT:
        if not wanted or name in wanted:
            # slant 0 is SIRFS's protocol: original.png under its one lab light
            yield real_data.mit_photo(name, slant=slant or None), real_data.mit(name, slant=slant)


def score(row, key, case, normals, depth):
    """Score one result into ``row``.

    Parameters
    ----------
    row : dict
        Receives ``row[key]``, the mean angle (degrees, ``real_data.angular_error``), and
        ``row[key + " Z"]``, the Z-MAE (pixels; None where the case has no true height).
    key : str
        The column.
    case : real_data.Case
    normals : (H, W, 3) ndarray
    depth : (H, W) ndarray
        Height in pixels.
    """
    row[key] = real_data.angular_error(normals, case)
    row[key + " Z"] = None if case.depth is None else real_data.z_mae(depth, case.depth, case.valid)


def run_case(case, methods, shading=None):
    """Measure one object.

    Parameters
    ----------
    case : real_data.Case
        The photo as taken.
    methods : list of str
        ``"auto"`` and solver names, each run with the known and the estimated light.
    shading : real_data.Case, optional
        The cleaned photo: with ``"auto"`` in ``methods`` it adds the column :data:`SHADING`.

    Returns
    -------
    dict
        ``{column: degrees, column + " Z": Z-MAE, column + " s": seconds}``, the picks of auto,
        and the estimated light's error and confidence.
    """
    row = {}
    constant = np.zeros(case.image.shape + (3,))
    constant[..., 2] = 1.0
    score(row, "constant", case, constant, np.zeros(case.image.shape))
    depth = silhouette_depth(case.mask)
    score(row, "silhouette", case, real_data.normals_of_height(depth), depth)
    for light_name, light in (("known", case.light), ("estimate", "estimate")):
        for method in methods:
            solver = None if method == "auto" else get_solver(method)
            key = f"{method} ({light_name})"
            if solver is not None and not solver.takes(None if light_name == "estimate" else light):
                row[key] = None
                continue
            start = time.perf_counter()
            rec = shadeform.reconstruct(case.image, mask=case.mask, light=light, solver=method)
            row[key + " s"] = time.perf_counter() - start
            score(row, key, case, rec.normals, rec.depth)
            if method == "auto":
                row[f"auto ({light_name}) picks"] = rec.info["solver"]
            if light_name == "estimate" and "light error" not in row:
                row["light error"] = real_data.light_error(rec.light, case)
                row["confidence"] = rec.info["light_estimate"].get("confidence", float("nan"))
    if shading is not None and "auto" in methods:
        start = time.perf_counter()
        rec = shadeform.reconstruct(shading.image, mask=shading.mask, light="estimate", solver="auto")
        row[SHADING + " s"] = time.perf_counter() - start
        score(row, SHADING, shading, rec.normals, rec.depth)
    return row


def _write_rows(path, rows):
    """The rows file: one JSON object per measured object (written whole, then moved in place)."""
    text = "".join(
        json.dumps({"object": name, "set": kind, **row}) + "\n" for (name, kind), row in rows.items()
    )
    part = path.with_suffix(".part")
    part.write_text(text)
    part.replace(path)


def _values(rows, key):
    """``key``'s measured values over ``rows`` (None, absent and text left out)."""
    return [r[key] for r in rows if isinstance(r.get(key), float)]


def summary(rows, columns, sets):
    """Markdown: per set and column, the median degrees, the geometric mean N-MAE (radians), the
    mean Z-MAE and the count of objects worse than the constant normal.

    Parameters
    ----------
    rows : dict
        ``{(object, set): row}`` as made by :func:`run_case`.
    columns, sets : list of str
    """
    lines = [
        "| set | column | objects | median ° | N-MAE rad (geometric mean) | Z-MAE px (mean) "
        "| worse than constant |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for set_name in sets:
        these = [row for (_, s), row in rows.items() if s == set_name]
        for c in columns:
            degrees = _values(these, c)
            if not degrees:
                continue
            depths = _values(these, c + " Z")
            worse = sum(1 for r in these if isinstance(r.get(c), float) and r[c] > r["constant"])
            cells = [
                str(len(degrees)),
                _cell(float(np.median(degrees))),
                f"{real_data.geometric_mean(np.radians(degrees)):.3f}",
                _cell(float(np.mean(depths)) if depths else None),
                "" if c == "constant" else str(worse),
            ]
            lines.append(f"| {set_name} | {c} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def table(rows, columns, sets, *, suffix="", average=("median", np.median)):
    """Markdown: one line per object, then one per set.

    Parameters
    ----------
    rows : dict
        ``{(object, set): row}`` as made by :func:`run_case`.
    columns : list of str
        The header; the cells are ``row[column + suffix]``.
    sets : list of str
        The sets to average.
    suffix : str
        ``""`` (degrees), ``" Z"`` (Z-MAE), ``" s"`` (seconds).
    average : (str, callable)
        The label and function of the per-set line.
    """
    lines = ["| set | object | " + " | ".join(columns) + " |", "|---|---|" + "---:|" * len(columns)]
    for (name, set_name), row in rows.items():
        cells = [_cell(row.get(c + suffix)) for c in columns]
        lines.append(f"| {set_name} | {name} | " + " | ".join(cells) + " |")
    label, reduce = average
    for set_name in sets:
        these = [row for (_, s), row in rows.items() if s == set_name]
        cells = []
        for c in columns:
            values = _values(these, c + suffix)
            cells.append(_cell(float(reduce(values)) if values else None))
        lines.append(f"| **{set_name}** | **{label}** | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _cell(value):
    if value is None:
        return "—"
    if isinstance(value, str):
        return value
    return f"{value:.1f}"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", help="comma-separated object names (default: all)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument(
        "--resume",
        action="store_true",
        help="keep the objects already measured in the rows file beside --out (.jsonl, one JSON row per object)",
    )
    parser.add_argument(
        "--solvers",
        help="comma-separated methods to measure again on every object, the other columns kept from "
        f"the rows file (default: measure every method; auto includes '{SHADING}')",
    )
    parser.add_argument("--note", default="", help="a paragraph under the header: how this run was made")
    parser.add_argument(
        "--slant",
        type=float,
        default=0.0,
        help="each object's photo lit nearest this many degrees off the camera (default 0: DiLiGenT's "
        "most frontal, MIT's original.png); other than 0 the default --out is results/real-slant<N>.md",
    )
    args = parser.parse_args(argv)
    if args.slant and args.out == RESULTS:
        args.out = RESULTS.with_name(f"real-slant{args.slant:g}.md")
    if not real_data.available():
        print(f"no real data at {real_data.DATA}: nothing to measure")
        return 1
    wanted = set(args.objects.split(",")) if args.objects else None
    methods = ["auto", *solver_names()]
    rows = {}
    done = {}
    rows_file = args.out.with_suffix(".jsonl")
    again = args.solvers.split(",") if args.solvers else None
    if (args.resume or again) and rows_file.exists():
        for line in rows_file.read_text().splitlines():
            item = json.loads(line)
            done[(item.pop("object"), item.pop("set"))] = item
    started = time.perf_counter()
    measured = 0
    for case, shading in cases(args.slant, wanted):
        key = (case.name, case.set)
        if key in done and not again:
            rows[key] = done[key]
            continue
        if again:
            row = {**done.get(key, {}), **run_case(case, again, shading)}
        else:
            row = run_case(case, methods, shading)
        rows[key] = done[key] = row
        measured += 1
        _write_rows(rows_file, done)
        print(
            case.set,
            case.name,
            " ".join(f"{k}={_cell(v)}" for k, v in row.items() if not k.endswith(" s")),
            flush=True,
        )
    elapsed = time.perf_counter() - started
    angle_columns = ["constant", "silhouette"] + [
        f"{m} ({light})" for light in ("known", "estimate") for m in methods
    ]
    angle_columns = [c for c in [*angle_columns, SHADING] if any(r.get(c) is not None for r in rows.values())]
    light_columns = ["light error", "confidence", "auto (known) picks", "auto (estimate) picks"]
    time_columns = [c for c in angle_columns if any((c + " s") in r for r in rows.values())]
    sets = [s for s in ("diligent", "mit") if any(k[1] == s for k in rows)]
    mit_rows = {key: row for key, row in rows.items() if key[1] == "mit"}  # the heights known
    if args.slant:
        photos = (
            f"the photo lit nearest {args.slant:g} degrees off the camera (MIT-Berkeley: that light "
            "photo's luma, albedo kept, scaled by its 99.9th percentile inside the mask, with its "
            "fitted light)"
        )
    else:
        photos = (
            "DiLiGenT's photo lit nearest the camera; MIT-Berkeley's `original.png` (SIRFS's protocol: "
            "the object's albedo, print and gloss under the lab light), its luma scaled by its 99.9th "
            "percentile inside the mask, with the light of `shading_light.txt`"
        )
    text = "\n\n".join(
        [
            "# Real photographs: single-photo shape from shading against measured shapes",
            f"`python benchmarks/bench_real.py{f' --slant {args.slant:g}' if args.slant else ''}` on "
            f"{platform.node() or 'this machine'} "
            f"({os.cpu_count()} cores, Python {platform.python_version()}), {time.strftime('%Y-%m-%d')}, "
            f"{elapsed / 60:.0f} min for the {measured} objects measured in this run. One photo per object as "
            f"a user has it: {photos}. DiLiGenT's are 8-bit linear crops divided by their light's "
            "strength, albedo, highlights and shadows kept. Lights: DiLiGenT calibrated, MIT fitted "
            f"to the ground truth. `{SHADING}`: `auto` with the estimated light on the older "
            "benchmark's cleaned MIT input (the photo lit nearest the camera, luma over the "
            "reflectance's luma), which no user has.",
            "Scores of SIRFS's benchmark (Barron & Malik, TPAMI 2015): per object the mean angle "
            "between the normals and the truth's (DiLiGenT's `Normal_gt`, MIT's from `Z.mat`) over "
            "the mask pixels where both are finite, in degrees in the tables and as N-MAE in radians; "
            "Z-MAE, the mean absolute height error in pixels after the median offset, MIT only (the "
            "DiLiGenT crops have no depth: `diligent-normals/` holds full-frame perspective depth in "
            "mm, not aligned with them). Per set: the median degrees, the geometric mean N-MAE, the "
            "mean Z-MAE and how many objects end worse than the constant normal.",
            *([args.note] if args.note else []),
            "## Summary",
            summary(rows, angle_columns, sets),
            "## Normals per object (degrees)",
            table(rows, angle_columns, sets),
            "## Heights per object: Z-MAE (pixels)",
            table(
                mit_rows, angle_columns, ["mit"] if mit_rows else [], suffix=" Z", average=("mean", np.mean)
            ),
            "## Estimated light",
            table(rows, light_columns, sets),
            "## Time per solve (s)",
            table(rows, time_columns, sets, suffix=" s"),
        ]
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text + "\n")
    print(f"wrote {args.out} ({elapsed:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
