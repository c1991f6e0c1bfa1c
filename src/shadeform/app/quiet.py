"""Python warnings from the libraries the server calls, kept off its console.

A library's warning (numpy's "divide by zero" in a solver, Pillow's "Corrupt EXIF data" on an
upload, ...) is about the library's internals: the user of the app can do nothing about it, and
printed raw it would repeat on the server's console with every request that meets it. While the
server runs (:func:`warnings_logged`, the app's lifespan; the solver process sets
:func:`log_warning` itself) each distinct warning is logged once, at DEBUG level, on this
module's logger: out of sight unless the server is started with debug logging. So are the
warnings python-multipart logs about each malformed upload. What the user must know is said by
the routes themselves, in their answers.

``warnings.catch_warnings`` cannot do this per request: it changes the interpreter's global
state, and the routes run in several threads at once.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import warnings
from collections.abc import Iterator

__all__ = ["log_warning", "warnings_logged"]

logger = logging.getLogger(__name__)

_seen: set[tuple] = set()
_seen_lock = threading.Lock()


def log_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A :func:`warnings.showwarning` that logs each warning (by category and place) once, at
    DEBUG level, and prints nothing."""
    key = (category, filename, lineno)
    with _seen_lock:
        if key in _seen:
            return
        _seen.add(key)
    logger.debug("a library warned (shown once): %s:%s: %s: %s", filename, lineno, category.__name__, message)


#: Libraries that log a malformed request's details as warnings (python-multipart: "Did not find
#: CR at end of boundary"): the client is told in its 400; the console hears only their errors.
_CHATTY_LOGGERS = ("python_multipart", "multipart")


@contextlib.contextmanager
def warnings_logged() -> Iterator[None]:
    """While inside, warnings go to :func:`log_warning` instead of stderr, and the libraries of
    :data:`_CHATTY_LOGGERS` log only their errors."""
    previous = warnings.showwarning
    warnings.showwarning = log_warning
    levels = {name: logging.getLogger(name).level for name in _CHATTY_LOGGERS}
    for name in _CHATTY_LOGGERS:
        logging.getLogger(name).setLevel(logging.ERROR)
    try:
        yield
    finally:
        if warnings.showwarning is log_warning:  # unless someone replaced it meanwhile
            warnings.showwarning = previous
        for name, level in levels.items():
            logging.getLogger(name).setLevel(level)
