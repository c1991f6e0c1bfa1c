"""Fuzzing the command line: every argument set ends in a result (exit 0) or a one-line refusal
(exit 2), never a traceback, a hang, a raw warning or a file left behind.

Run with ``python benchmarks/fuzz_cli.py --cases 10000`` (under ``nice``; about 20 minutes on
two cores). Each case is one command of ``shadeform`` (reconstruct, stereo, fuse, relief, maps,
lights, batch, synth, demo, formats, methods; not ``app``, which serves until stopped, ``warm``,
which takes no arguments, nor ``evaluate``, which runs every solver for over 30 s) with a seeded random draw of its options, read from the
command itself: each option given or not, with a value from a pool for its kind (numbers: ordinary,
0, negative, huge, tiny, NaN, infinite, 400 digits, not a number; paths: the tiny photos made here,
a photo set, a mask, regions and views files, and missing files, folders, a FIFO, /dev/null, an
empty file, text named .png, a damaged EXIF, a decompression-bomb header, a unicode name; outputs
in the case's folder under every suffix, a missing folder, the folder itself; strings: the good
ones and odd ones), sometimes an unknown option, a repeated one or a missing required one. The
photos are 12 to 24 pixels a side, so each case is fast.

The cases run in this process (typer's ``CliRunner``), each in a fresh folder that is also the
working directory, with ``--case-seconds`` as a hang guard (SIGALRM). A case counts as:

- a *traceback*: an exception escaped the command, or "Traceback" on its output;
- a *hang*: still running at the guard;
- a *bad refusal*: exit code 2 with other than exactly one stderr line ``error: ...``;
- a *bad exit*: an exit code other than 0 or 2;
- a *raw warning*: a line of a Python warning (``...Warning:``) on stderr;
- an *internal warning*: a Python warning the command line's edge caught and hid (a bug to fix
  where it arises; logged to the ``shadeform`` logger);
- *leftovers*: a temporary (``.NAME.shadeform-*``) or a tiles folder (``*.tiles``) anywhere in
  the case's folder, or any file written there by a refused command (``batch`` excepted, whose
  other photos' models stand).

Prints a table and writes it (atomically) to ``benchmarks/results/fuzz_cli.md``. The same case
number with the same ``--seed`` is the same argument list: ``--case N`` reruns one case and prints
its output.
"""

from __future__ import annotations

import os

if __name__ == "__main__":  # one thread each when run, before numpy loads; never when a test imports it
    for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ.setdefault(_name, "1")

import argparse
import contextlib
import logging
import random
import re
import shutil
import signal
import sys
import tempfile
import time
import traceback
from collections import Counter
from pathlib import Path

import numpy as np

from hostile_files import jpeg_with_damaged_exif, png_claiming

RESULTS = Path(__file__).resolve().parent / "results" / "fuzz_cli.md"

#: Commands left out: ``app`` serves until stopped; ``warm`` takes no arguments; ``evaluate``
#: runs every solver on the synthetic scenes (over 30 s even at 16 pixels a side).
LEFT_OUT = ("app", "warm", "evaluate")

#: What each check counts, in the table's order.
FINDINGS = (
    "traceback",
    "hang",
    "bad refusal",
    "bad exit",
    "raw warning",
    "internal warning",
    "leftovers",
)

#: The chance that an option given gets a hostile value rather than a good one: low enough that
#: a case often reaches the work (one hostile value refuses it), high enough for every pair.
HOSTILE = 0.15

# (good, hostile) values by kind
NUMBERS = (["1", "2", "0.5", "30", "10", "45"],
           ["0", "-1", "1e308", "-1e308", "1e-320", "nan", "inf", "-inf", "1e309", "9" * 400, "abc", "",
            "1,2", "٣", "0x10"])  # fmt: skip
WHOLE = (["1", "2", "3"], ["0", "-1", "100", "1000000000", "9" * 30, "9" * 400, "1.5", "abc", "", "nan"])
ODD = ["", " ", "x", "é", "∞", "a" * 3000, "../../x", "-", "%s%n", "{}", "🙂", "\udcff"]

