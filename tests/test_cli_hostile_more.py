"""Hostile input to the command line, found by hand and by ``benchmarks/fuzz_cli.py`` (issue 34):
each is refused in one stderr line with exit code 2 (or done right), at once, with nothing left
behind; signals end a command soon and cleanly."""

from __future__ import annotations

import contextlib
import importlib.util
import multiprocessing
import os
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from shadeform import synth
from shadeform.io.atomic import OutputSet, atomic_write
from shadeform.io.maps import save_gray

ROOT = Path(__file__).resolve().parents[1]
COMMAND = [sys.executable, "-c", "from shadeform.cli import main; main()"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("inputs")
    save_gray(synth.scene("sphere", size=32).image, folder / "photo.png")
    save_gray(synth.scene("vase", size=32).image, folder / "vase.png")
    polygon = "[[{x}, 0], [9, 0], [9, 9]]"
    for name, x in (("digits", "9" * 5000), ("huge", "1e300"), ("nan", "NaN"), ("inf", "1e999")):
        (folder / f"{name}.json").write_text(
            '{"regions": [{"polygon": ' + polygon.format(x=x) + ', "axis": "x"}]}'
        )
    os.mkfifo(folder / "pipe.png")
    os.mkfifo(folder / "pipe.json")
    return folder


def one_line_refusal(result, out: Path, fragment: str) -> str:
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    assert fragment in lines[0], lines[0]
    assert list(out.iterdir()) == []
    return lines[0]


@pytest.fixture
def guard():
    """A generous hang guard (SIGALRM) for a command that must answer at once."""

    class Hung(BaseException):  # not an OSError, which the commands turn into their messages
        pass

    def expire(signum, frame):
        raise Hung("the command hung")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(60)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, previous)


@pytest.mark.parametrize(("name", "fragment"), [("digits", "thousands of digits"), ("huge", "1e+300"),
                                                 ("nan", "non-finite"), ("inf", "non-finite")])  # fmt: skip
def test_a_regions_file_of_absurd_numbers_is_one_line(files, out, cli, name, fragment):
    result = cli("reconstruct", files / "photo.png", "-o", out / "m.glb", "--concave", files / f"{name}.json")
    one_line_refusal(result, out, fragment)


@pytest.mark.parametrize("flag", ["--width", "--height", "--base"])
@pytest.mark.parametrize("value", ["1e308", "1e-300"])
def test_relief_sizes_out_of_range_are_one_line(files, out, cli, flag, value):
    sizes = {"--width": "50", "--height": "3", "--base": "2", flag: value}
    args = [part for pair in sizes.items() for part in pair]
    result = cli("relief", files / "photo.png", "-o", out / "r.stl", *args)
    one_line_refusal(result, out, flag)


def test_a_light_of_huge_or_tiny_components_is_its_direction():
    from shadeform.light import as_light

    assert np.allclose(as_light([1e308, 1e308, 1e308]), np.full(3, 3**-0.5))
    assert np.allclose(as_light([1e-320, 0.0, 1e-320]), [2**-0.5, 0.0, 2**-0.5])


@pytest.mark.parametrize(
    "args",
    [
        ["reconstruct", "{inputs}/pipe.png", "-o", "{out}/m.glb"],
        ["reconstruct", "{inputs}/photo.png", "-o", "{out}/m.glb", "--concave", "{inputs}/pipe.json"],
        ["fuse", "--views", "{inputs}/pipe.json", "-o", "{out}/f.glb"],
        [
            "stereo",
            "{inputs}/photo.png",
            "{inputs}/vase.png",
            "{inputs}/photo.png",
            "-o",
            "{out}/s.glb",
            "--lights",
            "{inputs}/pipe.json",
        ],
    ],  # fmt: skip
    ids=["photo", "regions", "views", "lights"],
)
def test_a_pipe_is_refused_at_once(files, out, cli, guard, args):
    result = cli(*(arg.format(inputs=files, out=out) for arg in args))
    one_line_refusal(result, out, "pipe.")


