"""What the app's sessions opened, and the users' projects, kept in SQLite so that they outlive
a server restart.

The server holds images and photo sets in memory (:class:`shadeform.app.store.LRU`); this store
keeps, for each id a client was given, how to make it again: the uploaded files' bytes (decoded
again, with the same limits) or the example's name. Decoded pixels are not stored: a 12-Mpx
photo is a few MB as the JPEG the user sent and 144 MB as floats. A client that comes back after
a restart (or after the memory store let the entry go) names its id, and the server makes the
entry again from here.

One SQLite file in the user's data folder (:func:`data_folder`), in WAL mode (a reader never
waits for a writer; a crash never leaves it half-written), bounded by bytes: the least recently
used entries go first. The same file keeps the users' projects (table ``projects``: the client's
project documents, autosaved), so that a project outlives a restart of the server, a browser
whose storage was cleared and a change of browser; the most recently updated are kept.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import sqlite3
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path

__all__ = ["SessionStore", "data_folder"]

logger = logging.getLogger(__name__)

#: The first bytes of every SQLite database file.
_SQLITE_HEADER = b"SQLite format 3\0"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS entries (
    key TEXT PRIMARY KEY,
    kind TEXT NOT NULL,
    recipe TEXT NOT NULL,
    nbytes INTEGER NOT NULL,
    used REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS blobs (
    key TEXT NOT NULL REFERENCES entries(key) ON DELETE CASCADE,
    position INTEGER NOT NULL,
    data BLOB NOT NULL,
    PRIMARY KEY (key, position)
);
CREATE TABLE IF NOT EXISTS projects (
    id TEXT PRIMARY KEY,
    name TEXT NOT NULL,
    image TEXT NOT NULL,
    kind TEXT NOT NULL,
    document TEXT NOT NULL,
    created REAL NOT NULL,
    updated REAL NOT NULL
);
CREATE INDEX IF NOT EXISTS projects_by_update ON projects (updated);
"""

#: The columns of a project's row, as the keys of the dicts the store returns.
_PROJECT_FIELDS = ("id", "name", "image", "kind", "created", "updated")


def data_folder() -> Path:
    """The user's data folder for shadeform: ``$XDG_DATA_HOME/shadeform`` (default
    ``~/.local/share/shadeform``) on Linux, ``~/Library/Application Support/shadeform`` on
    macOS, ``%LOCALAPPDATA%\\shadeform`` on Windows."""
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Application Support"
    else:
        base = Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share")
    return base / "shadeform"