#: Good and hostile values of the string options, by option name.
STRINGS = {
    "light": (["0,0,1", "0.3,0.2,1", "estimate", "1e308,1e308,1e308", "1e-320,0,1e-320"],
              ["nan,0,1", "0,0,0", "0,0,-1", "1,2", "a,b,c"]),
    "filter": (["gaussian:1", "median:1", "mean:2", "minimum:1", "none"],
               ["median:1e20", "gaussian:nan", "bogus:3", "gaussian", "gaussian:-1"]),
    "method": (["auto", "eikonal", "photo", "oblique", "propagation", "learned", "guided", "woodham",
                "bivariate", "uncalibrated"], ["bogus"]),
    "integrator": (["poisson", "fourier", "paths", "eikonal", "bilateral"], ["bogus"]),
    "channel": (["auto", "luma", "r", "g", "b", "max"], ["bogus"]),
    "tiles": (["auto", "off", "8"], ["0", "-3", "abc", "1e9"]),
    "scheduler": (["synchronous", "threads"], ["evil"]),
    "angles": (["0,180", "0,90", "0,180,90"], ["0,1e309", "a,b", "0", "0,nan"]),
    "only": (["normal,height", "occlusion", "curvature"], ["height,glossiness", ""]),
    "format": ([".glb", "obj", ".ply", ".stl", ".wrl", ".3mf"], [".xyz", ""]),
    "outline": (["mask", "frame"], ["bogus"]),
    "example": (["synth:sphere", "synth:vase"], ["synth:bogus", "bogus"]),
    "scene": (["sphere", "vase", "bumps"], ["bogus"]),
    "axis": (["x", "y"], ["z", "bogus"]),
    "surface": (["poisson", "volume"], ["bogus"]),
    "depth_format": (["npy", "tiff"], ["bogus"]),
    "scenes": (["sphere", "vase"], ["bogus"]),
    "reference": (["6,6", "6,6,0,0,1", "8,8"], ["1000000000,2", "a", "6,6,nan,0,1", "-1,-1"]),
}  # fmt: skip


def _pick(rng: random.Random, pool) -> str:
    good, hostile = pool
    return rng.choice(hostile if rng.random() < HOSTILE else good)


#: Integer options, and the float ones (by option name).
INTEGERS = {
    "step",
    "refine",
    "max_pixels",
    "workers",
    "size",
    "seed",
    "resolution",
    "max_triangles",
    "settle",
}
FLOATS = {"slant", "tilt", "width", "height", "base", "compress", "border", "min_wall", "noise", "reach"}
#: Path options the command writes (a file, or a folder for ``--out``).
OUTPUTS = {"output", "depth", "normals", "intensities", "albedo", "confidence", "out"}
#: The good values of some integer options are small, so that the cases stay fast.
SMALL = {"size": ["12", "16", "24"], "max_triangles": ["100", "1000"], "resolution": ["16", "24"]}


