"""What a refusal on the command line looks like to a test."""

from __future__ import annotations


def refused(result, *words) -> None:
    """Assert that a CLI run refused in one stderr line, ``error: ...``, with exit code 2, and
    that the line holds each of ``words``."""
    assert result.exit_code == 2, result.output
    line = result.output.strip()
    assert "\n" not in line and line.startswith("error:") and all(w in line for w in words), line
