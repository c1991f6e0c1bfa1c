"""The house rules that a linter does not keep: file sizes, the web client's import graph,
docs/architecture.md naming every module that exists (and none that does not), and test modules
that import no other.

The Python layers and cycles are kept by import-linter's contracts (``.importlinter``, run by
``make lint``); the web client has no such tool here, so its graph is read from the sources.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "shadeform"
WEB = ROOT / "web" / "src"
ARCHITECTURE = ROOT / "docs" / "architecture.md"

#: The house limits (docs/architecture.md, "Habits").
MAX_MODULE_LINES = 600
MAX_WEB_LINES = 700
GENERATED_WEB = {"api.gen.ts"}


def _lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())


def test_no_python_module_is_over_the_limit():
    modules = sorted(SRC.rglob("*.py"))
    assert len(modules) > 50  # the walk found the package
    over = {str(p.relative_to(SRC)): _lines(p) for p in modules if _lines(p) > MAX_MODULE_LINES}
    assert over == {}


def test_no_web_file_is_over_the_limit():
    files = sorted(WEB.glob("*.ts"))
    assert len(files) > 20
    over = {p.name: _lines(p) for p in files if p.name not in GENERATED_WEB and _lines(p) > MAX_WEB_LINES}
    assert over == {}


_WEB_IMPORT = re.compile(
    r"""(?:^|\n)\s*(?:import|export)\b[^'"]*?\bfrom\s*['"]\./([\w.]+?)(?:\.ts|\.js)?['"]"""
)


def web_imports(text: str) -> set[str]:
    """The sibling modules one web source imports or re-exports from (``from './x'``)."""
    return set(_WEB_IMPORT.findall(text))


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle in ``graph`` (module -> modules it imports), or None; depth-first."""
    state: dict[str, int] = {}  # 1: on the current path, 2: finished
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt) :] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_the_cycle_finder_finds_a_cycle_and_only_one_that_exists():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert web_imports("import { x } from './api';\nexport { y } from \"./decode.ts\";\n") == {
        "api",
        "decode",
    }
    assert web_imports("import * as THREE from 'three';") == set()


def test_the_web_client_has_no_import_cycle():
    graph = {p.stem: web_imports(p.read_text(encoding="utf-8")) for p in WEB.glob("*.ts")}
    assert sum(len(v) for v in graph.values()) > 50  # the imports were read
    unknown = {(a, b) for a, bs in graph.items() for b in bs if b not in graph}
    assert unknown == set()
    assert find_cycle(graph) is None


def _modules() -> set[str]:
    """Every module and package of src/shadeform as docs/architecture.md names it: a package as
    ``name/``, a module as ``name.py`` (both relative to the package that holds them)."""
    names = set()
    for path in SRC.rglob("*.py"):
        if "static" in path.parts or path.name in {"__init__.py", "__main__.py"}:
            continue
        names.add(path.name)
    for path in SRC.rglob("__init__.py"):
        if path.parent != SRC:
            names.add(path.parent.name + "/")
    return names


def test_architecture_names_every_module_and_no_missing_one():
    text = ARCHITECTURE.read_text(encoding="utf-8")
    # a path names its last part (`solvers/photo/` names the package `photo/`)
    paths = re.findall(r"`([\w/]+(?:\.py|/))`", text)
    named = {re.search(r"\w+(?:\.py|/)$", p).group() for p in paths}
    named |= {f"{m}.py" for m in re.findall(r"`(\w+)`", text)}
    modules = _modules()
    missing = sorted(m for m in modules if m not in named and m.rstrip("/") + ".py" not in named)
    assert missing == []
    # every module the table names exists in the package
    table = text[text.index("## Where each concern lives") :].split("\n\n")[1]
    paths = set(re.findall(r"`((?:\w+/)*\w+\.py)`", table))
    assert len(paths) > 100
    stale = sorted(p for p in paths if not list(SRC.rglob(Path(p).name)))
    assert stale == []


def test_the_moved_photo_set_reader_is_still_reachable_from_io_with_a_warning():
    import pytest

    from shadeform import photoset

    with pytest.warns(DeprecationWarning, match="shadeform.photoset.load_photo_set"):
        from shadeform.io.photoset import load_photo_set
    assert load_photo_set is photoset.load_photo_set
    with pytest.raises(ImportError, match="no_such_name"):
        from shadeform.io.photoset import no_such_name  # noqa: F401


def test_no_test_module_imports_another():
    """Shared test code lives in ``tests/helpers/`` (and fixtures in ``tests/conftest.py``): a test
    module, the conftest or a helper importing a test module (or the conftest) would run that
    module's import-time work and tie the two together."""
    import ast

    tests = ROOT / "tests"
    found = []
    for path in sorted([*tests.glob("*.py"), *(tests / "helpers").glob("*.py")]):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            else:
                continue
            for name in names:
                parts = name.split(".")
                first = parts[1] if parts[0] == "tests" and len(parts) > 1 else parts[0]
                if first.startswith("test_") or first in ("conftest", "_surfaces"):
                    found.append(f"{path.relative_to(tests)}:{node.lineno} imports {name}")
    assert len(list(tests.glob("test_*.py"))) > 50  # the walk found the tests
    assert found == []
