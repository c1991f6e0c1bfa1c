"""Single-photo shape from shading on real photographs with measured ground truth.

For every object of ``../shared/data/real`` (``real_data.py``: the most frontal photo of each
DiLiGenT and MIT-Berkeley object) reports the mean angular error of the normals (degrees) of

- the constant normal (0, 0, 1) and the silhouette-only shape
  (:func:`shadeform.solvers.photo.silhouette_depth`), which use no shading;
- every registered solver and ``method="auto"``, with the calibrated (DiLiGenT) or fitted (MIT)
  light, and with ``light="estimate"``;
- the estimated light's error (degrees) and its confidence;

then the medians per set and, per column, how many objects end worse than the constant normal.
The solvers that need the light at the camera are run only where it is (none of these photos).
Writes ``benchmarks/results/real.md``.

``--slant 30`` measures each object's photo lit nearest 30 degrees off the camera instead (a
second photo of every object, for a check on photos the solvers' constants were not set on),
into ``benchmarks/results/real-slant30.md``.

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


def run_case(case, methods):
    """One row: ``{column: value}``."""
    row = {}
    constant = np.zeros(case.image.shape + (3,))
    constant[..., 2] = 1.0
    row["constant"] = real_data.angular_error(constant, case)
    row["silhouette"] = real_data.angular_error(
        real_data.normals_of_height(silhouette_depth(case.mask)), case
    )
    for light_name, light in (("known", case.light), ("estimate", "estimate")):
        for method in methods:
            solver = None if method == "auto" else get_solver(method)
            key = f"{method} ({light_name})"
            if solver is not None and not solver.takes(None if light_name == "estimate" else light):
                row[key] = None
                continue
            start = time.perf_counter()
            rec = shadeform.reconstruct(case.image, mask=case.mask, light=light, method=method)
            row[key] = real_data.angular_error(rec.normals, case)
            row[key + " s"] = time.perf_counter() - start
            if method == "auto":
                row[f"auto ({light_name}) picks"] = rec.info["method"]
            if light_name == "estimate" and "light error" not in row:
                row["light error"] = real_data.light_error(rec.light, case)
                row["confidence"] = rec.info["light_estimate"].get("confidence", float("nan"))
    return row


def _write_rows(path, rows):
    """The rows file: one JSON object per measured object (written whole, then moved in place)."""
    text = "".join(
        json.dumps({"object": name, "set": kind, **row}) + "\n" for (name, kind), row in rows.items()
    )
    part = path.with_suffix(".part")
    part.write_text(text)
    part.replace(path)


def table(rows, columns, sets, *, compare=False):
    """Markdown: one line per object, then the medians and the count worse than the constant."""
    lines = ["| set | object | " + " | ".join(columns) + " |", "|---|---|" + "---:|" * len(columns)]
    for (name, set_name), row in rows.items():
        cells = [_cell(row.get(c)) for c in columns]
        lines.append(f"| {set_name} | {name} | " + " | ".join(cells) + " |")
    for set_name in sets:
        these = [row for (_, s), row in rows.items() if s == set_name]
        medians = []
        worse = []
        for c in columns:
            values = [r[c] for r in these if isinstance(r.get(c), float)]
            medians.append(_cell(float(np.median(values)) if values else None))
            if c in ("constant", "light error", "confidence") or not values:
                worse.append("")
            else:
                count = sum(1 for r in these if isinstance(r.get(c), float) and r[c] > r["constant"])
                worse.append(str(count))
        lines.append(f"| **{set_name}** | **median** | " + " | ".join(medians) + " |")
        if compare:
            lines.append(f"| {set_name} | worse than constant | " + " | ".join(worse) + " |")
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
        "--methods",
        help="comma-separated methods to measure again on every object, the other columns kept from "
        "the rows file (default: measure every method)",
    )
    parser.add_argument("--note", default="", help="a paragraph under the header: how this run was made")
    parser.add_argument(
        "--slant",
        type=float,
        default=0.0,
        help="each object's photo lit nearest this many degrees off the camera (default 0: the most "
        "frontal); other than 0 the default --out is results/real-slant<N>.md",
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
    again = args.methods.split(",") if args.methods else None
    if (args.resume or again) and rows_file.exists():
        for line in rows_file.read_text().splitlines():
            item = json.loads(line)
            done[(item.pop("object"), item.pop("set"))] = item
    cases = real_data.cases(slant=args.slant)
    for case in cases:
        if wanted and case.name not in wanted:
            continue
        key = (case.name, case.set)
        if key in done and not again:
            rows[key] = done[key]
            continue
        row = run_case(case, methods) if not again else {**done.get(key, {}), **run_case(case, again)}
        rows[key] = done[key] = row
        _write_rows(rows_file, done)
        print(
            case.set,
            case.name,
            " ".join(f"{k}={_cell(v)}" for k, v in row.items() if not k.endswith(" s")),
            flush=True,
        )
    angle_columns = ["constant", "silhouette"] + [
        f"{m} ({light})" for light in ("known", "estimate") for m in methods
    ]
    angle_columns = [c for c in angle_columns if any(r.get(c) is not None for r in rows.values())]
    light_columns = ["light error", "confidence", "auto (known) picks", "auto (estimate) picks"]
    time_columns = [c + " s" for c in angle_columns if any((c + " s") in r for r in rows.values())]
    sets = [s for s in ("diligent", "mit") if any(k[1] == s for k in rows)]
    where = f"{args.slant:g} degrees off the camera" if args.slant else "the camera"
    text = "\n\n".join(
        [
            "# Real photographs: single-photo shape from shading against measured normals",
            f"`python benchmarks/bench_real.py{f' --slant {args.slant:g}' if args.slant else ''}` on "
            f"{platform.node() or 'this machine'} "
            f"({os.cpu_count()} cores, Python {platform.python_version()}), {time.strftime('%Y-%m-%d')}. "
            "Mean angular error of the normals (degrees) over the pixels with ground truth; one photo "
            f"per object, the one lit nearest {where} (DiLiGenT: 8-bit linear crop divided by its "
            "light's strength, albedo, highlights and shadows kept; MIT-Berkeley: luma over the "
            "reflectance's luma). Lights: DiLiGenT calibrated, MIT fitted to the ground truth.",
            *([args.note] if args.note else []),
            "## Normals (degrees)",
            table(rows, angle_columns, sets, compare=True),
            "## Estimated light",
            table(rows, light_columns, sets),
            "## Time per solve (s)",
            table(rows, time_columns, sets),
        ]
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
