"""DiLiGenT noise-seed spread: how often the slope-cap rule, and BiNI solved more tightly, beat BiNI.

Issue 12 item 4 asks that the rule (:func:`shadeform.integration.bilateral.integrate_bilateral`,
``sharpness = 2``, its default geometric slope cap) be at or below BiNI in MADE on every DiLiGenT
case. ``benchmarks/bench_diligent.py`` finds it at or below the BiNI re-run in 24 of 30 cases. The
hypothesis tested here: the per-case differences are set by the offsets of whole parts across
interior occluding contours, which the normals do not determine, so whether one method is at or
below another on a given case is close to a coin flip, for BiNI against itself too.

For every object and noise seeds ``0 .. N-1`` (Gaussian noise on the normals, 2 degrees RMS,
:func:`bench_diligent.noisy`) it computes MADE (median-scale protocol, as ``bench_diligent.py``)
of (a) the rule exactly as ``bench_diligent.py`` calls it, (b) :func:`bench_diligent.bini_rerun`
with its defaults (Jacobi CG to 1e-3 per step, BiNI's settings) and (c) the same with
``cg_tol=1e-5`` (BiNI's own equations solved more accurately), and counts per object how often
a <= b and c <= b, with two-sided sign tests (:func:`scipy.stats.binomtest`, ties dropped). On the
objects as published (no noise) it compares the re-run at CG tolerances 1e-2, 1e-3 and 1e-5.
All loaders, perturbations and the re-run are imported from ``bench_diligent.py``.
Writes ``benchmarks/results/diligent-spread.md``.

Run: ``python benchmarks/bench_diligent_spread.py [--seeds N] [--objects bear,cat] [--out PATH]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import binomtest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_diligent import DATA, OBJECTS, ROOT, bini_rerun, load, noisy
from shadeform.integration.bilateral import integrate_bilateral
from shadeform.metrics import made

#: The methods of the seed study: label -> (description, function of (normals, mask, K) -> depth).
METHODS = {
    "a": ("rule", lambda n, m, K: integrate_bilateral(n, m, K=K, sharpness=2.0).depth),
    "b": ("BiNI re-run (CG 1e-3)", lambda n, m, K: bini_rerun(n, m, K)),
    "c": ("BiNI-tight (CG 1e-5)", lambda n, m, K: bini_rerun(n, m, K, cg_tol=1e-5)),
}
#: CG tolerances of the re-run on the objects as published (1e-3 is BiNI's own).
ORIGINAL_TOLS = (1e-2, 1e-3, 1e-5)


def _made(z, gt, mask) -> float:
    return float(made(z, gt, mask, fit="median_scale"))


def _sign_test(x: np.ndarray, y: np.ndarray) -> tuple[int, int, int, float]:
    """(x < y, x > y, ties, two-sided sign-test p-value over the untied pairs)."""
    below, above = int(np.sum(x < y)), int(np.sum(x > y))
    ties = x.size - below - above
    p = binomtest(below, below + above, 0.5).pvalue if below + above else float("nan")
    return below, above, ties, float(p)


def _progress(loads: list, line: str) -> None:
    """Print one case's ``line`` with the 1-minute load average now, and keep that load."""
    loads.append(os.getloadavg()[0])
    print(f"{line}  load {loads[-1]:.2f}", flush=True)


def run_seeds(objects, seeds, loads: list, on_round=None) -> dict:
    """MADE (median protocol) and time of every method on every (object, seed):
    ``{object: {label: (errors (S,), seconds (S,))}}``. Seed by seed over all objects, so that
    ``on_round(results, done_seeds)`` can write a complete report after each seed."""
    data = {name: load(name) for name in objects}
    errs = {o: {k: [] for k in METHODS} for o in objects}
    secs = {o: {k: [] for k in METHODS} for o in objects}
    out = {}
    for seed in seeds:
        for name in objects:
            normals, mask, K, gt = data[name]
            nn = noisy(normals, mask, seed=seed)
            for k, (_, fn) in METHODS.items():
                t = time.perf_counter()
                z = fn(nn, mask, K)
                secs[name][k].append(time.perf_counter() - t)
                errs[name][k].append(_made(z, gt, mask))
            _progress(
                loads,
                f"{name:8s} seed {seed}  "
                + "  ".join(f"{k} {errs[name][k][-1]:.3f} ({secs[name][k][-1]:.1f} s)" for k in METHODS),
            )
        out = {o: {k: (np.array(errs[o][k]), np.array(secs[o][k])) for k in METHODS} for o in objects}
        if on_round is not None:
            on_round(out, seeds[: seeds.index(seed) + 1])
    return out


def run_original(objects, loads: list) -> dict:
    """MADE of the rule and of the re-run at each of ``ORIGINAL_TOLS`` on the objects as
    published: ``{object: {"rule": e, tol: e, ...}}``."""
    out = {}
    for name in objects:
        normals, mask, K, gt = load(name)
        row = {"rule": _made(METHODS["a"][1](normals, mask, K), gt, mask)}
        for tol in ORIGINAL_TOLS:
            row[tol] = _made(bini_rerun(normals, mask, K, cg_tol=tol), gt, mask)
        _progress(
            loads,
            f"{name:8s} original  rule {row['rule']:.3f}  "
            + "  ".join(f"CG {t:g} {row[t]:.3f}" for t in ORIGINAL_TOLS),
        )
        out[name] = row
    return out