def make_inputs(folder: Path) -> dict[str, list[str]]:
    """The input files the cases draw from, made in ``folder``: good ones and hostile ones."""
    from PIL import Image

    from shadeform import synth
    from shadeform.io.maps import save_gray

    folder.mkdir(parents=True, exist_ok=True)
    sphere = synth.scene("sphere", size=16)
    save_gray(sphere.image, folder / "photo.png")
    save_gray(synth.scene("vase", size=20).image, folder / "vase.png", bitdepth=16)
    save_gray(sphere.mask.astype(np.float64), folder / "mask.png")
    Image.fromarray((sphere.image * 255).astype(np.uint8)).save(folder / "photo.jpg")
    (folder / "ünï cödé.png").write_bytes((folder / "photo.png").read_bytes())
    # a photo set: four lights, their directions and strengths
    lights = np.array([[0.3, 0.2, 1], [-0.3, 0.2, 1], [0.2, -0.3, 1], [0, 0, 1]], dtype=np.float64)
    lights /= np.linalg.norm(lights, axis=1, keepdims=True)
    stack = folder / "set"
    stack.mkdir(exist_ok=True)
    normals = sphere.normals
    for k, light in enumerate(lights):
        shading = np.clip(np.nan_to_num(normals @ light), 0, 1) * sphere.mask
        save_gray(shading, stack / f"{k:03d}.png", bitdepth=16)
    np.savetxt(stack / "light_directions.txt", lights)
    np.savetxt(stack / "light_intensities.txt", np.ones((4, 3)))
    (folder / "lights.txt").write_text("\n".join(" ".join(map(str, row)) for row in lights) + "\n")
    (folder / "lights_huge.txt").write_text("1e308 1e308 1e308\n" * 4)
    (folder / "lights_bad.txt").write_text("1 2\nx y z\n")
    (folder / "lights.lp").write_text(
        "4\n" + "".join(f"{k:03d}.png {r[0]} {r[1]} {r[2]}\n" for k, r in enumerate(lights))
    )
    # regions and views
    (folder / "regions.json").write_text(
        '{"regions": [{"polygon": [[2, 2], [10, 2], [10, 10]], "axis": "x"}]}'
    )
    (folder / "regions_big.json").write_text(
        '{"regions": [{"polygon": [[' + "9" * 5000 + ', 0], [9, 0], [9, 9]], "axis": "x"}]}'
    )
    (folder / "regions_nan.json").write_text(
        '{"regions": [{"polygon": [[NaN, 0], [9, 0], [9, 9]], "axis": "x"}]}'
    )
    (folder / "nested.json").write_text("[" * 100_000 + "]" * 100_000)
    (folder / "views.json").write_text(
        '{"views": [{"photo": "photo.png", "angle": 0}, {"photo": "photo.png", "angle": 180}]}'
    )
    # hostile files
    (folder / "empty.png").write_bytes(b"")
    (folder / "notes.png").write_text("these are notes, not a photo")
    (folder / "bomb.png").write_bytes(png_claiming(100_000, 100_000, colour=False))
    (folder / "exif.jpg").write_bytes(jpeg_with_damaged_exif())
    fifo = folder / "fifo.png"
    if not fifo.exists():
        os.mkfifo(fifo)
    photos = [str(folder / name) for name in ("photo.png", "vase.png", "photo.jpg", "ünï cödé.png")]
    hostile = [str(folder / name) for name in ("empty.png", "notes.png", "bomb.png", "exif.jpg", "fifo.png")]
    hostile += [str(folder / "missing.png"), str(folder), "/dev/null", "/dev/zero"]
    named = {
        "concave": (["regions.json"], ["regions_big.json", "regions_nan.json", "nested.json", "fifo.png", "missing.json", "."]),
        "views": (["views.json"], ["nested.json", "fifo.png", "missing.json", "."]),
        "lights": (["lights.txt", "lights.lp"], ["lights_huge.txt", "lights_bad.txt", "fifo.png", "missing.txt", "photo.png"]),
        "sphere": (["photo.png"], ["mask.png", "fifo.png", "empty.png"]),
    }  # fmt: skip
    pools = {
        name: ([str(folder / n) for n in good], [str(folder / n) for n in bad])
        for name, (good, bad) in named.items()
    }
    return {
        "photo": (photos, hostile),
        "set": ([str(stack)], [str(stack / "000.png"), str(stack / "light_directions.txt")]),
        "mask": ([str(folder / "mask.png")], [str(folder / "photo.png"), *hostile]),
        **pools,
    }


def command_options() -> dict[str, list[tuple[str, str, bool, bool, bool]]]:
    """Each command's parameters as (name, flag or "" for an argument, is a flag, takes many,
    required), read from the command line itself."""
    from typer.main import get_command

    from shadeform.cli import app

    group = get_command(app)
    found = {}
    for name, command in group.commands.items():
        if name in LEFT_OUT:
            continue
        params = []
        for param in command.params:
            is_option = param.param_type_name == "option"
            flag = param.opts[-1] if is_option else ""
            if param.name == "output" and "-o" in param.opts:
                flag = "-o" if len(name) % 2 else "--output"
            params.append((param.name, flag, bool(getattr(param, "is_flag", False)),
                           param.nargs == -1 or param.multiple, bool(param.required)))  # fmt: skip
        found[name] = params
    return found


def _value(rng: random.Random, command: str, name: str, inputs: dict, case: Path) -> str:
    """One value for option ``name`` of ``command``."""
    if name in OUTPUTS:
        if name == "out":
            return _pick(rng, ([str(case / "results")], [str(case / "no" / "such"), str(case / "file.txt"),
                                                          str(case / "ünï")]))  # fmt: skip
        suffixes = {"depth": [".tif", ".npy", ".tiff"], "normals": [".png"], "intensities": [".txt"],
                    "albedo": [".png"], "confidence": [".png"]}  # fmt: skip
        good = suffixes.get(name, [".glb", ".obj", ".ply", ".stl", ".wrl", ".3mf"])
        suffix = _pick(rng, (good, [".png", ".xyz", "", ".jpg"]))
        return _pick(rng, ([str(case / f"{name}{suffix}"), str(case / f"ünï cödé{suffix}")],
                           [str(case / "no" / f"x{suffix}"), str(case), str(case / f".hidden{suffix}")]))  # fmt: skip
    if name in ("image", "photos"):
        return _pick(rng, inputs["photo"])
    if name == "sources":
        return _pick(rng, (inputs["set"][0] + inputs["photo"][0], inputs["set"][1] + inputs["photo"][1]))
    if name in ("mask", "concave", "views", "lights", "sphere"):
        return _pick(rng, inputs[name])
    if name in STRINGS:
        return _pick(rng, (STRINGS[name][0], STRINGS[name][1] + ODD))
    if name in INTEGERS:
        return _pick(rng, (SMALL.get(name, WHOLE[0]), WHOLE[1]))
    if name in FLOATS:
        return _pick(rng, NUMBERS)
    return rng.choice(ODD)


