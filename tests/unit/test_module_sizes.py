"""Modules stay small (STYLE §3): none of `mapapi/`, `mapctl/` or `mapbench/` is over
400 lines unless `docs/design.md` ("Modules over 400 lines", in "The house") names
it with the reason. The generated `_pb/` is not counted. The test also fails when a
listed module is back under the limit, so the list only shrinks.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LIMIT = 400
PACKAGES = ("mapapi", "mapctl", "mapbench")
_HEADING = "**Modules over 400 lines.**"
_ENTRY = re.compile(r"^- `((?:mapapi|mapctl|mapbench)/[\w/]+\.py)`: \S")


def documented() -> dict[str, str]:
    """Path -> the line of `docs/design.md` that justifies it."""
    text = (ROOT / "docs" / "design.md").read_text(encoding="utf-8")
    assert _HEADING in text, f"docs/design.md lost its list {_HEADING}"
    listed: dict[str, str] = {}
    for line in text.split(_HEADING, 1)[1].splitlines()[1:]:
        if not line.strip() and listed:
            break  # the list ends at the first blank line after its entries
        if match := _ENTRY.match(line):
            listed[match.group(1)] = line
    return listed


def sizes() -> dict[str, int]:
    """Path -> lines, for every module of the three packages but generated code."""
    return {
        path.relative_to(ROOT).as_posix(): len(path.read_text(encoding="utf-8").splitlines())
        for package in PACKAGES
        for path in sorted((ROOT / package).rglob("*.py"))
        if "_pb" not in path.relative_to(ROOT).parts
    }


def test_the_list_names_its_modules() -> None:
    assert documented(), "no entries under the heading (`- `path.py`: reason`)"


def test_no_module_is_over_the_limit_unless_justified() -> None:
    listed = documented()
    over = {p: n for p, n in sizes().items() if n > LIMIT and p not in listed}
    assert over == {}, (
        f"over {LIMIT} lines: split them (STYLE §3), or justify each in one line "
        f"under {_HEADING} in docs/design.md"
    )


def test_every_justified_module_is_still_over_the_limit() -> None:
    found = sizes()
    stale = sorted(p for p in documented() if found.get(p, 0) <= LIMIT)
    assert stale == [], "no longer over the limit (or gone): drop them from docs/design.md"
