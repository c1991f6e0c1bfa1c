"""Atomic file writes: a temporary file in the target's folder, then one rename.

A reader (or a crash) never sees a half-written file, and a failed write never clobbers an
existing good file (``docs/conventions.md``, "Errors").

Every temporary is named ``.<target name>.shadeform-<pid>-<random>.partial<suffix>`` (an
:class:`OutputSet`'s) or ``...tmp`` (:func:`atomic_write`'s): hidden, recognisable, and naming
the process that writes it. A command that writes a whole folder (files read together, as a web
viewer reads them) fills a temporary folder named the same way (:meth:`OutputSet.temp_folder`,
:func:`atomic_folder`), renamed into place once complete. A temporary is removed on every exit
that runs Python's clean-up (an exception, Ctrl-C, and SIGTERM or SIGHUP where the command line
turns them into an exit); what a process killed outright (``kill -9``, a power cut) leaves is
swept from a folder by the next process that writes there (:func:`sweep`), once the process
named in it no longer runs.
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
import shutil
import signal
import stat
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from shadeform.errors import InputError

__all__ = [
    "OutputSet",
    "atomic_folder",
    "atomic_write",
    "exit_on_signals",
    "remove_temporaries",
    "sweep",
    "target_name",
]

#: A temporary's name: the target's name (a temporary's own, the last ".shadeform-", is its), the
#: writing process, a random part, the kind.
_TEMPORARY = re.compile(r"^\.(?P<target>.+)\.shadeform-(?P<pid>\d+)-[0-9a-z_]+\.(?:partial.*|tmp)$")
#: This process's temporaries not yet renamed or deleted (for :func:`remove_temporaries`).
_LIVE: set[Path] = set()
#: Folders this process has swept already (once each is enough: later leftovers are its own).
_SWEPT: set[Path] = set()


def _read_umask() -> int:
    # os.umask can only be read by setting it; do it once, at import, while nothing else runs.
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _read_umask()


@contextmanager
def atomic_write(path: str | os.PathLike[str], *, mode: str = "wb") -> Iterator[IO]:
    """Open a file for writing so that it appears at ``path`` only once complete.

    The data goes to a hidden temporary file ``.<name>.<random>.tmp`` in the same folder (so the
    final rename stays on one file system), unless ``path`` is itself a temporary of this
    process (an :class:`OutputSet`'s), which is written in place; on leaving the ``with`` block it is flushed,
    fsynced and moved onto ``path`` with :func:`os.replace`. If the block raises, the temporary
    file is deleted and the exception propagates: ``path`` keeps its old content, if any.

    Parameters
    ----------
    path : str or path-like
        The file to create or replace.
    mode : {"wb", "w"}, keyword-only
        Binary (default) or text. Text is UTF-8 with ``"\\n"`` line endings on every platform.

    Yields
    ------
    file object
        The open temporary file; write to it, do not close it.

    Raises
    ------
    InputError
        If the parent folder does not exist or ``path`` is a folder.

    Notes
    -----
    The new file gets the permissions of the file it replaces, or ``0o666`` minus the umask for
    a new file (a bare temporary file would be private, ``0o600``).

    Examples
    --------
    >>> with atomic_write(tmp_path / "out.txt", mode="w") as f:  # doctest: +SKIP
    ...     f.write("hello\\n")
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"atomic_write mode must be 'wb' or 'w', got {mode!r}")
    path = Path(path)
    parent = path.parent
    if not parent.is_dir():
        raise InputError(f"output folder '{parent}' does not exist; create it first")
    if path.is_dir():
        raise InputError(f"output path '{path}' is a folder; give a file name instead")

    text_options = {"encoding": "utf-8", "newline": "\n"} if mode == "w" else {}
    own = _TEMPORARY.match(path.name)
    if own is not None and int(own["pid"]) == os.getpid():
        # a temporary of this process's already (an OutputSet's): hidden, and renamed by its
        # owner, so written in place; a temporary of a temporary would be one more name to leave
        with open(path, mode, **text_options) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        return
    if path.exists():
        permissions = stat.S_IMODE(path.stat().st_mode)
    else:
        permissions = 0o666 & ~_UMASK

    sweep(parent)
    tmp = tempfile.NamedTemporaryFile(  # noqa: SIM115 (the with below closes it)
        mode=mode,
        delete=False,
        dir=parent,
        prefix=f".{path.name}.shadeform-{os.getpid()}-",
        suffix=".tmp",
        **text_options,
    )
    tmp_path = Path(tmp.name)
    _LIVE.add(tmp_path)
    try:
        with tmp:
            yield tmp
            tmp.flush()
            os.fsync(tmp.fileno())
        os.chmod(tmp_path, permissions)
        os.replace(tmp_path, path)
    except BaseException:
        # BaseException too: a KeyboardInterrupt mid-write must not leave the temporary behind.
        tmp_path.unlink(missing_ok=True)
        raise
    finally:
        _LIVE.discard(tmp_path)
    _fsync_folder(parent)


