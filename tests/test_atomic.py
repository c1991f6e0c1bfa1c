"""Tests for shadeform.io.atomic: a failed write leaves nothing behind and clobbers nothing."""

from __future__ import annotations

import os
import stat

import pytest

from shadeform.errors import InputError
from shadeform.io.atomic import atomic_write


class Boom(RuntimeError):
    """Raised on purpose in the middle of a write."""


def leftovers(folder):
    """Names in ``folder`` that look like atomic_write temporaries."""
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


class TestAtomicWrite:
    def test_smoke(self, tmp_path):
        target = tmp_path / "out.bin"
        with atomic_write(target) as f:
            f.write(b"\x00\x01payload")
        assert target.read_bytes() == b"\x00\x01payload"
        assert leftovers(tmp_path) == []

    def test_text_mode_writes_utf8_with_unix_newlines(self, tmp_path):
        target = tmp_path / "out.txt"
        with atomic_write(target, mode="w") as f:
            f.write("épure\nline 2\n")
        assert target.read_bytes() == "épure\nline 2\n".encode()

    def test_target_appears_only_when_complete(self, tmp_path):
        target = tmp_path / "out.bin"
        with atomic_write(target) as f:
            f.write(b"first half")
            assert not target.exists()
            temporaries = leftovers(tmp_path)
            assert len(temporaries) == 1 and temporaries[0].startswith(".out.bin.")
            f.write(b", second half")
        assert target.read_bytes() == b"first half, second half"

    def test_replaces_existing_file(self, tmp_path):
        target = tmp_path / "out.bin"
        target.write_bytes(b"old content that is longer than the new one")
        with atomic_write(target) as f:
            f.write(b"new")
        assert target.read_bytes() == b"new"
        assert leftovers(tmp_path) == []

    def test_exception_mid_write_keeps_existing_file(self, tmp_path):
        target = tmp_path / "model.wrl"
        target.write_bytes(b"good old file")
        with pytest.raises(Boom), atomic_write(target) as f:
            f.write(b"half of a new fi")
            raise Boom("disk full, say")
        assert target.read_bytes() == b"good old file"
        assert leftovers(tmp_path) == []
        assert sorted(p.name for p in tmp_path.iterdir()) == ["model.wrl"]

    def test_exception_mid_write_creates_nothing(self, tmp_path):
        target = tmp_path / "new.wrl"
        with pytest.raises(Boom), atomic_write(target) as f:
            f.write(b"partial")
            raise Boom
        assert list(tmp_path.iterdir()) == []

    def test_keyboard_interrupt_also_cleans_up(self, tmp_path):
        target = tmp_path / "new.bin"
        with pytest.raises(KeyboardInterrupt), atomic_write(target) as f:
            f.write(b"partial")
            raise KeyboardInterrupt
        assert list(tmp_path.iterdir()) == []

    def test_missing_folder_is_input_error(self, tmp_path):
        target = tmp_path / "no" / "such" / "out.bin"
        with (
            pytest.raises(InputError, match="does not exist; create it first") as info,
            atomic_write(target) as f,
        ):
            f.write(b"x")
        assert "\n" not in str(info.value)
        assert str(tmp_path / "no" / "such") in str(info.value)

    def test_folder_as_target_is_input_error(self, tmp_path):
        with pytest.raises(InputError, match="is a folder"), atomic_write(tmp_path) as f:
            f.write(b"x")
        assert list(tmp_path.iterdir()) == []

    def test_bad_mode_is_rejected(self, tmp_path):
        with pytest.raises(ValueError, match="mode"), atomic_write(tmp_path / "x", mode="a"):
            pass

    @pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
    def test_permissions_of_replaced_file_are_kept(self, tmp_path):
        target = tmp_path / "shared.bin"
        target.write_bytes(b"old")
        target.chmod(0o640)
        with atomic_write(target) as f:
            f.write(b"new")
        assert stat.S_IMODE(target.stat().st_mode) == 0o640

    @pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
    def test_new_file_follows_umask_not_private_tempfile_mode(self, tmp_path):
        umask = os.umask(0o022)
        os.umask(umask)
        target = tmp_path / "new.bin"
        with atomic_write(target) as f:
            f.write(b"x")
        assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~umask


def test_a_temporary_is_named_as_the_file_it_stands_for(tmp_path):
    from shadeform.io.atomic import OutputSet, target_name

    with OutputSet() as outputs:
        partial = outputs.temp(tmp_path / "model.glb")
        with atomic_write(partial) as handle:  # a temporary's temporary, as the exporters make
            inner = handle.name
            handle.write(b"x")
        assert target_name(partial) == target_name(inner) == "model.glb" != partial.name
    assert target_name(tmp_path / "photo.png") == "photo.png"


@pytest.mark.skipif(
    not os.path.isdir("/proc/self"), reason="needs Linux's /proc, a folder no file can be made in"
)
def test_a_folder_that_cannot_be_written_is_said_before_any_work():
    from shadeform.io.atomic import OutputSet

    with OutputSet() as outputs, pytest.raises(InputError, match=r"cannot write 'x.glb' in folder '/proc'"):
        outputs.temp("/proc/x.glb")