def draw_case(seed: int, number: int, commands: dict, inputs: dict, case: Path) -> list[str]:
    """The argument list of case ``number`` (the same for the same seed, number and inputs)."""
    rng = random.Random(f"{seed}:{number}")
    command = rng.choice(sorted(commands))
    args = [command]
    for name, flag, is_flag, many, required in commands[command]:
        given = required and rng.random() > 0.03 or rng.random() < 0.25
        if name == "size" and command in ("demo", "synth") and rng.random() < 0.95:
            given = True  # a synthetic scene at its default size takes seconds
        if command == "demo" and name == "example" and rng.random() < 0.95:
            given = True  # the shipped photograph takes seconds
        if not given:
            continue
        if is_flag:
            args.append(flag)
            continue
        count = rng.choice([1, 1, 1, 2, 3, 4]) if many else 1
        for _ in range(count):
            value = _value(rng, command, name, inputs, case)
            args += [flag, value] if flag else [value]
    roll = rng.random()
    if roll < 0.03:
        args.insert(
            rng.randrange(1, len(args) + 1), rng.choice(["--bogus", "--json=3", "-x", "--", "--help"])
        )
    elif roll < 0.06 and len(args) > 2:
        args.pop(rng.randrange(1, len(args)))  # a value loses its flag, or a flag its value
    return args


class Hang(BaseException):
    """Raised by the guard when a case runs past its time."""


def _on_alarm(signum, frame):
    raise Hang


WARNING_LINE = re.compile(r"\b\w*Warning: ")