@contextmanager
def atomic_folder(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Fill a folder so that it appears at ``path`` only once complete: the folder counterpart
    of :func:`atomic_write`.

    Yields a hidden, empty temporary folder beside ``path`` (or ``path`` itself when it is
    already a temporary folder of this process, an :class:`OutputSet`'s); on leaving the ``with``
    block it takes ``path``'s place, replacing a folder there. If the block raises, the temporary
    folder is deleted with what it holds and ``path`` is left as it was.

    Raises
    ------
    InputError
        If the parent folder does not exist or cannot be written to, or ``path`` is a file.
    """
    path = Path(path)
    own = _TEMPORARY.match(path.name)
    if own is not None and int(own["pid"]) == os.getpid() and path.is_dir():
        yield path  # renamed by its owner
        return
    with OutputSet() as outputs:
        folder = outputs.temp_folder(path)
        yield folder
        outputs.commit()


def target_name(path: str | os.PathLike[str]) -> str:
    """The name of the file a temporary of this module's (or a temporary's temporary) stands for,
    for messages; any other path's own name."""
    name = Path(path).name
    while found := _TEMPORARY.match(name):
        name = found["target"]
    return name


def sweep(folder: str | os.PathLike[str], *, again: bool = False) -> list[Path]:
    """Delete the temporaries that processes no longer running left in ``folder``.

    Called by every writer before its first temporary in a folder (once per folder and process),
    so the leftovers of a run killed outright go with the next run that writes there. A
    temporary whose process still runs (another command writing beside this one) is kept.

    Parameters
    ----------
    folder : str or path-like
        The folder to sweep; a folder that cannot be listed is left alone.
    again : bool, keyword-only
        Sweep even if this process swept the folder before (after ending worker processes
        that wrote there).

    Returns
    -------
    list of Path
        The files deleted.
    """
    folder = Path(folder)
    key = folder.resolve()
    if key in _SWEPT and not again:
        return []
    _SWEPT.add(key)
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        found = _TEMPORARY.match(entry.name) if ".shadeform-" in entry.name else None
        if found is None or _running(int(found["pid"])):
            continue
        with contextlib.suppress(OSError):
            _delete(Path(entry.path))
            removed.append(Path(entry.path))
    return removed


def remove_temporaries() -> None:
    """Delete every temporary this process has open, for an exit that skips clean-up
    (``os._exit`` in a worker whose parent is gone)."""
    for path in list(_LIVE):
        with contextlib.suppress(OSError):
            _delete(path)
        _LIVE.discard(path)


#: Seconds a process given SIGINT, SIGTERM or SIGHUP has to end by its exception before it is
#: ended outright (its temporaries removed first): an exception can be swallowed (a library's
#: ``except BaseException`` around an optional import) and clean-up can hang.
STOP_SECONDS = 0.5


def exit_on_signals() -> None:
    """Make SIGTERM and SIGHUP (``kill``, a closed terminal) end the process as an exception
    would, so that ``with`` blocks remove their temporaries (Python's default for them ends the
    process without any clean-up), and SIGINT (Ctrl-C) raise KeyboardInterrupt as usual; and if
    the process still runs :data:`STOP_SECONDS` after any of them, remove this process's
    temporaries and end it. Call from the main thread."""
    for name in ("SIGTERM", "SIGHUP", "SIGINT"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), _raise_exit)


#: Seconds a signal that came during a finaliser waits to be delivered again.
_AGAIN_SECONDS = 0.01
#: Whether a signal's stop timer runs already (one is enough).
_STOPPING = threading.Event()


def _raise_exit(signum, frame) -> None:
    if not _STOPPING.is_set():
        _STOPPING.set()
        timer = threading.Timer(STOP_SECONDS, _end_now, args=(signum,))
        timer.daemon = True  # does not hold up an exit that goes well
        timer.start()
    if _in_finaliser(frame):
        # Python prints an exception raised in a __del__ as a traceback and drops it: deliver
        # the signal again once the finaliser is done.
        again = threading.Timer(_AGAIN_SECONDS, os.kill, args=(os.getpid(), signum))
        again.daemon = True
        again.start()
        return
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise SystemExit(128 + signum)


def _in_finaliser(frame) -> bool:
    """Whether ``frame`` runs inside an object's ``__del__`` (at any depth)."""
    while frame is not None:
        if frame.f_code.co_name == "__del__":
            return True
        frame = frame.f_back
    return False


def _end_now(signum: int) -> None:
    """The end of a process that a signal's exception did not end in time."""
    remove_temporaries()
    os._exit(128 + signum)


def _running(pid: int) -> bool:
    """Whether process ``pid`` is alive (not a zombie); True when that cannot be told."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True  # another user's process; or an id no process can have, left alone
    try:  # a killed process its parent has not reaped yet is no longer writing
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return True
    return state not in ("Z", "X")


def _delete(path: Path) -> None:
    """Delete a temporary: a file, or a folder with what it holds (a link is not followed)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)