def _count(seed_res: dict, obj: str, x: str, y: str) -> int:
    """On how many seeds method ``x`` is at or below method ``y`` on ``obj``."""
    return int(np.sum(seed_res[obj][x][0] <= seed_res[obj][y][0]))


def _rng(e: np.ndarray) -> str:
    return f"{np.median(e):.3f} ({e.min():.3f}-{e.max():.3f})"


def report(seed_res: dict, orig: dict, seeds, loads: list, wall: float, reduced: bool) -> str:
    """The markdown of ``benchmarks/results/diligent-spread.md``."""
    objects = list(seed_res)
    ns = len(seeds)
    a = np.concatenate([seed_res[o]["a"][0] for o in objects])
    b = np.concatenate([seed_res[o]["b"][0] for o in objects])
    c = np.concatenate([seed_res[o]["c"][0] for o in objects])
    ab, cb, ac = _sign_test(a, b), _sign_test(c, b), _sign_test(a, c)
    a_le_b, c_le_b = int(np.sum(a <= b)), int(np.sum(c <= b))
    # per object: does the ordering of a and b stay the same across seeds?
    mixed_ab = [o for o in objects if 0 < _count(seed_res, o, "a", "b") < ns]
    orig_cb = [o for o in orig if orig[o][1e-5] <= orig[o][1e-3]]
    orig_2b = [o for o in orig if orig[o][1e-2] <= orig[o][1e-3]]
    orig_ab = [o for o in orig if orig[o]["rule"] <= orig[o][1e-3]]
    lopsided_cb = [o for o in objects if not 1 < _count(seed_res, o, "c", "b") < ns - 1]
    lop_dirs = {_count(seed_res, o, "c", "b") > ns / 2 for o in lopsided_cb}
    n_all = a.size
    lines = [
        "# DiLiGenT: spread of MADE over noise seeds (rule vs BiNI re-run vs BiNI-tight)",
        "",
        f"What was run: {len(objects)} DiLiGenT objects ({', '.join(objects)}) with ground-truth normals perturbed by 2 degrees RMS "
        f"of Gaussian noise, seeds 0-{seeds[-1]} ({n_all} cases"
        + (", fewer than the 10 planned" if reduced else "")
        + "), each integrated by (a) the rule (`integrate_bilateral`, k = 2, its geometric slope cap, "
        "exactly as `bench_diligent.py` calls it), (b) the BiNI re-run of `bench_diligent.py` (Jacobi CG "
        "to 1e-3 per step, BiNI's settings) and (c) BiNI-tight, the same re-run with CG to 1e-5 (BiNI's "
        "own equations solved more accurately); MADE in mm under the median-scale protocol. "
        f"What it shows: the rule is at or below the re-run in {a_le_b} of {n_all} seed cases "
        f"(two-sided sign test p = {ab[3]:.2g})"
        + (", so against the re-run it is not a coin flip" if ab[3] < 0.05 else "")
        + "; per object "
        + ", ".join(f"{o} {_count(seed_res, o, 'a', 'b')}/{ns}" for o in objects)
        + f"; the seed changes the ordering on {len(mixed_ab)} of {len(objects)} objects "
        f"({', '.join(mixed_ab) or 'none'}). "
        f"BiNI-tight, the same method as the re-run with a tighter solver, is at or below the re-run "
        f"in {c_le_b} of {n_all} seed cases (p = {cb[3]:.2g}) and on {len(orig_cb)} of {len(orig)} objects "
        "as published"
        + (
            ", so BiNI's own equations, solved more accurately, do not meet the bar 'at or below BiNI on "
            "every case' either. "
            if c_le_b < n_all or len(orig_cb) < len(orig)
            else ". "
        )
        + "Per object it is "
        + ", ".join(f"{o} {_count(seed_res, o, 'c', 'b')}/{ns}" for o in objects)
        + f": on {len(lopsided_cb)} of {len(objects)} objects the same way on all but at most one seed"
        + (
            " (below on some, above on others), so the pooled near-even split is a mix of objects, not a "
            "per-case coin flip. "
            if cb[3] >= 0.05 and 2 * len(lopsided_cb) > len(objects) and len(lop_dirs) == 2
            else ". "
        )
        + f"As published (no noise), the rule is at or below the re-run on {len(orig_ab)} of {len(orig)} "
        f"objects, BiNI-tight on {len(orig_cb)}, the re-run with CG 1e-2 on {len(orig_2b)}. "
        + "This measures how often the orderings flip; it does not by itself show where in the surface "
        "the differences sit (that is the diagnosis in `diligent.md`, issue 12 follow-up (1)-(3)).",
        "",
        f"Noise: `bench_diligent.noisy(normals, mask, seed=s)` (2 degrees RMS in the tangent plane). "
        f"Wall time of the whole run {wall / 60:.1f} min on {os.cpu_count()} CPUs shared with other work "
        f"({platform.processor() or platform.machine()}); 1-minute load average sampled after each case: "
        f"{min(loads):.2f}-{max(loads):.2f} (median {np.median(loads):.2f}).",
        "",
        "## Per object over the noise seeds (MADE in mm, median (min-max) over the seeds)",
        "",
        "| object | (a) rule | (b) BiNI re-run | (c) BiNI-tight | a <= b | c <= b | a <= c "
        "| median ratio a / b (min-max) | sign test a vs b, p (this object) | mean time a / b / c (s) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for o in objects:
        ea, eb, ec = (seed_res[o][k][0] for k in "abc")
        ta, tb, tc = (seed_res[o][k][1].mean() for k in "abc")
        r = ea / eb
        lines.append(
            f"| {o} | {_rng(ea)} | {_rng(eb)} | {_rng(ec)} | {int(np.sum(ea <= eb))}/{ns} "
            f"| {int(np.sum(ec <= eb))}/{ns} | {int(np.sum(ea <= ec))}/{ns} "
            f"| {np.median(r):.3f} ({r.min():.3f}-{r.max():.3f}) | {_sign_test(ea, eb)[3]:.3g} "
            f"| {ta:.2f} / {tb:.1f} / {tc:.1f} |"
        )
    lines += [
        "",
        f"**All {n_all} seed cases** (sign tests two-sided, `scipy.stats.binomtest`, ties dropped): "
        f"a vs b: a below in {ab[0]}, above in {ab[1]}, ties {ab[2]}, p = {ab[3]:.3g}; "
        f"c vs b: c below in {cb[0]}, above in {cb[1]}, ties {cb[2]}, p = {cb[3]:.3g}; "
        f"a vs c: a below in {ac[0]}, above in {ac[1]}, ties {ac[2]}, p = {ac[3]:.3g}. "
        f"The pooled test mixes objects whose ordering is fixed with objects where it flips; the per-object "
        f"columns say which is which.",
        "",
        "## The objects as published (no noise): BiNI re-run at three CG tolerances (MADE in mm, median)",
        "",
        "| object | rule | re-run CG 1e-2 | re-run CG 1e-3 (BiNI) | re-run CG 1e-5 (tight) "
        "| tight <= BiNI | 1e-2 <= BiNI | rule <= BiNI |",
        "|---|---:|---:|---:|---:|:---:|:---:|:---:|",
    ]
    for o, row in orig.items():
        lines.append(
            f"| {o} | {row['rule']:.3f} | {row[1e-2]:.3f} | {row[1e-3]:.3f} | {row[1e-5]:.3f} "
            f"| {'yes' if row[1e-5] <= row[1e-3] else 'no'} | {'yes' if row[1e-2] <= row[1e-3] else 'no'} "
            f"| {'yes' if row['rule'] <= row[1e-3] else 'no'} |"
        )
    lines += [
        "",
        f"Tight at or below BiNI on {len(orig_cb)} of {len(orig)} objects as published, CG 1e-2 on "
        f"{len(orig_2b)} of {len(orig)}.",
        "",
        "## Every seed case (MADE in mm, median protocol)",
        "",
        "| object | seed | (a) rule | (b) BiNI re-run | (c) BiNI-tight |",
        "|---|---:|---:|---:|---:|",
    ]
    for o in objects:
        for i, s in enumerate(seeds):
            lines.append(f"| {o} | {s} | " + " | ".join(f"{seed_res[o][k][0][i]:.3f}" for k in "abc") + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10, help="noise seeds 0 .. N-1 (default 10)")
    parser.add_argument("--objects", default=",".join(OBJECTS), help="comma-separated objects")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "diligent-spread.md")
    args = parser.parse_args(argv)
    if not DATA.is_dir():
        raise SystemExit(f"DiLiGenT data not found at {DATA}")
    objects = [o for o in args.objects.split(",") if o]
    unknown = sorted(set(objects) - set(OBJECTS))
    if unknown:
        raise SystemExit(f"unknown objects {', '.join(unknown)}; choose from {', '.join(OBJECTS)}")
    seeds = list(range(args.seeds))
    # compile the numba kernels once, outside the timings
    n, m, K, _ = load("cow")
    integrate_bilateral(n, m, K=K)
    loads: list = []
    t0 = time.perf_counter()
    orig = run_original(objects, loads)

    def write(seed_res, done):
        # after every seed: a stopped run leaves a complete report of the seeds done
        text = report(seed_res, orig, done, loads, time.perf_counter() - t0, reduced=len(done) < 10)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.out.with_suffix(".md.tmp")
        tmp.write_text(text)
        tmp.replace(args.out)
        return text

    seed_res = run_seeds(objects, seeds, loads, on_round=write)
    text = write(seed_res, seeds)
    print(text)
    return text


if __name__ == "__main__":
    main()
