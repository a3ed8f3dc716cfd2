"""The host level and the process level meet only through coco_core.levels (issue 38): neither
package imports the other, in any import statement (a TYPE_CHECKING block or a function's included).
Read from the source with ast, so that a shortcut from one level into the other fails here."""

from __future__ import annotations

import ast
from pathlib import Path

import coco_core

PACKAGE = Path(coco_core.__file__).parent


def imported(path: Path) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in the module at ``path``, relative ones
    resolved against the module's own package."""
    own = ["coco_core", *path.relative_to(PACKAGE).parent.parts]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = own[:len(own) - node.level + 1] if node.level else []
            module = ".".join([*base, *([node.module] if node.module else [])])
            found += [(node.lineno, f"{module}.{alias.name}") for alias in node.names]
    return found


def crossings(level: str, other: str) -> list[str]:
    """Where a module of ``coco_core.<level>`` imports from ``coco_core.<other>``."""
    prefix = f"coco_core.{other}."
    return [f"{path.relative_to(PACKAGE)}:{line}: {name}"
            for path in sorted((PACKAGE / level).glob("*.py"))
            for line, name in imported(path) if name.startswith(prefix)]


def test_the_reader_resolves_relative_imports() -> None:
    """The check's own reader: a relative import of the other level is found (were it not, the
    tests below could not fail)."""
    names = [name for _, name in imported(PACKAGE / "processes" / "child.py")]
    assert "coco_core.processes.remote.call_over" in names
    assert "coco_core.levels.Ends" in names


def test_the_host_level_imports_nothing_of_the_process_level() -> None:
    assert crossings("hosts", "processes") == []


def test_the_process_level_imports_nothing_of_the_host_level() -> None:
    assert crossings("processes", "hosts") == []
