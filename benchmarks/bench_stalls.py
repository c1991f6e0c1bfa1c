"""Stalls: the worst of 20 runs against their median, for every solver and integrator, while
another process keeps one of the machine's cores busy.

Compiled parallel kernels (numba, OpenMP threading layer) hand each thread a share of the work;
when another program holds a core, a thread may wait for it. With OpenMP's default "active"
waiting, idle threads spin for a while before sleeping, competing for the busy core: on two
cores a DiLiGenT integration ran 2.5x slower under load, and an audit saw a 60x worst case.
``shadeform`` sets ``OMP_WAIT_POLICY=PASSIVE`` on import unless the user set it
(``shadeform/__init__.py``); this benchmark measures every solver and integrator both ways, each
in its own process (the policy is read once, when OpenMP starts).

Solvers: ``reconstruct`` of the synthetic vase (512x512; the light at the camera, or at slant 30
for the solvers that take any light). Integrators: ``integrate`` of the sphere's true normals
(1024x1024) and ``integrate_bilateral`` of DiLiGenT ``cat`` with its camera (the kernel the audit
timed). Writes ``benchmarks/results/stalls.md``.

Run: ``python benchmarks/bench_stalls.py [--runs 20]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: One case, timed in a fresh process: prints the run times as JSON.
CASE = r"""
import json, sys, time
import numpy as np
import shadeform
from shadeform import synth
from shadeform.light import light_from_slant_tilt
kind, name, runs = sys.argv[1], sys.argv[2], int(sys.argv[3])
if kind == "solver":
    light = (0, 0, 1) if name in ("eikonal", "auto") else light_from_slant_tilt(30, 60)
    scene = synth.scene("vase", size=512, light=light)
    work = lambda: shadeform.reconstruct(scene.image, light=light, solver=name)
elif name == "bilateral-diligent":
    sys.path.insert(0, sys.argv[4])
    from bench_diligent import load
    from shadeform.integration.bilateral import integrate_bilateral
    normals, mask, K, _ = load("cat")
    work = lambda: integrate_bilateral(normals, mask, K=K)
else:
    scene = synth.scene("sphere", size=1024)
    work = lambda: shadeform.integrate(scene.normals, scene.mask, integrator=name)
work(); work()  # compiled, warm
times = []
for _ in range(runs):
    start = time.perf_counter(); work(); times.append(time.perf_counter() - start)
print(json.dumps(times))
"""


def run_case(kind: str, name: str, runs: int, policy: str | None) -> list[float]:
    env = {key: value for key, value in os.environ.items() if key != "OMP_WAIT_POLICY"}
    if policy is not None:
        env["OMP_WAIT_POLICY"] = policy
    done = subprocess.run(
        [sys.executable, "-c", CASE, kind, name, str(runs), str(ROOT / "benchmarks")],
        capture_output=True, text=True, env=env, check=True,
    )  # fmt: skip
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "stalls.md")
    args = parser.parse_args()
    import numpy as np

    import shadeform
    from shadeform.integration import available_integrators
    from shadeform.io.atomic import atomic_write

    cases = [("solver", name) for name in shadeform.available_solvers() if name != "auto"]
    cases += [("integrator", name) for name in available_integrators()] + [
        ("integrator", "bilateral-diligent")
    ]
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])  # one core kept busy
    rows = []
    try:
        for kind, name in cases:
            row = [kind, name]
            for policy in ("PASSIVE", "ACTIVE"):
                times = np.array(run_case(kind, name, args.runs, policy))
                row += [float(np.median(times)), float(times.max())]
            rows.append(row)
            print(row, flush=True)
    finally:
        busy.kill()
    lines = [
        "# Stalls under load",
        "",
        f"`benchmarks/bench_stalls.py`: {args.runs} runs per case after two warm ones, each case in a fresh process, "
        f"while another process keeps one of the {os.cpu_count()} cores busy; {platform.machine()}, "
        f"Python {platform.python_version()}. Seconds; **worst / median** is the bar (at most 2).",
        "",
        "| kind | name | passive: median | worst | **worst / median** | active: median | worst | worst / median |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for kind, name, pm, pw, am, aw in rows:
        lines.append(
            f"| {kind} | {name} | {pm:.3f} | {pw:.3f} | **{pw / pm:.2f}** | {am:.3f} | {aw:.3f} | {aw / am:.2f} |"
        )
    worst = max(row[3] / row[2] for row in rows)
    lines += ["", f"Passive (the package's setting): the largest worst / median is {worst:.2f}.", ""]
    text = "\n".join(lines)
    print(text)
    with atomic_write(args.out, mode="w") as f:
        f.write(text)


if __name__ == "__main__":
    main()
