"""Every `mapctl` command with `--json` prints the shape docs/guide/scripting.md
documents for it (issue 15), and item data is plain JSON for scripts.

The commands come from the click tree, so a new command with `--json` and no
documented shape fails `test_every_json_command_has_a_documented_shape`. The
shapes come from the guide's "JSON shapes" section (written there as JSON), so
the page is what is checked. Each command runs on real repositories and real
peer daemons (tests/cli/json_scenario.py); the benchmarks and the demo start
peer processes of their own and are marked slow.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import click
import pytest

from mapapi.core.table import message_class
from mapctl.cli import cli
from tests.cli.json_scenario import (
    BENCHMARKS,
    Command,
    Outputs,
    run_benchmark,
    run_offline,
    run_secure,
    run_swarm,
)
from tests.multiproc.conftest import Daemons

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "guide" / "scripting.md"
HEADING = re.compile(r"^### `mapctl ([a-z][a-z -]*)`(?P<lines> \(one document per line\))?$")
HEX_ID = re.compile(r"[0-9a-f]{32}")


# -- the documented shapes -------------------------------------------------------------------
@dataclass
class Documented:
    """A command's documented output: one shape, or alternatives (one per block)."""

    shapes: list[Any] = field(default_factory=list)
    lines: bool = False  # one JSON document per line (else one document)


def documented_shapes(text: str) -> dict[Command, Documented]:
    """The "JSON shapes" section of the guide: command path -> its shapes."""
    section = text.split("\n## JSON shapes\n", 1)[1].split("\n## ", 1)[0]
    found: dict[Command, Documented] = {}
    current: Documented | None = None
    block: list[str] | None = None
    for line in section.splitlines():
        if block is not None:
            if line == "```":
                assert current is not None, "a json block before any command's heading"
                current.shapes.append(json.loads("\n".join(block)))
                block = None
            else:
                block.append(line)
        elif line == "```json":
            block = []
        elif heading := HEADING.match(line):
            current = found.setdefault(tuple(heading[1].split()), Documented())
            current.lines = heading["lines"] is not None
    return found


SHAPES = documented_shapes(GUIDE.read_text())


def json_commands(group: click.Group = cli, path: Command = ()) -> Iterator[Command]:
    """Every command of the click tree that has a `--json` option."""
    for name, command in sorted(group.commands.items()):
        if isinstance(command, click.Group):
            yield from json_commands(command, (*path, name))
        elif any(p.name == "as_json" for p in command.params):
            yield (*path, name)


JSON_COMMANDS = list(json_commands())


# -- the checker -----------------------------------------------------------------------------
def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


_TYPES = {
    "int": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "number": _is_number,
    "str": lambda v: isinstance(v, str),
    "bool": lambda v: isinstance(v, bool),
    "null": lambda v: v is None,
    "id": lambda v: isinstance(v, str) and HEX_ID.fullmatch(v) is not None,
    "box": lambda v: isinstance(v, list) and len(v) == 6 and all(map(_is_number, v)),
    "item": lambda v: True,
    "any": lambda v: True,
}


def _fits(value: Any, spec: str) -> bool:
    for each in spec.split("|"):
        if each.startswith("'"):
            if value == each.strip("'"):
                return True
        elif _TYPES[each](value):
            return True
    return False


def mismatches(value: Any, shape: Any, where: str = "$") -> list[str]:
    """How `value` differs from `shape` (see the guide's notation); [] if it fits."""
    if isinstance(shape, str):
        return [] if _fits(value, shape) else [f"{where}: {value!r:.60} is not {shape}"]
    if isinstance(shape, list):
        if not isinstance(value, list):
            return [f"{where}: {value!r:.60} is not a list"]
        return [m for i, v in enumerate(value) for m in mismatches(v, shape[0], f"{where}[{i}]")]
    if not isinstance(value, dict):
        return [f"{where}: {value!r:.60} is not an object"]
    if set(shape) == {"*"}:
        return [m for k, v in value.items() for m in mismatches(v, shape["*"], f"{where}.{k}")]
    keys = {k.removesuffix("?"): k for k in shape}
    found = [f"{where}: unexpected key {k!r}" for k in value if k not in keys]
    found += [f"{where}: no key {k!r}" for k, s in keys.items() if k not in value and k == s]
    for key, spec in keys.items():
        if key in value:
            found += mismatches(value[key], shape[spec], f"{where}.{key}")
    return found


def shape_errors(stdout: str, documented: Documented) -> list[str]:
    """How a command's stdout differs from its documented shape; [] if it fits."""
    texts = stdout.splitlines() if documented.lines else [stdout]
    assert texts, "no output"
    errors: list[str] = []
    for text in texts:
        value = json.loads(text)
        tries = [mismatches(value, shape) for shape in documented.shapes]
        if all(tries):
            closest: list[str] = min(tries, key=len)  # the alternative it nearly fits
            errors.extend(closest)
    return errors


