"""`mapctl` imports only what `mapapi` exports (DESIGN §3, STYLE §1, §6).

The CLI is parse -> one call -> render over the public API, so it may import
`mapapi` itself (`from mapapi import X`, X in `mapapi.__all__`) and never a
submodule. It may also import `mapbench`, whose benchmarks and demo it runs.
Every import counts: inside functions, and for type checking only.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import mapapi

ROOT = Path(__file__).resolve().parents[2]
CLI_FILES = sorted((ROOT / "mapctl").rglob("*.py"))

ALLOWED: dict[tuple[str, str], str] = {}
"""(mapctl module, mapapi submodule) -> why it cannot go through `mapapi`; none now."""


def _module(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(source: str, module: str) -> Iterator[tuple[str, str, list[str]]]:
    """(module, imported module, names taken from it) for every import of mapapi in
    `source`, the text of `module`."""
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module.split(".")[0] == "mapapi":
                yield module, node.module, [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "mapapi":
                    yield module, alias.name, []


def _cli_imports() -> Iterator[tuple[str, str, list[str]]]:
    for path in CLI_FILES:
        yield from _imports(path.read_text(encoding="utf-8"), _module(path))


def test_mapctl_imports_no_mapapi_submodule() -> None:
    found = {(m, target) for m, target, _ in _cli_imports()}
    submodules = {(m, t) for m, t in found if t != "mapapi"}
    assert sorted(submodules - ALLOWED.keys()) == []
    assert sorted(ALLOWED.keys() - submodules) == [], "no longer needed: remove from the list"


def test_mapctl_takes_only_exported_names() -> None:
    exported = set(mapapi.__all__)
    taken = {(m, n) for m, target, names in _cli_imports() if target == "mapapi" for n in names}
    assert sorted((m, n) for m, n in taken if n not in exported) == []


def test_the_checker_sees_a_submodule_import() -> None:
    # A check that finds nothing proves nothing: imports inside functions count.
    code = "def f():\n    from mapapi.service.ops import Operations\n    import mapapi.sync\n"
    found = [(target, names) for _, target, names in _imports(code, "mapctl.sample")]
    assert found == [("mapapi.service.ops", ["Operations"]), ("mapapi.sync", [])]