def run_case(args: list[str], case: Path, seconds: float) -> tuple[list[str], dict]:
    """Run one argument list in ``case`` (made empty first, the working directory); the findings
    and what the command did."""
    from typer.testing import CliRunner

    from shadeform.cli import app

    shutil.rmtree(case, ignore_errors=True)
    case.mkdir(parents=True)
    hidden: list[str] = []

    class Catch(logging.Handler):
        def emit(self, record):
            hidden.append(record.getMessage())

    catcher = Catch(logging.DEBUG)
    logger = logging.getLogger("shadeform")
    logger.addHandler(catcher)
    logger.setLevel(logging.DEBUG)
    before = Path.cwd()
    os.chdir(case)
    signal.signal(signal.SIGALRM, _on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    start = time.perf_counter()
    findings: list[str] = []
    result = None
    # what reaches the process's own stderr (fd 2): worker processes write there, not to the
    # runner's captured stream
    sys.stderr.flush()
    saved = os.dup(2)
    raw = tempfile.TemporaryFile()  # noqa: SIM115 (closed below, once fd 2 is back)
    os.dup2(raw.fileno(), 2)
    try:
        result = CliRunner(env={"COLUMNS": "200"}).invoke(app, args, catch_exceptions=True)
    except Hang:
        findings.append("hang")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        os.dup2(saved, 2)
        os.close(saved)
        os.chdir(before)
        logger.removeHandler(catcher)
    raw.seek(0)
    elsewhere = raw.read().decode("utf-8", "replace")
    raw.close()
    took = time.perf_counter() - start
    done = {"seconds": took, "exit": None, "stderr": "", "stdout": "", "hidden": hidden}
    if result is not None:
        done.update(exit=result.exit_code, stderr=result.stderr, stdout=result.stdout)
        escaped = result.exception is not None and not isinstance(result.exception, SystemExit)
        if escaped:
            done["traceback"] = "".join(traceback.format_exception(result.exception))
        if escaped or "Traceback" in result.output:
            findings.append("traceback")
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        if result.exit_code == 2 and (len(lines) != 1 or not lines[0].startswith("error: ")):
            findings.append("bad refusal")
        if result.exit_code not in (0, 2) and not escaped:
            findings.append("bad exit")
        if any(WARNING_LINE.search(line) for line in lines + elsewhere.splitlines()):
            findings.append("raw warning")
            done["stderr"] += elsewhere
    if hidden:
        findings.append("internal warning")
    left = []
    for path in case.rglob("*"):
        relative = path.relative_to(case).as_posix()
        # a hidden name the case asked for (``-o .hidden.png``) is an output, not a leftover
        temporary = ".shadeform-" in path.name or path.name.endswith(".tiles")
        refused_wrote = done["exit"] == 2 and args[0] != "batch" and path.is_file()
        if temporary or refused_wrote:
            left.append(relative)
    if left:
        findings.append("leftovers")
        done["left"] = left
    shutil.rmtree(case, ignore_errors=True)
    return findings, done


def _table(counts: Counter, by_command: dict, cases: int, seed: int, seconds: float, exits: Counter) -> str:
    lines = [
        f"# CLI fuzz: {cases:,} argument sets, seed {seed}",
        "",
        f"{seconds:.0f} s in all; exit codes: "
        + ", ".join(f"{code}: {n:,}" for code, n in sorted(exits.items(), key=lambda item: str(item[0]))),
        "",
        "| command | cases | mean s | " + " | ".join(FINDINGS) + " |",
        "|---|---:|---:|" + "---:|" * len(FINDINGS),
    ]
    for command in sorted(by_command):
        row = by_command[command]
        mean = row["seconds"] / max(row["cases"], 1)
        cells = " | ".join(f"{row[f]:,}" for f in FINDINGS)
        lines.append(f"| {command} | {row['cases']:,} | {mean:.2f} | {cells} |")
    cells = " | ".join(f"**{counts[f]:,}**" for f in FINDINGS)
    lines.append(f"| **all** | {cases:,} | {seconds / max(cases, 1):.2f} | {cells} |")
    return "\n".join(lines) + "\n"


def fuzz(cases: int, *, seed: int = 0, seconds: float = 30.0, first: int = 0, report=None) -> dict:
    """Run ``cases`` argument sets from number ``first``; returns the counts, the table and the
    failing cases (number, arguments, findings, what the command said)."""
    work = Path(tempfile.mkdtemp(prefix="shadeform-fuzz-cli-"))
    try:
        inputs = make_inputs(work / "inputs")
        commands = command_options()
        counts: Counter = Counter()
        exits: Counter = Counter()
        by_command: dict = {}
        failures = []
        start = time.perf_counter()
        for number in range(first, first + cases):
            case = work / "case"
            args = draw_case(seed, number, commands, inputs, case)
            findings, done = run_case(args, case, seconds)
            counts.update(findings)
            exits[done["exit"]] += 1
            row = by_command.setdefault(args[0], Counter())
            row["cases"] += 1
            row["seconds"] += done["seconds"]
            row.update(findings)
            if findings:
                failures.append((number, args, findings, done))
                if report is not None:
                    report(number, args, findings, done)
        took = time.perf_counter() - start
        return {
            "counts": counts,
            "failures": failures,
            "table": _table(counts, by_command, cases, seed, took, exits),
        }
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _show(number, args, findings, done) -> None:
    shown = " ".join(a if len(a) < 60 else a[:57] + "..." for a in args)
    print(f"case {number}: {', '.join(findings)}: {shown}", flush=True)
    for line in (done.get("traceback") or done["stderr"]).strip().splitlines()[-3:]:
        print(f"    {line[:300]}", flush=True)
    for message in done["hidden"][:2]:
        print(f"    hidden: {message[:300]}", flush=True)
    if done.get("left"):
        print(f"    left: {done['left'][:5]}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--case-seconds", type=float, default=30.0, help="hang guard per case")
    parser.add_argument("--first", type=int, default=0, help="number of the first case")
    parser.add_argument("--case", type=int, help="rerun this one case and print its output")
    parser.add_argument("--no-write", action="store_true", help="do not write the results file")
    options = parser.parse_args()
    logging.getLogger("numba").setLevel(logging.WARNING)
    if options.case is not None:
        result = fuzz(1, seed=options.seed, seconds=options.case_seconds, first=options.case, report=_show)
        if not result["failures"]:
            print(f"case {options.case}: clean")
        return
    result = fuzz(
        options.cases, seed=options.seed, seconds=options.case_seconds, first=options.first, report=_show
    )
    print(result["table"])
    if not options.no_write:
        from shadeform.io.atomic import atomic_write

        with contextlib.suppress(OSError), atomic_write(RESULTS, mode="w") as handle:
            handle.write(result["table"])
    sys.exit(1 if result["failures"] else 0)


if __name__ == "__main__":
    main()
