"""The library's layers (DESIGN §3): imports point down, never in a circle.

core <- store <- net <- lookup <- swarm <- service <- maps; the modules at the
top of `mapapi/` (the public API: `__init__`, `sync`, `testing`, ...) may import
any layer, and no layer imports them; nothing in `mapapi` imports `mapctl` or
`mapbench`. Imports inside functions count (they still tie modules together);
imports only for type checking (`if TYPE_CHECKING:`) do not.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LAYERS = ("core", "store", "net", "lookup", "swarm", "service", "maps")

ALLOWED_UPWARD: dict[tuple[str, str], str] = {}
"""Known upward imports, each with why it is still there; the test fails when one
is no longer needed, so the list only shrinks (empty since the application's
composition moved to `mapapi/app.py`)."""


def _module(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {
    _module(p): p
    for p in sorted((ROOT / "mapapi").rglob("*.py"))
    if "_pb" not in p.relative_to(ROOT).parts
}


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    hidden: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            hidden.update(id(sub) for stmt in node.body for sub in ast.walk(stmt))
    return hidden


def imports_of(module: str) -> set[str]:
    """The modules `module` imports at run time (a name imported from a package
    counts as the submodule when there is one)."""
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    hidden = _type_checking_nodes(tree)
    found: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in hidden:
            continue
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for alias in node.names:
                sub = f"{node.module}.{alias.name}"
                found.add(sub if sub in MODULES else node.module)
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
    return {m for m in found if m.split(".")[0] in ("mapapi", "mapctl", "mapbench")}


def layer(module: str) -> int | None:
    """The layer's rank, or None for the public API at the top of `mapapi/`; the
    generated schema code (`_pb`) lies under every layer."""
    parts = module.split(".")
    if len(parts) > 1 and parts[1] == "_pb":
        return -1
    return LAYERS.index(parts[1]) if len(parts) > 1 and parts[1] in LAYERS else None


def _wrong_imports() -> Iterator[tuple[str, str]]:
    for module in MODULES:
        rank = layer(module)
        for target in imports_of(module):
            if target.split(".")[0] != "mapapi":
                yield module, target  # the library never imports its tools
                continue
            if rank is None:
                continue  # the public API may import any layer
            other = layer(target)
            if other is None or other > rank:
                yield module, target


def test_imports_point_down_only() -> None:
    wrong = set(_wrong_imports())
    assert sorted(wrong - ALLOWED_UPWARD.keys()) == []
    assert sorted(ALLOWED_UPWARD.keys() - wrong) == [], "no longer needed: remove from the list"


def _circles() -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    graph = {m: {t for t in imports_of(m) if t in MODULES and t != "mapapi"} for m in MODULES}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for nxt in graph[node]:
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in graph:
        if node not in index:
            visit(node)
    return found


def test_no_module_imports_itself_through_others() -> None:
    assert _circles() == []


def test_the_checker_sees_an_upward_import() -> None:
    # A check that finds nothing proves nothing: the maps layer sits above core.
    assert layer("mapapi.maps.graph") > layer("mapapi.core.ids")  # type: ignore[operator]
    assert "mapapi.core.errors" in imports_of("mapapi.maps.plot")


def test_the_core_is_pure() -> None:
    """No core module drives I/O: asyncio and zmq stay out (DESIGN §3)."""
    impure = {}
    for module, path in MODULES.items():
        if not module.startswith("mapapi.core."):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        names |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        found = {n for n in names if n.split(".")[0] in ("asyncio", "zmq")}
        if found:
            impure[module] = sorted(found)
    assert impure == {}