def test_batch_workers_are_capped_at_the_photos(files, tmp_path, cli, monkeypatch):
    """One photo and --workers 1000: no pool of a thousand processes, and a line says so."""
    pools = []

    def no_pool(method=None):
        raise AssertionError(f"a process pool was started ({method})")

    monkeypatch.setattr(
        multiprocessing, "get_context", lambda method=None: pools.append(method) or no_pool(method)
    )
    result = cli("batch", files / "photo.png", "--out", tmp_path / "models", "--workers", "1000")
    assert result.exit_code == 0, result.output
    assert pools == []
    assert "--workers 1000 lowered to 1" in result.stderr


def test_the_workers_are_at_most_the_photos_and_the_cpus():
    from shadeform.batch import worker_count

    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert worker_count(1000, 3) == min(3, cpus)
    assert worker_count(None, 1) == 1 and worker_count(2, 1000) == min(2, cpus)


def test_the_shadow_fill_of_a_normal_along_the_light_is_finite():
    """A shadow under a frontal light: the filled normals face the light, and moving one onto the
    terminator divided 0 by 0 (a RuntimeWarning and NaN normals)."""
    from shadeform.solvers.oblique.shadow import fill_shadow_normals

    mask = np.ones((9, 9), dtype=bool)
    shadow = np.zeros_like(mask)
    shadow[3:6, 3:6] = True
    normals = np.zeros((9, 9, 3))
    normals[..., 2] = 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        filled = fill_shadow_normals(normals, mask, shadow, light=np.array([0.0, 0.0, 1.0]))
    assert np.isfinite(filled).all()
    assert np.allclose(np.linalg.norm(filled, axis=2), 1.0)


