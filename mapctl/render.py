"""Every rich Console / Table / diff rendering call of `mapctl` lives here.

Humans get tables and a coloured side-by-side diff (added green, removed red,
conflict yellow); scripts get exact JSON with `--json`.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from typing import Any

from rich.console import Console
from rich.table import Table
from rich.text import Text

console = Console(highlight=False, soft_wrap=True)


def emit_json(value: Any) -> None:
    """Print exact JSON to stdout (one document)."""
    sys.stdout.write(json.dumps(value, indent=None, sort_keys=False) + "\n")


def line(text: str, style: str | None = None) -> None:
    """One line for humans."""
    console.print(Text(text, style=style or ""))


def table(
    title: str,
    columns: Sequence[str],
    rows: Iterable[Sequence[Any]],
    *,
    no_wrap: Iterable[str] = (),
) -> None:
    """A rich table; an empty listing says so instead of drawing nothing.

    Args:
        no_wrap: columns whose cells stay on one line (they may be cut with "…"
            on a narrow terminal rather than broken over lines).
    """
    rows = list(rows)
    if not rows:
        line(f"no {title}", "dim")
        return
    kept = set(no_wrap)
    grid = Table(title=title, title_justify="left")
    for column in columns:
        grid.add_column(column, no_wrap=column in kept)
    for row in rows:
        grid.add_row(*("" if v is None else str(v) for v in row))
    console.print(grid)


def records(title: str, rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> None:
    """A table of JSON records, one column per key in `columns`."""
    table(title, [c.replace("_", " ") for c in columns], [[r[c] for c in columns] for r in rows])


def size_text(count: int) -> str:
    """Bytes for humans: 512 B, 3.4 kB, 1.2 MB."""
    if count < 1000:
        return f"{count} B"
    units = ("kB", "MB", "GB")
    value, unit = count / 1000, 0
    while value >= 1000 and unit < len(units) - 1:
        value, unit = value / 1000, unit + 1
    return f"{value:.1f} {units[unit]}"


BOX_STEP = 0.1  # metres: what a person reading a box needs, not the float's 17 digits


def box_text(bbox: Sequence[float]) -> str:
    """A box (xmin, ymin, zmin, xmax, ymax, zmax) for humans, per axis, e.g.
    "x -300..-280 y 200..230 z 0..4.1": the min corner rounded down and the max
    corner up to 0.1 m, so the box shown contains the box stored."""
    low = [_step(v, math.floor) for v in bbox[:3]]
    high = [_step(v, math.ceil) for v in bbox[3:]]
    return " ".join(f"{axis} {lo}..{hi}" for axis, lo, hi in zip("xyz", low, high, strict=True))


def _step(value: float, to_int: Callable[[float], int]) -> str:
    # round() first: 0.3 / 0.1 is 2.9999999999999996, which floor would take to 0.2
    steps = to_int(round(value / BOX_STEP, 6))
    return f"{steps * BOX_STEP:.1f}".removesuffix(".0") if steps else "0"


def pretty_json(value: Any) -> None:
    """A JSON value, indented and coloured for humans."""
    from rich.json import JSON

    console.print(JSON(json.dumps(value)))


def _fields(value: Any) -> dict[str, Any]:
    if value is None:
        return {}
    if isinstance(value, dict):
        return value
    return {"(value)": value}


def _cell(value: Any) -> str:
    return "" if value is None else json.dumps(value)


def side_by_side(
    title: str, sides: dict[str, Any], *, conflict: bool = False, marker: str = ""
) -> None:
    """A field-by-field diff of 2 or 3 sides (base, ours[, theirs]).

    Fields that differ from the base are green where added or changed and red
    where removed; in a conflict, fields both sides changed differently are yellow.
    """
    names = list(sides)
    maps = {n: _fields(v) for n, v in sides.items()}
    keys = sorted(set().union(*(m.keys() for m in maps.values())))
    grid = Table(title=f"{title} {marker}".strip(), title_justify="left")
    grid.add_column("field")
    for name in names:
        absent = sides[name] is None
        grid.add_column(f"{name}{' (absent)' if absent else ''}")
    base = maps[names[0]]
    for key in keys:
        cells = [Text(key)]
        values = [maps[n].get(key) for n in names]
        clash = conflict and len(names) == 3 and values[1] != values[0] != values[2] != values[1]
        for i, value in enumerate(values):
            style = ""
            if i > 0 and value != base.get(key):
                style = "yellow" if clash else ("red" if key not in maps[names[i]] else "green")
            cells.append(Text(_cell(value), style=style))
        grid.add_row(*cells)
    console.print(grid)


def error(text: str) -> None:
    """A red line on stderr."""
    Console(stderr=True, highlight=False).print(Text(text, style="red"))


def warning(text: str) -> None:
    """A yellow line on stderr: something done, but not all that was asked."""
    Console(stderr=True, highlight=False, soft_wrap=True).print(Text(text, style="yellow"))


def note(text: str) -> None:
    """One line for humans on stderr (keeps stdout for what scripts read)."""
    Console(stderr=True, highlight=False, soft_wrap=True).print(Text(text, style="dim"))


@contextmanager
def transfer(text: str) -> Iterator[Callable[[int, int], None]]:
    """A spinner on stderr that becomes a progress bar once the work reports
    more than one part (nothing shown when stderr is no terminal).

    Yields:
        `show(done, total)`, to call with each progress report.
    """
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    console = Console(stderr=True, highlight=False)
    if not console.is_terminal:
        yield lambda done, total: None
        return
    progress = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        console=console,
        transient=True,
    )
    task = progress.add_task(text, total=None)

    def show(done: int, total: int) -> None:
        if total > 1:
            progress.update(task, completed=done, total=total)

    with progress:
        yield show


@contextmanager
def steps() -> Iterator[Callable[[str, str], None]]:
    """Progress of a command made of steps, on stderr: a spinner with the step
    running (on a terminal), a line per step done and a dim line per event.

    Yields:
        `show(kind, text)`: kind "step" (one begins), "done" (it ended) or "info".
    """
    console = Console(stderr=True, highlight=False, soft_wrap=True)
    status = console.status("") if console.is_terminal else None

    def show(kind: str, text: str) -> None:
        if kind == "step":
            if status is not None:
                status.update(Text(text + " ..."))
            else:
                console.print(Text(text + " ...", style="bold"))
        elif kind == "done":
            console.print(Text("✓ " + text, style="green"))
        else:
            console.print(Text("  " + text, style="dim"))

    if status is None:
        yield show
        return
    with status:
        yield show


@contextmanager
def chunk_transfers() -> Iterator[Callable[[str, int, int], None]]:
    """`transfer` bars for chunks fetched one after another (`clone`).

    Yields:
        `show(chunk, done, total)`: a chunk not seen before ends the bar of the
        previous one and begins its own.
    """
    with ExitStack() as stack:
        current: list[tuple[str, Callable[[int, int], None]]] = []

        def show(chunk: str, done: int, total: int) -> None:
            if not current or current[-1][0] != chunk:
                stack.close()
                bar = stack.enter_context(transfer(f"fetching chunk {chunk[:8]} with its history"))
                current[:] = [(chunk, bar)]
            current[-1][1](done, total)

        yield show


def cloned(address: str, info: dict[str, Any], peer_name: str, *, as_json: bool) -> None:
    """What `clone` made: its path, peer and chunks (`Cloned.to_json()`)."""
    if as_json:
        emit_json(info)
        return
    items = sum(c["items"] for c in info["chunks"])
    line(
        f"cloned {address} into {info['path']}: peer {peer_name} at {info['address']}, "
        f"{len(info['chunks'])} chunk(s), {items} item(s)",
        "green",
    )


def json_line(value: Any) -> None:
    """One JSON document on one line, flushed at once (a stream scripts read)."""
    sys.stdout.write(json.dumps(value) + "\n")
    sys.stdout.flush()


class ChangeRows:
    """Changes `watch` reports, as rows of a table that grows as they come."""

    def __init__(self) -> None:
        self.header_done = False

    def add(self, change: dict[str, Any]) -> None:
        """Print one change (the header with the first)."""
        grid = Table(show_header=not self.header_done, box=None, pad_edge=False)
        for name, width in (("time", 6), ("commit", 8), ("kind", 8), ("table", 10), ("id", 8)):
            grid.add_column(name, width=width, no_wrap=True)
        grid.add_column("data", overflow="fold")
        data = "-" if change["data"] is None else json.dumps(change["data"], sort_keys=True)
        grid.add_row(
            str(change["time"]),
            change["commit"][:8],
            change["kind"],
            change["table"],
            change["id"][:8],
            data,
        )
        console.print(grid)
        self.header_done = True


def fsck_report(report: dict[str, Any]) -> None:
    """`mapctl fsck`: what was checked, then each problem found, in red."""
    payloads, chains = report["payloads"], report["chains"]
    line(
        f"{report['store']}: file {'sound' if not report['integrity'] else 'DAMAGED'}, "
        f"{payloads['checked']} payload(s), {chains['checked']} chain(s) checked"
    )
    for problem in [
        *report["integrity"],
        *payloads["bad"],
        *chains["problems"],
        *report["rollback"]["problems"],
        *(d["detail"] for d in report["diverged"]),
    ]:
        line(f"  {problem}", "red")
    line("no problem found" if report["ok"] else "problems found: see above", "bold")


def history_warnings(info: dict[str, Any]) -> None:
    """`mapctl peer status`: a chunk whose history differs from another holder's,
    or a store behind its high-water mark, one red line each (issue 18 §3)."""
    for problem in [*(d["detail"] for d in info["diverged"]), *info["rollback"]]:
        line(f"  {problem}", "red")


def measures(title: str, result: dict[str, Any], as_json: bool) -> None:
    """A benchmark's figures: JSON for scripts, else a table of its flat measures."""
    if as_json:
        emit_json(result)
        return
    rows = [(k, v) for k, v in result.items() if not isinstance(v, dict | list)]
    table(title, ["measure", "value"], rows)


def staleness(replicas: dict[str, Any]) -> str:
    """What a stale view's answer says about how old this peer's replicas may be."""
    silent = replicas["leaders_silent_s"]
    if silent is None:
        return "stale: the replicas here are all this peer knows (it is in no swarm)"
    if silent == 0:
        return "stale: read without asking; this peer leads every chunk it holds"
    return (
        f"stale: read without asking the chunks' leaders; the longest silent spoke here "
        f"{silent:g} s ago (newer commits may exist elsewhere)"
    )
