"""Scale: time and memory of one photo's whole path (load, reconstruct, mesh, export) against
its size, and how fast the package starts.

Each size runs ``shadeform reconstruct PHOTO -o model.glb --step 2`` on a synthetic vase saved as
a 16-bit PNG (the user's path, in a fresh process each run, so that peak resident memory is the
command's own), ``--repeats`` times: median and worst wall time, ms per megapixel, peak resident
memory and bytes per pixel. Also: ``import numpy`` and ``import shadeform`` in fresh processes
(median of 7), the first run's time (the compiled kernels loaded from numba's cache), and a fresh
install simulated: an empty ``NUMBA_CACHE_DIR``, the set-up step (``shadeform warm``, which
``make venv`` runs) and then the first run at the smallest size. Writes
``benchmarks/results/scale.md`` and a log-log plot ``docs/scale.png``.

Run: ``python benchmarks/bench_scale.py [--sizes 1024,2048,4096] [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
COMMAND = [sys.executable, "-c", "from shadeform.cli import main; main()"]


def timed_run(args: list[str], env: dict | None = None) -> tuple[float, float]:
    """Wall seconds and peak resident MiB of a fresh process (``os.wait4``: that child's own)."""
    start = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        child = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=err, env=env)
        _, status, usage = os.wait4(child.pid, 0)
        seconds = time.perf_counter() - start
        child.returncode = os.waitstatus_to_exitcode(status)
        if child.returncode != 0:
            err.seek(0)
            raise RuntimeError(err.read().decode(errors="replace")[-2000:])
    return seconds, usage.ru_maxrss / 1024


def fresh_install(folder: Path, side: int) -> tuple[float, float]:
    """A fresh install simulated: seconds of the set-up step (``shadeform warm``) on an empty numba
    cache, then of the first ``reconstruct`` at ``side`` pixels on the cache it filled."""
    from shadeform import synth
    from shadeform.io.maps import save_gray

    photo = folder / f"fresh{side}.png"
    save_gray(synth.scene("vase", size=side).image, photo, bitdepth=16)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(folder / "numba-cache")}
    setup, _ = timed_run([*COMMAND, "warm"], env=env)
    run = [*COMMAND, "reconstruct", str(photo), "-o", str(folder / "fresh.glb"), "--step", "2"]
    first, _ = timed_run(run, env=env)
    return setup, first


def import_seconds(module: str, repeats: int = 7) -> float:
    times = []
    for _ in range(repeats):
        out = subprocess.run(
            [sys.executable, "-X", "importtime", "-c", f"import {module}"], capture_output=True, text=True
        ).stderr
        last = [line for line in out.splitlines() if re.search(rf"\|\s+{re.escape(module)}$", line)]
        times.append(int(last[-1].split("|")[1]) / 1e6)
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="1024,2048,4096", help="sides of the square photos")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "scale.md")
    parser.add_argument("--plot", type=Path, default=ROOT / "docs" / "scale.png")
    parser.add_argument(
        "--no-fresh", action="store_true", help="skip the fresh-install run (set-up compiles, about a minute)"
    )
    args = parser.parse_args()
    from shadeform import synth
    from shadeform.io.atomic import atomic_write
    from shadeform.io.maps import save_gray

    numpy_s, shadeform_s = import_seconds("numpy"), import_seconds("shadeform")
    rows = []
    fresh = None
    with tempfile.TemporaryDirectory() as folder:
        for side in sorted(int(s) for s in args.sizes.split(",")):
            photo = Path(folder) / f"vase{side}.png"
            save_gray(synth.scene("vase", size=side).image, photo, bitdepth=16)
            run = [*COMMAND, "reconstruct", str(photo), "-o", str(Path(folder) / "model.glb"), "--step", "2"]
            first, _ = timed_run(run)
            results = [timed_run(run) for _ in range(args.repeats)]
            seconds = [r[0] for r in results]
            peak = max(r[1] for r in results)
            pixels = side * side
            rows.append((side, pixels, first, float(np.median(seconds)), max(seconds), peak))
            print(rows[-1], flush=True)
        if not args.no_fresh:
            fresh = fresh_install(Path(folder), min(int(s) for s in args.sizes.split(",")))
            print(f"fresh install: set-up {fresh[0]:.1f} s, first run {fresh[1]:.2f} s", flush=True)

    lines = [
        "# Scale",
        "",
        f"`benchmarks/bench_scale.py`: `shadeform reconstruct PHOTO -o model.glb --step 2` on a synthetic vase "
        f"(16-bit PNG), a fresh process per run, {args.repeats} runs per size after a first one; "
        f"{platform.machine()}, {os.cpu_count()} CPUs (shared with other work), Python {platform.python_version()}.",
        "",
        f"`import numpy` {numpy_s * 1000:.0f} ms, `import shadeform` {shadeform_s * 1000:.1f} ms "
        f"({shadeform_s / numpy_s:.2f}x numpy's; medians of 7 fresh processes).",
        "",
        *(
            [
                f"Fresh install (an empty numba cache, `NUMBA_CACHE_DIR`): the set-up step `shadeform warm` "
                f"(run by `make venv`) compiles for {fresh[0]:.1f} s, then the first run at the smallest size "
                f"takes {fresh[1]:.2f} s.",
                "",
            ]
            if fresh
            else []
        ),
        "| photo | Mpx | first run s | median s | worst s | worst / median | ms / Mpx | peak MiB | bytes / pixel |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for side, pixels, first, median, worst, peak in rows:
        mpx = pixels / 1e6
        lines.append(
            f"| {side} x {side} | {mpx:.1f} | {first:.2f} | {median:.2f} | {worst:.2f} | {worst / median:.2f} | "
            f"{median * 1000 / mpx:,.0f} | {peak:,.0f} | {peak * 2**20 / pixels:,.0f} |"
        )
    lines += ["", "Peak memory is the whole process's (Python, numpy and the kernels included).", ""]
    text = "\n".join(lines)
    print(text)
    with atomic_write(args.out, mode="w") as f:
        f.write(text)
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    mpx = np.array([r[1] for r in rows]) / 1e6
    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.5))
    left.loglog(mpx, [r[3] for r in rows], "o-")
    left.set(xlabel="megapixels", ylabel="seconds (median)", title="time")
    right.loglog(mpx, [r[5] for r in rows], "o-")
    right.set(xlabel="megapixels", ylabel="peak MiB", title="memory")
    for axis in (left, right):
        axis.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    with atomic_write(args.plot) as f:
        fig.savefig(f, format="png", dpi=100)


if __name__ == "__main__":
    main()