class SessionStore:
    """Recipes for the entries the app's clients were given, in one SQLite file.

    Parameters
    ----------
    path : path-like
        The database file (its folder is created).
    max_bytes : int
        Most bytes of blobs kept; the least recently used entries go first (the one just put is
        always kept).
    max_projects, max_project_bytes : int
        Most projects, and most bytes of their documents, kept; the least recently updated go
        first (the one just saved is always kept).
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        max_bytes: int,
        max_projects: int = 200,
        max_project_bytes: int = 256 * 2**20,
    ) -> None:
        self.path = Path(path)
        self.max_bytes = int(max_bytes)
        self.max_projects = int(max_projects)
        self.max_project_bytes = int(max_project_bytes)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        #: What was done about a damaged file, in the user's words (logged once); None if nothing.
        self.notice: str | None = None
        try:
            self._open()
            damaged = self._db.execute("PRAGMA quick_check").fetchone()[0] != "ok"
        except sqlite3.DatabaseError as err:
            if not _corrupt(err, self.path):
                raise
            damaged = True
        if damaged:
            self._set_aside()

    def _open(self) -> None:
        # one connection, shared by the server's worker threads under a lock
        self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
        with self._lock:
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA foreign_keys=ON")
            self._db.executescript(_SCHEMA)

    def _set_aside(self) -> None:
        """The file is an SQLite database damaged past its header: rename it (with its WAL)
        aside, start a fresh one, copy into it what can still be read, and say so once."""
        with contextlib.suppress(AttributeError, sqlite3.Error):
            self._db.close()
        stamp = time.strftime("%Y%m%d-%H%M%S")
        aside = self.path.with_name(f"{self.path.name}.damaged-{stamp}")
        count = 1
        while aside.exists():  # never over an earlier one
            count += 1
            aside = self.path.with_name(f"{self.path.name}.damaged-{stamp}-{count}")
        for suffix in ("", "-wal", "-shm"):
            source = Path(f"{self.path}{suffix}")
            if source.exists():
                os.replace(source, f"{aside}{suffix}")
        self._open()
        entries, projects = self._salvage(aside)
        self.notice = (
            f"the sessions file {self.path} was damaged: kept what could still be read ({entries} "
            f"photo{'s' * (entries != 1)}, {projects} project{'s' * (projects != 1)}) in a fresh one, "
            f"and set the damaged file aside as {aside.name}"
        )
        logger.warning("%s", self.notice)

    def _salvage(self, aside: Path) -> tuple[int, int]:
        """Copy the entries whose files are whole, and the projects, readable in the damaged
        file ``aside`` into the fresh one; how many of each."""
        entries = projects = 0
        try:
            old = sqlite3.connect(f"{aside.as_uri()}?mode=ro", uri=True)
        except sqlite3.Error:
            return 0, 0
        try:
            for row in _readable(old, "SELECT key, kind, recipe, nbytes, used FROM entries"):
                try:
                    blobs = [
                        bytes(data)
                        for (data,) in old.execute(
                            "SELECT data FROM blobs WHERE key = ? ORDER BY position", (row[0],)
                        )
                    ]
                    json.loads(row[2])
                except (sqlite3.Error, ValueError):
                    continue
                if sum(len(blob) for blob in blobs) != row[3]:
                    continue  # a file lost in part
                with self._lock, self._db:
                    self._db.execute("BEGIN")
                    self._db.execute("INSERT OR REPLACE INTO entries VALUES (?, ?, ?, ?, ?)", row)
                    self._db.executemany(
                        "INSERT INTO blobs VALUES (?, ?, ?)",
                        [(row[0], i, sqlite3.Binary(b)) for i, b in enumerate(blobs)],
                    )
                entries += 1
            fields = "id, name, image, kind, document, created, updated"
            for row in _readable(old, f"SELECT {fields} FROM projects"):
                with self._lock:
                    self._db.execute(
                        f"INSERT OR REPLACE INTO projects ({fields}) VALUES (?, ?, ?, ?, ?, ?, ?)", row
                    )
                projects += 1
        finally:
            old.close()
        return entries, projects

    @property
    def journal_mode(self) -> str:
        with self._lock:
            return self._db.execute("PRAGMA journal_mode").fetchone()[0]

    def put(self, key: str, kind: str, recipe: dict, blobs: Sequence[bytes] = ()) -> None:
        """Keep how to make entry ``key`` again: its ``kind``, a JSON-able ``recipe`` and the
        files' bytes; then let the least recently used others go to fit :attr:`max_bytes`."""
        nbytes = sum(len(blob) for blob in blobs)
        with self._lock, self._db:
            self._db.execute("BEGIN")
            self._db.execute("DELETE FROM entries WHERE key = ?", (key,))
            self._db.execute(
                "INSERT INTO entries VALUES (?, ?, ?, ?, ?)",
                (key, kind, json.dumps(recipe), nbytes, time.time()),
            )
            self._db.executemany(
                "INSERT INTO blobs VALUES (?, ?, ?)",
                [(key, i, sqlite3.Binary(b)) for i, b in enumerate(blobs)],
            )
            total = self._db.execute("SELECT COALESCE(SUM(nbytes), 0) FROM entries").fetchone()[0]
            if total > self.max_bytes:
                for old, size in self._db.execute(
                    "SELECT key, nbytes FROM entries WHERE key != ? ORDER BY used", (key,)
                ).fetchall():
                    if total <= self.max_bytes:
                        break
                    self._db.execute("DELETE FROM entries WHERE key = ?", (old,))
                    total -= size

    def get(self, key: str) -> tuple[str, dict, list[bytes]] | None:
        """``(kind, recipe, blobs)`` of entry ``key`` (now the most recently used), or None."""
        with self._lock:
            row = self._db.execute("SELECT kind, recipe FROM entries WHERE key = ?", (key,)).fetchone()
            if row is None:
                return None
            self._db.execute("UPDATE entries SET used = ? WHERE key = ?", (time.time(), key))
            blobs = [
                bytes(data)
                for (data,) in self._db.execute(
                    "SELECT data FROM blobs WHERE key = ? ORDER BY position", (key,)
                ).fetchall()
            ]
        return row[0], json.loads(row[1]), blobs

    # --- projects ------------------------------------------------------------------------------

    def save_project(
        self, project_id: str, name: str, document: str | dict, *, image: str = "", kind: str = ""
    ) -> dict:
        """Keep (or replace) project ``project_id``: its ``name``, its ``document`` (JSON text, or
        a JSON-able dict) and, for listing without reading every document, what it is about
        (``image``) and its ``kind``; then let the least recently updated others go to fit
        :attr:`max_projects` and :attr:`max_project_bytes`. Returns the project's listing (as
        :meth:`list_projects`)."""
        text = document if isinstance(document, str) else json.dumps(document)
        now = time.time()
        with self._lock, self._db:
            self._db.execute("BEGIN")
            # created survives a save; updated never goes back (a clock set back keeps the order)
            self._db.execute(
                "INSERT INTO projects VALUES (?, ?, ?, ?, ?, ?, ?) ON CONFLICT (id) DO UPDATE SET "
                "name = excluded.name, image = excluded.image, kind = excluded.kind, "
                "document = excluded.document, updated = MAX(excluded.updated, projects.updated)",
                (project_id, name, image, kind, text, now, now),
            )
            newest = self._db.execute("SELECT MAX(updated) FROM projects WHERE id != ?", (project_id,))
            latest = newest.fetchone()[0]
            if latest is not None and latest >= now:  # same clock tick, or a clock set back
                self._db.execute("UPDATE projects SET updated = ? WHERE id = ?", (latest + 1e-6, project_id))
            self._bound_projects(project_id)
            row = self._db.execute(
                f"SELECT {', '.join(_PROJECT_FIELDS)} FROM projects WHERE id = ?", (project_id,)
            ).fetchone()
        return dict(zip(_PROJECT_FIELDS, row))

    def _bound_projects(self, keep: str) -> None:
        count, total = self._db.execute(
            "SELECT COUNT(*), COALESCE(SUM(LENGTH(document)), 0) FROM projects"
        ).fetchone()
        if count <= self.max_projects and total <= self.max_project_bytes:
            return
        for old, size in self._db.execute(
            "SELECT id, LENGTH(document) FROM projects WHERE id != ? ORDER BY updated", (keep,)
        ).fetchall():
            if count <= self.max_projects and total <= self.max_project_bytes:
                break
            self._db.execute("DELETE FROM projects WHERE id = ?", (old,))
            count, total = count - 1, total - size

    def get_project(self, project_id: str) -> dict | None:
        """Project ``project_id``: its listing (as :meth:`list_projects`) and ``document``, the
        JSON text as saved; None if the store does not have it."""
        with self._lock:
            row = self._db.execute(
                f"SELECT {', '.join(_PROJECT_FIELDS)}, document FROM projects WHERE id = ?",
                (project_id,),
            ).fetchone()
        return None if row is None else dict(zip((*_PROJECT_FIELDS, "document"), row))

    def list_projects(self) -> list[dict]:
        """Every project kept, the most recently updated first: dicts of ``id``, ``name``,
        ``image``, ``kind``, ``created`` and ``updated`` (seconds since the epoch)."""
        with self._lock:
            rows = self._db.execute(
                f"SELECT {', '.join(_PROJECT_FIELDS)} FROM projects ORDER BY updated DESC"
            ).fetchall()
        return [dict(zip(_PROJECT_FIELDS, row)) for row in rows]

    def delete_project(self, project_id: str) -> bool:
        """Forget project ``project_id``; whether the store had it."""
        with self._lock:
            return self._db.execute("DELETE FROM projects WHERE id = ?", (project_id,)).rowcount > 0

    def __len__(self) -> int:
        with self._lock:
            return self._db.execute("SELECT COUNT(*) FROM entries").fetchone()[0]

    def close(self) -> None:
        with self._lock:
            self._db.close()


def _corrupt(err: sqlite3.DatabaseError, path: Path) -> bool:
    """Whether ``err`` says that the SQLite database at ``path`` is damaged (not that it is
    locked, unreadable or not a database at all: a file that is not SQLite is never set aside)."""
    code = getattr(err, "sqlite_errorcode", None)
    if code is None or code & 0xFF not in (sqlite3.SQLITE_CORRUPT, sqlite3.SQLITE_NOTADB):
        return False
    try:
        with open(path, "rb") as file:
            return file.read(len(_SQLITE_HEADER)) == _SQLITE_HEADER
    except OSError:
        return False


def _readable(db: sqlite3.Connection, query: str):
    """The rows of ``query`` up to the first that cannot be read."""
    try:
        cursor = db.execute(query)
        while (row := cursor.fetchone()) is not None:
            yield row
    except sqlite3.DatabaseError:
        return
