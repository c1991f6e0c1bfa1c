"""Benchmark: masked Poisson integration, fast (multigrid-preconditioned CG) vs reference.

On the full square it also times the DCT solve of the same problem (``fourier``, the speed limit
for rectangles; uniform weights only).

Prints one table row per case and method: object pixels, set-up time, first solve (what
``integrate_poisson`` pays after the set-up), next solve (each further right-hand side, as in the
iterative refinement), milliseconds per megapixel of object for set-up + first solve, CG
iterations, peak memory traced by ``tracemalloc`` (numpy arrays; SuperLU's own memory is not
traced) and the largest difference from the reference as a fraction of the depth range.

Times are medians over ``--runs`` runs (set-up and solves in a fresh integrator each run), after one
warm-up run that loads the compiled kernels. The exact reference (sparse LU) factorises the
whole system: about 20 s for the 1024^2 disk, so it runs ``--reference-runs`` times (1 by default)
at that size and can be left out with ``--no-reference``. ``--pyamg`` adds the library route for
comparison: ``scipy.sparse.linalg.cg`` preconditioned by pyamg's smoothed aggregation
(``pyamg-sa``) or Ruge-Stueben AMG (``pyamg-rs``), same tolerance.

Usage: ``python benchmarks/bench_poisson.py [--runs 5] [--sizes 256 512 1024] [--no-reference] [--pyamg]``
"""

from __future__ import annotations

import argparse
import functools
import os
import statistics
import time
import tracemalloc

import numba
import numpy as np

from shadeform.integration.fourier import integrate_fourier
from shadeform.integration.poisson import poisson_integrator, poisson_integrator_reference


def sphere_case(n: int, full: bool, weights: str):
    """Mask, normals and weights: a disk (radius 0.43 n) or the full square, sphere-like normals
    with a little deterministic noise (so the field is not exactly integrable)."""
    rows, cols = np.mgrid[0:n, 0:n].astype(float)
    c = n / 2 - 0.5
    r = np.hypot(rows - c, cols - c)
    mask = np.ones((n, n), bool) if full else r < 0.43 * n
    radius = 0.72 * n if full else 0.43 * n + 0.5  # the disk: n_z -> ~0.05 at its rim
    a, b = (cols - c) / radius, -(rows - c) / radius
    normals = np.stack([a, b, np.sqrt(np.clip(1 - a**2 - b**2, 0, 1))], axis=-1)
    normals += 0.02 * np.random.default_rng(n).normal(size=normals.shape)
    normals[..., 2] = np.abs(normals[..., 2])
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    w = None if weights == "uniform" else np.clip(normals[..., 2], 0, 1) ** 4
    return mask, normals, w


def pyamg_integrator(mask, *, weights=None, tol=1e-8, kind="sa"):
    """The library route: ``scipy.sparse.linalg.cg`` preconditioned by one V-cycle of pyamg's
    smoothed aggregation (``kind="sa"``) or classical Ruge-Stueben AMG (``"rs"``), same tolerance
    (``|b - A z| <= tol |b|``). The set-up time includes assembling the sparse matrix."""
    import pyamg
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from shadeform.integration._slopes import slopes
    from shadeform.integration.poisson import _steps, difference_system

    w = np.ones(mask.shape) if weights is None else weights
    pairs, D, wts = difference_system(mask, w)
    A = (D.T @ sp.diags(wts) @ D).tocsr()
    A = A + sp.identity(A.shape[0], format="csr") * (1e-9 * A.diagonal().mean())  # non-singular
    if kind == "sa":
        amg = pyamg.smoothed_aggregation_solver(A, symmetry="symmetric", max_coarse=500)
    else:
        amg = pyamg.ruge_stuben_solver(A, max_coarse=500)
    M = amg.aspreconditioner(cycle="V")

    def solve(normals):
        zx, zy = slopes(normals, mask)
        iterations = []
        z, _ = spla.cg(
            A, D.T @ (wts * _steps(zx, zy, pairs)), rtol=tol, M=M, maxiter=200, callback=iterations.append
        )
        solve.info = {"iterations": len(iterations)}
        depth = np.full(mask.shape, np.nan)
        depth[mask] = z
        return depth

    solve.info = {}
    return solve