def fuzz_cli():
    """``benchmarks/fuzz_cli.py`` as a module (its folder on the path for its sibling imports)."""
    if str(ROOT / "benchmarks") not in sys.path:
        sys.path.insert(0, str(ROOT / "benchmarks"))
    spec = importlib.util.spec_from_file_location("fuzz_cli", ROOT / "benchmarks" / "fuzz_cli.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def damaged_exif(tmp_path_factory) -> Path:
    module = fuzz_cli()
    path = tmp_path_factory.mktemp("exif") / "photo.jpg"
    path.write_bytes(module.jpeg_with_damaged_exif())
    return path


def test_a_library_warning_is_a_note_in_the_user_s_words(damaged_exif, out, cli):
    result = cli("reconstruct", damaged_exif, "-o", out / "m.glb")
    assert result.exit_code == 0, result.output
    assert "Warning" not in result.stderr
    assert sum("EXIF data is damaged" in line for line in result.stderr.splitlines()) == 1


def test_a_refusal_after_a_library_warning_is_still_one_line(damaged_exif, out, cli):
    result = cli("reconstruct", damaged_exif, "-o", out / "m.glb", "--reference", "1000000,2")
    one_line_refusal(result, out, "reference")


def test_a_temporary_is_never_nested_in_another(tmp_path):
    """The library writes an OutputSet's temporary with atomic_write: that used to make a
    temporary of the temporary (``..model.obj.shadeform-1-ab.partial.obj.shadeform-1-xy.tmp``)."""
    with OutputSet() as outputs:
        temp = outputs.temp(tmp_path / "model.obj")
        with atomic_write(temp) as handle:
            handle.write(b"v 0 0 0\n")
            names = [p.name for p in tmp_path.iterdir()]
            assert names == [temp.name], names
        outputs.commit()
    assert [p.name for p in tmp_path.iterdir()] == ["model.obj"]


def _hidden(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(".") or ".shadeform-" in p.name)


@pytest.fixture(scope="module")
def big_photo(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("big") / "vase.png"
    save_gray(synth.scene("vase", size=600).image, path, bitdepth=16)
    return path


def _wait_for_temporary(process, folder: Path) -> None:
    """Until the command has a temporary in ``folder`` (it is writing), or has ended."""
    while process.poll() is None and not _hidden(folder):
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(timeout=0.02)


def test_kill_9_while_writing_then_one_run_leaves_nothing(big_photo, tmp_path):
    """kill -9 mid-write leaves a temporary (nothing can remove it then); one more run in the
    folder sweeps it, and nothing hidden is left."""
    folder = tmp_path / "models"
    folder.mkdir()
    for suffix in (".obj", ".ply"):
        process = subprocess.Popen([*COMMAND, "reconstruct", big_photo, "-o", folder / f"model{suffix}"],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
        _wait_for_temporary(process, folder)
        process.kill()
        process.wait(timeout=60)
    done = subprocess.run([*COMMAND, "reconstruct", big_photo, "-o", folder / "model.obj"],
                          capture_output=True, timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr.decode()
    assert _hidden(folder) == []


def test_sigterm_while_writing_ends_the_command_and_leaves_nothing(big_photo, tmp_path):
    folder = tmp_path / "models"
    folder.mkdir()
    process = subprocess.Popen([*COMMAND, "reconstruct", big_photo, "-o", folder / "model.obj", "--depth",
                                folder / "depth.tif"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)  # fmt: skip
    _wait_for_temporary(process, folder)
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=60)  # a hang guard, not a timing
    assert process.returncode in (0, 128 + signal.SIGTERM), stderr.decode()
    assert b"Traceback" not in stderr
    assert _hidden(folder) == []
    assert sorted(p.name for p in folder.iterdir()) in ([], ["depth.tif", "model.obj"])


def test_a_signal_ends_the_process_even_when_its_exception_is_swallowed(tmp_path):
    """A library's ``except BaseException`` (trimesh's around its optional imports) swallowed
    the SystemExit of a SIGTERM: the process went on. Now it ends soon after, its temporaries
    removed."""
    script = (
        "import sys, time\n"
        "from pathlib import Path\n"
        "from shadeform.io.atomic import OutputSet, exit_on_signals\n"
        "exit_on_signals()\n"
        "with OutputSet() as outputs:\n"
        "    outputs.temp(Path(sys.argv[1]) / 'model.obj').write_bytes(b'v 0 0 0')\n"
        "    while True:\n"
        "        try:\n"
        "            print('ready', flush=True)\n"
        "            time.sleep(0.01)\n"
        "        except BaseException:\n"
        "            pass\n"
    )
    process = subprocess.Popen([sys.executable, "-c", script, tmp_path], stdout=subprocess.PIPE)
    assert process.stdout.readline() == b"ready\n"
    process.send_signal(signal.SIGTERM)
    process.wait(timeout=60)  # a hang guard: it used to run forever
    process.stdout.close()
    assert process.returncode == 128 + signal.SIGTERM
    assert _hidden(tmp_path) == []


def test_a_short_fuzz_of_the_command_line_finds_nothing():
    """A few hundred seeded argument sets of benchmarks/fuzz_cli.py (the full run: 10,000)."""
    module = fuzz_cli()
    result = module.fuzz(200, seed=1, seconds=60)
    found = [
        (number, args, findings, done["stderr"][-300:]) for number, args, findings, done in result["failures"]
    ]
    assert found == [], result["table"]


def test_a_signal_during_a_finaliser_prints_no_traceback(tmp_path):
    """A SIGTERM that arrived while llvmlite ran an ``ObjectRef.__del__`` raised its SystemExit
    there: Python printed it as a traceback and dropped it. Now it is delivered again after the
    finaliser, and the process ends as for any other SIGTERM."""
    script = (
        "import signal, sys, time\n"
        "from pathlib import Path\n"
        "from shadeform.io.atomic import OutputSet, exit_on_signals\n"
        "exit_on_signals()\n"
        "class Finalised:\n"
        "    def __del__(self):\n"
        "        signal.raise_signal(signal.SIGTERM)\n"
        "with OutputSet() as outputs:\n"
        "    outputs.temp(Path(sys.argv[1]) / 'model.obj').write_bytes(b'v 0 0 0')\n"
        "    Finalised()\n"
        "    time.sleep(30)\n"
    )
    done = subprocess.run([sys.executable, "-c", script, tmp_path], capture_output=True, timeout=60)
    assert done.returncode == 128 + signal.SIGTERM, done.stderr.decode()
    assert done.stderr == b""
    assert _hidden(tmp_path) == []
