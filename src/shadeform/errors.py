"""The one exception type for user mistakes.

Everything a user can get wrong (a file that is not an image, a malformed regions file, a
reference pixel outside the object, ...) raises :class:`InputError` with a one-line message that
says what was wrong and what to do. The CLI turns it into that line and exit code 2; the server
turns it into an HTTP 4xx. Anything else escaping the library is a bug.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input from the user; ``str(err)`` is a one-line, actionable message."""