def dct_integrator(mask, *, weights=None):
    """:func:`shadeform.integration.fourier.integrate_fourier`: no set-up, uniform weights."""
    if weights is not None:
        raise ValueError("the DCT solve has uniform weights only")

    def solve(normals):
        return integrate_fourier(normals, mask)

    solve.info = {}
    return solve


METHODS = {
    "dct": dct_integrator,
    "fast": poisson_integrator,
    "reference": poisson_integrator_reference,
    "pyamg-sa": pyamg_integrator,
    "pyamg-rs": functools.partial(pyamg_integrator, kind="rs"),
}


def measure(method: str, mask, normals, weights, runs: int):
    make = METHODS[method]
    setup, first, again = [], [], []
    depth = info = None
    for _ in range(runs):
        t0 = time.perf_counter()
        solve = make(mask, weights=weights)
        t1 = time.perf_counter()
        depth = solve(normals)
        t2 = time.perf_counter()
        solve(normals)
        t3 = time.perf_counter()
        setup.append(t1 - t0)
        first.append(t2 - t1)
        again.append(t3 - t2)
        info = getattr(solve, "info", {})
        del solve
    tracemalloc.start()
    solve = make(mask, weights=weights)
    solve(normals)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    del solve
    return {
        "setup": statistics.median(setup),
        "first": statistics.median(first),
        "again": statistics.median(again),
        "peak": peak,
        "runs": runs,
        "iterations": info.get("iterations", ""),
        "depth": depth,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument(
        "--reference-runs",
        type=int,
        default=1,
        help="runs of the exact reference on 1024^2 masks (5 below that)",
    )
    parser.add_argument("--sizes", type=int, nargs="+", default=[256, 512, 1024])
    parser.add_argument("--no-reference", action="store_true")
    parser.add_argument(
        "--pyamg", action="store_true", help="also time CG preconditioned by pyamg (SA and RS)"
    )
    args = parser.parse_args()

    cases = [(f"disk {n}^2", n, False) for n in args.sizes]
    if max(args.sizes) >= 1024:
        cases.append(("full 1024^2", 1024, True))
    # the reference first, so that the other rows can show their difference from it
    methods = (
        ([] if args.no_reference else ["reference"])
        + ["fast"]
        + (["pyamg-sa", "pyamg-rs"] if args.pyamg else [])
    )

    print(f"numba threads: {numba.get_num_threads()}, CPUs: {os.cpu_count()}, runs: {args.runs} (median)")
    header = (
        f"{'case':<13} {'weights':<8} {'method':<9} {'pixels':>9} {'runs':>4} {'setup ms':>9} "
        f"{'solve ms':>9} {'next ms':>8} {'ms/Mpx':>7} {'iters':>5} {'peak MiB':>9} {'err/range':>9}"
    )
    print(header)
    print("-" * len(header))
    warm = sphere_case(64, False, "uniform")
    for method in methods + ["dct"]:  # load the compiled kernels / first-use costs outside the timings
        METHODS[method](warm[0])(warm[1])
    for name, n, full in cases:
        for weights in ("uniform", "nz**4"):
            mask, normals, w = sphere_case(n, full, "uniform" if weights == "uniform" else "nz4")
            pixels = int(mask.sum())
            results = {}
            extra = ["dct"] if full and weights == "uniform" else []
            for method in methods + extra:
                runs = args.runs
                if method == "reference" and n >= 1024:
                    runs = args.reference_runs
                results[method] = r = measure(method, mask, normals, w, runs)
                err = ""
                if "reference" in results and method != "reference":
                    ref = results["reference"]["depth"]
                    diff = r["depth"][mask] - ref[mask]  # both up to an offset
                    err = f"{np.max(np.abs(diff - diff.mean())) / np.ptp(ref[mask]):.1e}"
                total = r["setup"] + r["first"]
                print(
                    f"{name:<13} {weights:<8} {method:<9} {pixels:>9} {r['runs']:>4} "
                    f"{r['setup'] * 1e3:>9.1f} {r['first'] * 1e3:>9.1f} {r['again'] * 1e3:>8.1f} "
                    f"{total * 1e3 / (pixels / 1e6):>7.0f} {r['iterations']!s:>5} "
                    f"{r['peak'] / 2**20:>9.1f} {err:>9}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