def _fsync_folder(folder: Path) -> None:
    """Make the rename itself durable (POSIX only; Windows cannot open folders)."""
    if os.name != "posix":
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class OutputSet:
    """The files one command (or one batch item) writes, made to appear together or not at all.

    :meth:`temp` hands out, for each target, a hidden temporary path in the target's folder with
    the target's suffix (writers pick formats by suffix); the library writes there (atomically
    too). :meth:`commit` renames every temporary onto its target; if the command fails before,
    leaving the ``with`` block deletes the temporaries. If a rename itself fails, the targets this
    run had already created are removed again. :meth:`temp_folder` does the same for a target that
    is a whole folder.
    """

    def __init__(self) -> None:
        self._pending: list[tuple[Path, Path]] = []
        self._made_folder: Path | None = None

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, *exc) -> None:
        self._discard()
        if self._made_folder is not None and exc[0] is not None:
            with contextlib.suppress(OSError):
                self._made_folder.rmdir()  # only if still empty

    def make_folder(self, folder: Path) -> None:
        """Create ``folder`` (and parents) if missing; removed again if the command fails."""
        if folder.exists() and not folder.is_dir():
            raise InputError(f"output folder '{folder}' is a file; give a folder name")
        if not folder.exists():
            folder.mkdir(parents=True)
            self._made_folder = folder

    def temp(self, target: Path | str) -> Path:
        def probe(tmp: Path) -> None:  # a folder that cannot be written to is said now
            tmp.open("x").close()
            tmp.unlink()

        return self._claim(Path(target), probe, folder=False)

    def temp_folder(self, target: Path | str) -> Path:
        """A hidden, empty temporary folder beside ``target`` for a command that writes a whole
        folder; :meth:`commit` puts it in ``target``'s place (a folder there is moved aside
        first and deleted once the new one is in place). Whether an existing folder may be
        replaced is the caller's to decide before."""
        return self._claim(Path(target), Path.mkdir, folder=True)

    def _claim(self, target: Path, make, *, folder: bool) -> Path:
        """Check that ``target`` can be written (its folder exists, it is of the right kind, no
        other output of the set names it), sweep what killed runs left beside it, and make its
        hidden temporary (``make(tmp)``, said as a refusal when the folder cannot be written
        to), committed in its place by :meth:`commit`."""
        if not target.parent.is_dir():
            raise InputError(f"output folder '{target.parent}' does not exist; create it first")
        if folder and target.exists() and not target.is_dir():
            raise InputError(f"output '{target}' is a file; give a folder name")
        if not folder and target.is_dir():
            raise InputError(f"output path '{target}' is a folder; give a file name")
        if any(target.resolve() == final.resolve() for _, final in self._pending):
            what = "name" if folder else "file"
            raise InputError(f"'{target}' is given for two outputs; give each output its own {what}")
        sweep(target.parent)
        suffix = "" if folder else target.suffix
        tmp = target.with_name(
            f".{target.name}.shadeform-{os.getpid()}-{secrets.token_hex(4)}.partial{suffix}"
        )
        try:
            make(tmp)
        except OSError as err:
            reason = (err.strerror or type(err).__name__).lower()
            raise InputError(
                f"cannot write '{target.name}' in folder '{target.parent}' ({reason}); choose another output folder"
            ) from None
        self._pending.append((tmp, target))
        _LIVE.add(tmp)
        return tmp

    def commit(self) -> list[Path]:
        created: list[Path] = []
        try:
            for tmp, target in self._pending:
                existed = target.exists()
                if tmp.is_dir():
                    _replace_folder(tmp, target)
                else:
                    if existed:  # keep the permissions of the file being replaced
                        os.chmod(tmp, stat.S_IMODE(target.stat().st_mode))
                    os.replace(tmp, target)
                _LIVE.discard(tmp)
                if not existed:
                    created.append(target)
        except BaseException:
            for path in created:
                with contextlib.suppress(OSError):
                    _delete(path)
            raise
        return [target for _, target in self._pending]

    def _discard(self) -> None:
        for tmp, _ in self._pending:
            with contextlib.suppress(OSError):
                _delete(tmp)
            _LIVE.discard(tmp)


def _replace_folder(folder: Path, target: Path) -> None:
    """Put a complete ``folder`` in ``target``'s place: a folder already there is renamed aside
    (a hidden temporary), the new one renamed in, the old one deleted; if the second rename
    fails, the old folder is put back."""
    if not target.exists():
        os.rename(folder, target)
        _fsync_folder(target.parent)
        return
    aside = target.with_name(f".{target.name}.shadeform-{os.getpid()}-{secrets.token_hex(4)}.partial-old")
    os.rename(target, aside)
    _LIVE.add(aside)
    try:
        os.rename(folder, target)
    except BaseException:
        os.rename(aside, target)
        _LIVE.discard(aside)
        raise
    _fsync_folder(target.parent)
    with contextlib.suppress(OSError):
        _delete(aside)
    _LIVE.discard(aside)