# -- running the commands --------------------------------------------------------------------
@pytest.fixture(scope="module")
def outputs(tmp_path_factory: pytest.TempPathFactory) -> Outputs:
    """What every command but the benchmarks printed, on real repositories and peers."""
    root = tmp_path_factory.mktemp("json")
    out = Outputs()
    daemons = Daemons(root)
    try:
        repo = run_offline(out, root)
        run_secure(out, root)
        run_swarm(out, daemons, repo, root)
    finally:
        daemons.cleanup()
    return out


def _marks(path: Command) -> list[pytest.MarkDecorator]:
    return [pytest.mark.slow] if path in BENCHMARKS else []


@pytest.mark.parametrize(
    "path", [pytest.param(p, id=" ".join(p), marks=_marks(p)) for p in JSON_COMMANDS]
)
def test_output_has_the_documented_shape(
    path: Command, request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    assert path in SHAPES, f"`mapctl {' '.join(path)} --json` has no shape in {GUIDE.name}"
    if path in BENCHMARKS:
        out = Outputs()
        run_benchmark(out, path, tmp_path)
    else:
        out = request.getfixturevalue("outputs")
    runs = out.seen.get(path)
    assert runs, f"the scenario never ran `mapctl {' '.join(path)} --json`"
    for stdout in runs:
        assert shape_errors(stdout, SHAPES[path]) == [], stdout[:400]


def test_every_json_command_has_a_documented_shape() -> None:
    documented, commands = set(SHAPES), set(JSON_COMMANDS)
    assert commands - documented == set(), "commands with --json and no shape in the guide"
    assert documented - commands == set(), "shapes in the guide of commands with no --json"
    assert all(d.shapes for d in SHAPES.values()), "a heading with no ```json block"


# -- plain JSON: what issue 15 found -----------------------------------------------------------
def _first(out: Outputs, path: Command) -> Any:
    return json.loads(out.seen[path][0].splitlines()[0])


def test_a_counter_value_is_an_int(outputs: Outputs) -> None:
    got = [json.loads(s) for s in outputs.seen[("get",)]]
    assert {"name": "doors", "value": 2} in got
    assert all(type(g["value"]) is int for g in got if "value" in g)


def test_vertex_index_0_is_present_and_an_int(outputs: Outputs) -> None:
    listed = [json.loads(s)["items"] for s in outputs.seen[("ls",)]]
    vertices = [i["data"] for items in listed for i in items if "index" in i["data"]]
    assert vertices, "no ls of the vertices ran"
    first = next(v for v in vertices if v["index"] == 0)
    assert type(first["index"]) is int
    every_field = {f.name for f in message_class("mapapi.v1.Vertex").DESCRIPTOR.fields}
    assert set(first) == every_field  # defaults too


def test_query_bbox_lists_the_missions_and_named_holders(outputs: Outputs) -> None:
    offline, swarm = (json.loads(s)["results"] for s in outputs.seen[("query-bbox",)][:2])
    for results in (offline, swarm):
        vertices = next(r for r in results if r["table"] == "vertices")
        assert vertices["missions"] == ["intel"]
        assert all(h["name"] for r in results for h in r["holders"])
    assert {h["name"] for r in swarm for h in r["holders"]} == {"robot-a", "robot-b"}
    missions = next(r for r in swarm if r["table"] == "missions")
    assert missions["bbox"] == [-9.53713, -22.4756, 0.0, 15.8719, 3.37798, 0.0]  # unrounded


class TestChecker:
    """The checker itself: it must reject what it is there to catch."""

    @pytest.mark.parametrize(
        ("value", "shape"),
        [
            ({"value": "2"}, {"value": "int"}),  # an int64 as a string
            ({}, {"index": "int"}),  # a field at its default left out
            ({"index": 0, "x": 1}, {"index": "int"}),  # an undocumented key
            ({"a": True}, {"a": "int"}),  # a bool is no int
            ({"id": "ABC"}, {"id": "id"}),
            ([{"op": "upsert"}], [{"op": "'insert'|'update'"}]),
            ({"m": {"k": 1}}, {"m": {"*": "str"}}),
            ({"bbox": [0, 0, 0, 1, 1]}, {"bbox": "box"}),
        ],
    )
    def test_rejects(self, value: Any, shape: Any) -> None:
        assert mismatches(value, shape)

    @pytest.mark.parametrize(
        ("value", "shape"),
        [
            ({"n": 1, "x": None}, {"n": "number", "x": "int|null", "y?": "str"}),
            ({"m": {"a": "0" * 32}}, {"m": {"*": "id"}}),
            ([], ["int"]),
            ("anything", "item"),
        ],
    )
    def test_accepts(self, value: Any, shape: Any) -> None:
        assert mismatches(value, shape) == []

    def test_lines_are_checked_one_by_one(self) -> None:
        documented = Documented([{"n": "int"}], lines=True)
        assert shape_errors('{"n": 1}\n{"n": 2}\n', documented) == []
        assert shape_errors('{"n": 1}\n{"n": "2"}\n', documented)
