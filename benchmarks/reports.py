"""What every benchmark does last: its report written atomically where the results live, and printed."""

from __future__ import annotations

from pathlib import Path

from shadeform.io.atomic import atomic_write


def publish(lines: list[str], path: str | Path) -> str:
    """Write ``lines`` (one Markdown report) to ``path`` atomically, its folder made if need be,
    print it, and return its text."""
    text = "\n".join(lines) + "\n"
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path, mode="w") as handle:
        handle.write(text)
    print(text)
    return text
