"""g2o files whose ids are GTSAM `Symbol` keys: one mission per robot letter.

The DGS / distributed-mapper convention (`shared/datasets/README.md` §8) keeps
robot `n`'s part of a multi-robot graph in `<n>.g2o`; each id is a `Symbol`
key, the robot's letter (`a`, `b`, ...) in the top 8 bits of 64 and the pose's
index in the low 56, and an inter-robot edge appears in both robots' files.

A robotics user hands us either one such file or the folder, so we detect the
keys rather than ask for an option: a g2o file every vertex and edge end of
which is a `Symbol` key with a letter is read per robot, one mission per letter
(`{prefix}{letter}`, prefix `robot-` unless `--mission` gives one), indices the
low 56 bits. A plain graph (any id without a letter on top, as in
`fullGraph.g2o`) stays one mission, as before. The set's rules are those of
every multi-robot set (`mapapi.maps.robots`): an inter-robot edge is kept once,
by its source robot's mission. A folder's `<n>.g2o` files are read together;
one file alone imports the robots whose vertices it lists, with the edges they
are the source of (the other robots' files list the rest).

Rows keep each record's line but not its text: the text names 64-bit keys and
the row small indices, so export writes such a record from its values anyway.
Landmark records in a per-robot file are refused (their letters are not robots).
"""

from __future__ import annotations

import logging
import re
from collections.abc import Callable, Sequence
from pathlib import Path

from mapapi.core.errors import UsageError
from mapapi.maps.errors import MapImportError
from mapapi.maps.g2o import finish_graph, parse_g2o
from mapapi.maps.graph import MissionGraph, Origin
from mapapi.maps.robots import RobotMissions

log = logging.getLogger(__name__)

Progress = Callable[[int, int], None]  # (lines read, 0 while the total is unknown)

INDEX_BITS = 56
"""Bits of a `Symbol` key that hold the index; the 8 above hold the letter."""
DEFAULT_PREFIX = "robot-"
_ROBOT_FILE = re.compile(r"\d+\.g2o")


def symbol(key: int) -> tuple[str, int] | None:
    """(letter, index) of a GTSAM `Symbol` key; None for a plain id."""
    letter = key >> INDEX_BITS
    if not 0 < letter < 256 or not chr(letter).isascii() or not chr(letter).isalpha():
        return None
    return chr(letter), key & ((1 << INDEX_BITS) - 1)


def robot_files(folder: Path) -> list[Path]:
    """The `<n>.g2o` files of a DGS folder, by robot number."""
    found = [p for p in folder.iterdir() if _ROBOT_FILE.fullmatch(p.name)]
    return sorted(found, key=lambda p: int(p.stem))


def read_g2o_source(
    path: Path, mission: str | None, robot: str | None, progress: Progress | None = None
) -> list[MissionGraph]:
    """Read a g2o file, or a DGS folder of `<n>.g2o` files, as its missions: one
    for a plain graph, one per robot letter for `Symbol` keys.

    Args:
        mission: a plain graph's name (default: the file's); for robots, the
            prefix of each mission's name (default `robot-`).
        robot: the robot's name (a source of one mission only).

    Raises:
        MapImportError: a malformed line (named), a folder without `<n>.g2o`
            files or with a plain graph among them, or landmarks keyed by robot.
        UsageError: `robot` for a source of several missions.
    """
    files = robot_files(path) if path.is_dir() else [path]
    if not files:
        raise MapImportError("no <n>.g2o files (one per robot, DGS convention)", source=str(path))
    parsed, done = [], 0
    for file in files:
        shown = None if progress is None else _offset(progress, done)
        with file.open(encoding="utf-8") as lines:
            name = mission or file.stem
            graph = parse_g2o(
                lines, name, robot or "", source=str(file), progress=shown, finish=False
            )
        origins = [*graph.origins.values(), *(e.origin for e in graph.edges)]
        done += max((o.line for o in origins), default=0)
        parsed.append((graph, str(file)))
    if progress is not None:
        progress(done, done)
    if not path.is_dir() and not _symbol_keyed(parsed[0][0]):
        finish_graph(parsed[0][0], str(path))
        return [parsed[0][0]]
    graphs = per_robot(parsed, DEFAULT_PREFIX if mission is None else mission)
    if robot is not None:
        if len(graphs) != 1:
            raise UsageError(f"{path.name} holds {len(graphs)} robots' missions; drop --robot")
        graphs[0].robot = robot
    return graphs


def _offset(progress: Progress, before: int) -> Progress:
    """`progress` counting the lines of the files read before."""
    return lambda done, _: progress(before + done, 0)


def _symbol_keyed(graph: MissionGraph) -> bool:
    """True when every vertex and edge end of `graph` is a `Symbol` key."""
    keys = set(graph.vertices) | {e.source[1] for e in graph.edges}
    keys |= {e.target[1] for e in graph.edges}
    return bool(keys) and all(symbol(k) is not None for k in keys)


def per_robot(parsed: Sequence[tuple[MissionGraph, str]], prefix: str) -> list[MissionGraph]:
    """One mission per robot letter of the graphs `parse_g2o` read unfinished (with
    their files), for the robots whose vertices they list, by letter.

    Raises:
        MapImportError: a graph with a plain id or with landmarks.
    """
    missions: RobotMissions[str] = RobotMissions(lambda c: (f"{prefix}{c}", c))
    own: set[str] = set()
    for graph, source in parsed:
        if graph.landmarks or not _symbol_keyed(graph):
            raise MapImportError(
                "a per-robot g2o file must key every pose by robot letter (GTSAM Symbol) "
                "and hold no landmarks",
                source=source,
            )
        for key, pose in graph.vertices.items():
            letter, index = _split(key)
            own.add(letter)
            line = graph.origins[key].line
            if not missions.add_vertex(letter, index, pose, Origin(line)):
                log.debug(
                    "%s:%d: vertex %s%d placed already; first kept", source, line, *_split(key)
                )
        for edge in graph.edges:
            ends = (edge.source[1], edge.target[1])
            missions.add_edge(
                ends,
                _split(ends[0]),
                _split(ends[1]),
                edge.relative,
                edge.information,
                Origin(edge.origin.line),
            )
    graphs = missions.graphs(sorted(own))
    for graph in graphs:
        graph.planar = all(g.planar for g, _ in parsed)
    return graphs


def _split(key: int) -> tuple[str, int]:
    found = symbol(key)
    assert found is not None  # per_robot checked every key
    return found
