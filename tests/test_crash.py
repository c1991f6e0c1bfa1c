"""Crashes and signals: outputs old or complete, no temporary files left, no orphaned workers.

The commands run as real processes (``shadeform reconstruct``, ``shadeform batch``) and are
killed with SIGTERM or SIGKILL part-way; Linux's ``/proc`` tells which processes still run.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from shadeform import synth
from shadeform.io.atomic import OutputSet, atomic_write, sweep
from shadeform.io.maps import save_gray

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux's /proc")

COMMAND = [sys.executable, "-c", "from shadeform.cli import main; main()"]


def temporaries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".shadeform-" in p.name)


def running(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


def children(pid: int) -> list[int]:
    """The processes whose parent is ``pid``."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def _cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


def dead_pid() -> int:
    """The id of a process that has ended (and been reaped)."""
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


@pytest.fixture(scope="module")
def photo(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("photo") / "sphere.png"
    save_gray(synth.scene("sphere", size=384).image, path, bitdepth=16)
    return path


class TestSweep:
    def test_a_dead_process_s_temporaries_go_a_live_one_s_stay(self, tmp_path):
        dead, alive = dead_pid(), os.getppid()
        left = [
            tmp_path / f".model.glb.shadeform-{dead}-1a2b3c4d.partial.glb",
            tmp_path / f".depth.tiff.shadeform-{dead}-abc_12xy.tmp",
        ]
        kept = [
            tmp_path / f".model.glb.shadeform-{alive}-1a2b3c4d.partial.glb",  # a run beside this one
            tmp_path / "model.glb",
            tmp_path / f".notes.shadeform-{dead}.txt",  # not a temporary's name
        ]
        for path in left + kept:
            path.write_bytes(b"x")
        assert sorted(sweep(tmp_path)) == sorted(left)
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in kept)

    def test_a_dead_process_s_temporary_folders_go_with_what_they_hold(self, tmp_path):
        dead, alive = dead_pid(), os.getppid()
        left = [
            tmp_path / f".web.shadeform-{dead}-1a2b3c4d.partial",  # a web set half written
            tmp_path / f".web.shadeform-{dead}-5e6f7a8b.partial-old",  # an old one moved aside
        ]
        kept = [tmp_path / f".web.shadeform-{alive}-1a2b3c4d.partial", tmp_path / "web"]
        for folder in left + kept:
            folder.mkdir()
            (folder / "plane_0.jpg").write_bytes(b"x")
        assert sorted(sweep(tmp_path)) == sorted(left)
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in kept)

    def test_writers_sweep_their_folder_first(self, tmp_path):
        for write in ("atomic", "set"):
            folder = tmp_path / write
            folder.mkdir()
            litter = folder / f".old.obj.shadeform-{dead_pid()}-00ff00ff.partial.obj"
            litter.write_bytes(b"half a mesh")
            if write == "atomic":
                with atomic_write(folder / "new.txt", mode="w") as f:
                    f.write("done")
            else:
                with OutputSet() as outputs:
                    outputs.temp(folder / "new.txt").write_text("done")
                    outputs.commit()
            assert sorted(p.name for p in folder.iterdir()) == ["new.txt"]

    def test_temporaries_name_their_process(self, tmp_path):
        with atomic_write(tmp_path / "out.bin") as f:
            f.write(b"1")
            (name,) = temporaries(tmp_path)
            assert name.startswith(f".out.bin.shadeform-{os.getpid()}-") and name.endswith(".tmp")


class TestKilled:
    def test_sigterm_at_any_moment_leaves_no_temporaries(self, photo, tmp_path):
        """A kill (SIGTERM) at any point of a run: the outputs are all there or none is, and
        no temporary file is left behind."""
        outputs = ("model.glb", "depth.tiff", "normals.png")
        for delay in (0.5, 1.5, 2.5, 3.5, 5.0):
            folder = tmp_path / f"after{delay}"
            folder.mkdir()
            process = subprocess.Popen(
                [*COMMAND, "reconstruct", photo, "-o", folder / outputs[0], "--depth", folder / outputs[1],
                 "--normals", folder / outputs[2]],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
            )  # fmt: skip
            time.sleep(delay)
            process.send_signal(signal.SIGTERM)
            _, stderr = process.communicate(timeout=120)
            # -SIGTERM: killed while Python was still starting, before the command set its handler
            assert process.returncode in (0, 128 + signal.SIGTERM, -signal.SIGTERM), stderr.decode()
            assert b"Traceback" not in stderr
            assert temporaries(folder) == []
            made = sorted(p.name for p in folder.iterdir())
            assert made in ([], sorted(outputs)), made

    def test_kill_9_litter_is_swept_by_the_next_run(self, photo, tmp_path):
        """``kill -9`` cannot be caught: whatever it leaves, the outputs are old or complete,
        and the next run in the folder removes the leftovers."""
        target = tmp_path / "model.ply"
        target.write_bytes(b"the old model")
        for delay in (1.0, 2.0, 3.0):
            process = subprocess.Popen(
                [*COMMAND, "reconstruct", photo, "-o", target],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            time.sleep(delay)
            process.kill()
            process.wait(timeout=30)
            content = target.read_bytes()
            assert content == b"the old model" or content.startswith(b"ply\n")
        (tmp_path / f".model.ply.shadeform-{dead_pid()}-deadbeef.partial.ply").write_bytes(b"ply\nhalf")
        done = subprocess.run(
            [*COMMAND, "reconstruct", photo, "-o", target], capture_output=True, timeout=120
        )
        assert done.returncode == 0, done.stderr.decode()
        assert temporaries(tmp_path) == [] and target.read_bytes().startswith(b"ply\n")


@pytest.fixture(scope="module")
def many_photos(tmp_path_factory) -> list[Path]:
    folder = tmp_path_factory.mktemp("many")
    paths = []
    for k in range(8):
        path = folder / f"photo{k}.png"
        save_gray(
            synth.scene(("sphere", "ellipsoid", "vase", "bumps")[k % 4], size=320).image, path, bitdepth=16
        )
        paths.append(path)
    return paths


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGTERM])
def test_killing_a_batch_ends_its_workers(many_photos, tmp_path, how):
    """A batch killed in any way (``kill -9`` included) takes its worker processes with it
    within a few seconds, and they leave no temporary files."""
    out = tmp_path / "models"
    process = subprocess.Popen(
        [*COMMAND, "batch", *many_photos, "--out", out, "--workers", "2"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 90
    while not (out.exists() and any(".shadeform-" not in p.name for p in out.iterdir())):
        assert time.monotonic() < deadline and process.poll() is None, "the batch wrote no model"
        time.sleep(0.05)
    # the first model is written: the workers are at work on the next photos
    workers = [pid for pid in children(process.pid) if b"resource_tracker" not in _cmdline(pid)]
    assert len(workers) == 2 and process.poll() is None
    process.send_signal(how)
    process.wait(timeout=30)
    start = time.monotonic()
    while any(running(pid) for pid in workers) and time.monotonic() - start < 30:
        time.sleep(0.1)
    seconds = time.monotonic() - start
    assert not any(running(pid) for pid in workers), "workers still run 30 s after the batch was killed"
    print(f"workers ended {seconds:.2f} s after the batch was killed")
    assert seconds < 8.0, f"the workers took {seconds:.1f} s to end"
    if out.exists():
        assert temporaries(out) == []
