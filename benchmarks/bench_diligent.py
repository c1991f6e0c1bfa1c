"""DiLiGenT normal-integration benchmark: bilateral vs uniform least squares (perspective).

For each object of ``../shared/data/diligent-normals`` (ground-truth normals, 3x3 ``K``,
ground-truth depth in mm) integrates the normals with
:func:`shadeform.integration.bilateral.integrate_bilateral` (``k = 2``) and with the uniform
least-squares solution of the same log-depth equations (``iterations=0``), and reports MADE (mm,
after fitting the unknown scale, :func:`shadeform.metrics.made`) and the median wall time of
several runs. Writes ``benchmarks/results/diligent.md``.

Run: ``python benchmarks/bench_diligent.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

from shadeform.integration.bilateral import MIN_SCALE, integrate_bilateral
from shadeform.io.images import load_mask
from shadeform.io.maps import load_normal_map
from shadeform.metrics import made

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "diligent-normals"
OBJECTS = ("bear", "buddha", "cat", "cow", "pot1", "reading")
#: Published BiNI (k = 2) MADE in mm (shared/data/README.md).
BINI = {"bear": 0.334, "buddha": 1.098, "cat": 0.074, "cow": 0.058, "pot1": 0.635,
        "reading": 0.257}
#: Published uniform least-squares MADE in mm (same source).
PLAIN = {"bear": 1.20, "buddha": 3.72, "cat": 1.61, "cow": 0.89, "pot1": 1.51, "reading": 6.62}


def load(name: str, data: Path = DATA):
    """(normals (H, W, 3), mask (H, W), K (3, 3), depth_gt (H, W)) of one object."""
    folder = data / name
    mask = load_mask(folder / "mask.png")
    normals = load_normal_map(folder / "normal_map.png", mask=mask)
    K = np.loadtxt(folder / "K.txt")
    depth = np.load(folder / "depth_gt.npz")["depth_gt"].astype(np.float64)
    return normals, mask, K, depth


def timed(fn, repeats: int):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return out, float(np.median(times))


def main(argv=None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--no-sweep", action="store_true",
                        help="skip the min_scale sensitivity table")
    parser.add_argument("--out", type=Path,
                        default=ROOT / "benchmarks" / "results" / "diligent.md")
    args = parser.parse_args(argv)
    if not DATA.is_dir():
        raise SystemExit(f"DiLiGenT data not found at {DATA}")
    # compile the numba kernels once
    n, m, K, _ = load("cow")
    integrate_bilateral(n, m, K=K)
    rows = []
    for name in OBJECTS:
        normals, mask, K, gt = load(name)
        (z, info), t_bi = timed(lambda: integrate_bilateral(normals, mask, K=K, k=2.0,
                                                            return_info=True), args.repeats)
        z_ls, t_ls = timed(lambda: integrate_bilateral(normals, mask, K=K, iterations=0),
                           args.repeats)
        e_bi = made(z, gt, mask)
        e_ls = made(z_ls, gt, mask)
        rows.append((name, int(mask.sum()), e_bi, BINI[name], e_ls, PLAIN[name], t_bi, t_ls,
                     info["iterations"], info["cg_iterations"]))
        print(f"{name:8s} bilateral {e_bi:.3f} mm (BiNI {BINI[name]:.3f}) {t_bi:.2f} s "
              f"[{info['iterations']} steps, {info['cg_iterations']} CG]  "
              f"uniform LS {e_ls:.3f} mm (published {PLAIN[name]:.2f}) {t_ls:.2f} s", flush=True)
    lines = [
        "# DiLiGenT normal integration (perspective, ground-truth normals)",
        "",
        "MADE in mm after fitting the unknown scale (`shadeform.metrics.made`); time is the median",
        f"of {args.repeats} runs (wall clock, {os.cpu_count()} CPUs, {platform.processor() or platform.machine()};",
        "the machine may be shared, so timings are noisy). Bilateral: "
        "`integrate_bilateral(normals, mask, K=K, k=2)`;",
        "uniform LS: the same log-depth equations with `iterations=0`. Bar: bilateral MADE <= BiNI's "
        "published number and < 1 s.",
        "",
        "| object | pixels | bilateral MADE | BiNI (published) | meets MADE bar | uniform LS MADE "
        "| plain LS (published) | bilateral time (s) | uniform LS time (s) | IRLS steps | CG iterations |",
        "|---|---:|---:|---:|:---:|---:|---:|---:|---:|---:|---:|",
    ]
    for (name, npx, e_bi, ref, e_ls, plain, t_bi, t_ls, steps, cg) in rows:
        ok = "yes" if e_bi <= ref else "no"
        lines.append(f"| {name} | {npx} | {e_bi:.3f} | {ref:.3f} | {ok} | {e_ls:.3f} | {plain:.2f} "
                     f"| {t_bi:.2f} | {t_ls:.3f} | {steps} | {cg} |")
    if not args.no_sweep:
        scales = (0.01, 0.05, 0.1, 0.12, 0.15)
        lines += ["", "## Sensitivity to `min_scale` (bilateral MADE in mm; default "
                  f"{MIN_SCALE})", "",
                  "| object | BiNI | " + " | ".join(f"{v:g}" for v in scales) + " |",
                  "|---|---:|" + "---:|" * len(scales)]
        for name in OBJECTS:
            normals, mask, K, gt = load(name)
            errs = [made(integrate_bilateral(normals, mask, K=K, min_scale=v), gt, mask)
                    for v in scales]
            lines.append(f"| {name} | {BINI[name]:.3f} | " + " | ".join(f"{e:.3f}" for e in errs)
                         + " |")
    text = "\n".join(lines) + "\n"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(".md.tmp")
    tmp.write_text(text)
    tmp.replace(args.out)
    print(text)
    return text


if __name__ == "__main__":
    main()
