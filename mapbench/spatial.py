"""`mapctl bench spatial`: spatial-index query cost against the number of grid
cells (the Map API paper, Cieslewski et al., ICRA 2015, Fig. 8).

The missions are real: each robot of the 8-robot tunnels set is one mission,
and the parking-garage trajectory is cut into consecutive segments of
`SEGMENT` vertices, one mission each, as the paper's Fig. 8 data set held many
missions; a g2o file given by path is a data set of its own missions. Each
mission is registered by a random node as an import places it: its row under
the mission's box, and each of its spatial tiles (`mapapi.maps.tiles`) under
the tile's box (`mapbench.spatial_tiles`). A query then reports, besides the
missions found, the tiles found and the rows and bytes loading them moves
(`query-bbox --load`: the missions' rows and the tiles found), against the rows
and bytes of the whole missions found. The grid covers the data's extent (plus a small margin) in
``n x n`` cells over the two horizontal axes; the vertical axis, the one of
smallest extent, stays undivided (DESIGN §7: ground robots' missions span all
their floors). The garage is z-up, but the tunnels set is in a camera frame,
y down, so there y is the undivided axis.

On one still ring of N `ChordNode`s in this process (`mapbench.ring`),
every grid is registered first, without added latency. Then a fixed, seeded
set of query boxes, each `BOX_FRACTION` of the extent along both horizontal
axes and spanning all of the vertical one, is asked from seeded random nodes,
once with the exact filter at each cell's owner and once without (every entry
of the asked cells travels and is filtered at the asker), for each cell count
and each added one-way link latency (`mapapi.net.shaping`). Both modes must
find the same missions: `check_spatial` turns a difference into an error.
`requests` are the Chord requests the asking node sends (lookup hops and
gets; a step the asker answers from its own tables costs none), `returned_*`
the entries that travel back, counted once per asked cell: a mission whose box
spans several of them comes back from each.

Nothing here asserts a speed; the figures go to docs/benchmarks.md.
"""

from __future__ import annotations

import asyncio
import logging
import math
import random
import statistics
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mapapi.core.errors import MapError, UsageError
from mapapi.core.ids import ChunkId, PeerId
from mapapi.lookup.dht.chord import ChordNode
from mapapi.lookup.spatial import BBox, SpatialGrid
from mapapi.lookup.spatial_index import QueryStats, SpatialIndex, SpatialRef
from mapapi.maps import read_g2o, read_kimera
from mapapi.net import LinkShape, Shaper
from mapbench.ring import still_ring
from mapbench.spatial_tiles import MissionPart, Moved, TilePart, mission_part, pose_boxes, segments

log = logging.getLogger(__name__)

SAMPLES = Path(__file__).resolve().parents[1] / "sample_maps"
"""The source tree's sample maps (`sample_maps/README.md`)."""

DATASETS = ("parking-garage", "tunnels")
"""The data sets `load_dataset` knows."""

CELLS = (1, 4, 16, 64, 256, 1024, 4096)
"""Cell counts of `mapctl bench spatial` (``n x n`` horizontal cells, n = 1..64)."""

LATENCIES_MS = (0.0, 5.0, 20.0)
"""Added one-way link latencies of `mapctl bench spatial`, in milliseconds."""

DEFAULT_PEERS = 16
DEFAULT_QUERIES = 20
"""Queries per row. The 20 ms rows dominate the run (a query's cells are asked
32 at a time, each a lookup and a get of several 40 ms round trips), so with
registration the default run stays under ~3 minutes on 2 cores."""

BOX_FRACTION = 0.1
"""A query box's side as a fraction of the data's horizontal extent."""

SEGMENT = 100
"""Parking-garage vertices per mission: its 1,661 poses give 17 missions."""

_MARGIN = 0.02  # of each side, so no mission lies on the bounds' faces
_MIN_PAD = 0.5  # metres: the least margin, for an axis the data does not spread on
_TTL = 24 * 3600.0  # seconds; no entry may expire during a run
_INDEX = "bench"


class SpatialCheckFailed(MapError):
    """Queries with and without exact filtering found different missions."""


@dataclass(frozen=True)
class Dataset:
    """The missions of one real map, each with its box and tiles.

    Attributes:
        name: one of `DATASETS`, or a g2o file's stem.
        parts: mission name -> the mission as registered.
    """

    name: str
    parts: dict[str, MissionPart]

    @property
    def missions(self) -> dict[str, BBox]:
        """Mission name -> the box around its vertices."""
        return {name: part.bbox for name, part in self.parts.items()}

    @property
    def tiles(self) -> list[TilePart]:
        """Every mission's tiles."""
        return [tile for part in self.parts.values() for tile in part.tiles]

    @property
    def extent(self) -> BBox:
        """The box around every mission."""
        return BBox.enclosing(self.missions.values())

    @property
    def vertical(self) -> int:
        """The axis (0, 1, 2 for x, y, z) of smallest extent, taken as vertical:
        the grid does not divide it and query boxes span all of it."""
        sides = [hi - lo for lo, hi in zip(self.extent.mins, self.extent.maxs, strict=True)]
        return sides.index(min(sides))


def load_dataset(name: str, samples: Path = SAMPLES) -> Dataset:
    """The missions of data set `name` (read from the `samples` folder), or of
    the g2o file at path `name`.

    Raises:
        UsageError: `name` is not one of `DATASETS` nor a g2o file.
        MapImportError: a file is missing or malformed.
    """
    if name == "parking-garage":
        garage = read_g2o(samples / "pose_graphs" / "parking-garage.g2o")
        graphs = segments(garage, SEGMENT)
    elif name == "tunnels":
        graphs = read_kimera(samples / "kimera_multi_tunnels_8robots")
    elif name.endswith(".g2o") and Path(name).is_file():
        graphs = [read_g2o(Path(name))]
        name = Path(name).stem
    else:
        raise UsageError(
            f"no data set {name!r}; choose one of {', '.join(DATASETS)} or a .g2o file"
        )
    parts = (mission_part(graph) for graph in graphs)
    return Dataset(name, {part.name: part for part in parts if part is not None})


def grid_for(dataset: Dataset, cells: int) -> SpatialGrid:
    """The index grid of `cells` cells (a square number) over `dataset`'s extent
    plus a margin: ``n x n`` over the horizontal axes, 1 along the vertical.

    Raises:
        UsageError: `cells` is not a positive square number.
    """
    side = math.isqrt(cells) if cells > 0 else 0
    if side < 1 or side * side != cells:
        raise UsageError(f"{cells} cells are not n x n; use a square number such as 64")
    extent = dataset.extent
    # a flat map (a 2D graph: z = 0) still needs a positive extent on its vertical axis
    pad = [
        max(_MARGIN * (hi - lo), _MIN_PAD) for lo, hi in zip(extent.mins, extent.maxs, strict=True)
    ]
    lows = [lo - p for lo, p in zip(extent.mins, pad, strict=True)]
    highs = [hi + p for hi, p in zip(extent.maxs, pad, strict=True)]
    counts = [side, side, side]
    counts[dataset.vertical] = 1
    return SpatialGrid(BBox(*lows, *highs), (counts[0], counts[1], counts[2]))


def query_boxes(
    dataset: Dataset, count: int, *, seed: int = 0, fraction: float = BOX_FRACTION
) -> list[BBox]:
    """`count` seeded random boxes inside `dataset`'s extent, `fraction` of it
    along each horizontal axis and all of it along the vertical one.

    Raises:
        ValueError: `fraction` is not in (0, 1].
    """
    if not 0 < fraction <= 1:
        raise ValueError(f"a box fraction is in (0, 1], got {fraction}")
    rng = random.Random(f"{seed}:boxes")  # its own stream: the ring's ids do not shift it
    extent = dataset.extent
    boxes = []
    for _ in range(count):
        lows, highs = list(extent.mins), list(extent.maxs)
        for axis in {0, 1, 2} - {dataset.vertical}:
            size = fraction * (highs[axis] - lows[axis])
            lows[axis] = rng.uniform(lows[axis], highs[axis] - size)
            highs[axis] = lows[axis] + size
        boxes.append(BBox(*lows, *highs))
    return boxes


def measure_spatial(
    dataset: str,
    *,
    cells: Sequence[int] = CELLS,
    latencies_ms: Sequence[float] = LATENCIES_MS,
    peers: int = DEFAULT_PEERS,
    queries: int = DEFAULT_QUERIES,
    seed: int = 0,
    fraction: float = BOX_FRACTION,
    samples: Path = SAMPLES,
    around_poses: bool = False,
) -> list[dict[str, Any]]:
    """Register `dataset`'s missions in a ring of `peers` nodes under every grid of
    `cells`, then time `queries` queries for each cell count and latency.

    Args:
        dataset: one of `DATASETS`.
        cells: cell counts, each a square number (``n x n`` cells).
        latencies_ms: added one-way latency of every link, in milliseconds.
        peers: nodes on the ring.
        queries: query boxes (`query_boxes`), each asked from a random node.
        seed: seeds the node ids, the holders, the boxes and the asking nodes.
        fraction: a query box's side as a fraction of the extent; with
            `around_poses`, the share of the poses a box holds.
        samples: the folder holding the sample maps.
        around_poses: boxes around random poses, each holding `fraction` of
            the poses (`pose_boxes`), instead of boxes of a fixed size.

    Returns:
        One JSON-ready row per (cell count, latency), in that order: dataset,
        cells, latency_ms, peers, missions, tiles, queries, and per query on
        average: cells_asked, query_ms and query_ms_all (with and without exact
        filtering), requests (Chord requests sent by the asker), returned_exact
        and returned_all (entries that travelled back), matches (missions
        found), tiles_found, rows_moved and bytes_moved (what loading the
        missions' rows and the tiles found moves), rows_whole and bytes_whole
        (what loading the whole missions found would); then mismatches, the
        queries whose chunks differed between the modes (see `check_spatial`).

    Raises:
        UsageError: an unknown data set or a cell count that is not square.
        ValueError: fewer than 1 peer or query, or a bad fraction or latency.
        RingNotStable: the ring did not converge (a Chord bug).
    """
    if peers < 1 or queries < 1:
        raise ValueError(f"need at least 1 peer and 1 query, got {peers} and {queries}")
    shapes = [LinkShape(latency=ms / 1e3) for ms in latencies_ms]  # ValueError if negative
    data = load_dataset(dataset, samples)
    grids = [grid_for(data, count) for count in cells]
    if around_poses:
        boxes = pose_boxes(data.parts, data.extent, data.vertical, queries, fraction, seed)
    else:
        boxes = query_boxes(data, queries, seed=seed, fraction=fraction)
    return asyncio.run(_measure(data, grids, shapes, peers, boxes, random.Random(seed)))


def check_spatial(rows: Sequence[dict[str, Any]]) -> None:
    """Fail when a query found other missions with exact filtering than without.

    Raises:
        SpatialCheckFailed: some row counts mismatches.
    """
    bad = [r for r in rows if r["mismatches"]]
    if bad:
        where = ", ".join(f"{r['dataset']} {r['cells']} cells {r['latency_ms']} ms" for r in bad)
        raise SpatialCheckFailed(
            f"queries found different missions with and without exact filtering ({where}): "
            "a spatial index bug; reproduce with tests/net/test_bench_spatial.py"
        )


@dataclass(frozen=True)
class _Plan:
    """The fixed queries of every row: the boxes and the nodes that ask them."""

    boxes: list[BBox]
    askers: list[int]


async def _measure(
    data: Dataset,
    grids: Sequence[SpatialGrid],
    shapes: Sequence[LinkShape],
    peers: int,
    boxes: list[BBox],
    rng: random.Random,
) -> list[dict[str, Any]]:
    shapers: list[Shaper] = []

    def shaper() -> Shaper:
        # kept, so the latency can be set after registering without it
        shapers.append(Shaper())
        return shapers[-1]

    rows = []
    async with still_ring(peers, rng, shaper=shaper) as nodes:
        indexes = [[SpatialIndex(node, grid, _INDEX) for node in nodes] for grid in grids]
        started = time.perf_counter()
        await _register(data, indexes, rng)
        await _connect(nodes)
        log.info("%s registered in %.1f s", data.name, time.perf_counter() - started)
        plan = _Plan(boxes, [rng.randrange(peers) for _ in boxes])
        for index in indexes:
            for shape in shapes:
                for each in shapers:
                    each.default = shape
                rows.append(await _row(data, index, shape, plan))
    return rows


async def _register(data: Dataset, indexes: list[list[SpatialIndex]], rng: random.Random) -> None:
    """Register every mission's row and tiles, held by a random node, in every grid."""
    for mission, part in data.parts.items():
        holder = rng.randrange(len(indexes[0]))
        peer = PeerId(f"{rng.getrandbits(128):032x}")
        held = ((peer, indexes[0][holder].chord.me.address),)
        refs = [SpatialRef(part.chunk, "missions", part.bbox, (mission,), held)]
        refs += [SpatialRef(t.chunk, "vertices", t.bbox, (mission,), held) for t in part.tiles]
        for ref in refs:
            await asyncio.gather(*(index[holder].register(ref, _TTL) for index in indexes))


async def _connect(nodes: Sequence[ChordNode]) -> None:
    """Have every node ask every other once, so that no timed query pays for
    opening a zmq connection (a node owns its own key)."""
    for node in nodes:
        await asyncio.gather(*(node.get(other.key) for other in nodes if other is not node))


async def _row(
    data: Dataset, index: Sequence[SpatialIndex], shape: LinkShape, plan: _Plan
) -> dict[str, Any]:
    """Ask every query of `plan` in both modes: the means per query, and the
    number of queries whose missions differed between the modes."""
    exact: list[tuple[float, QueryStats]] = []
    every: list[tuple[float, QueryStats]] = []
    moved: list[Moved] = []
    mismatches = 0
    for box, asker in zip(plan.boxes, plan.askers, strict=True):
        found, timed = await _timed_query(index[asker], box, exact_at_owner=True)
        found_all, timed_all = await _timed_query(index[asker], box, exact_at_owner=False)
        exact.append(timed)
        every.append(timed_all)
        moved.append(Moved.of(data.parts, found))
        if found != found_all:
            mismatches += 1
            log.warning("query %s: %s with exact filtering, %s without", box, found, found_all)
    return {
        "dataset": data.name,
        "cells": index[0].grid.cell_count,
        "latency_ms": round(shape.latency * 1e3, 3),
        "peers": len(index),
        "missions": len(data.missions),
        "tiles": len(data.tiles),
        "queries": len(plan.boxes),
        "cells_asked": _mean(s.cells for _, s in exact),
        "query_ms": _mean(ms for ms, _ in exact),
        "query_ms_all": _mean(ms for ms, _ in every),
        "requests": _mean(s.requests for _, s in exact),
        "returned_exact": _mean(s.transferred for _, s in exact),
        "returned_all": _mean(s.transferred for _, s in every),
        "matches": _mean(len(m.missions) for m in moved),
        "tiles_found": _mean(m.tiles for m in moved),
        "rows_moved": _mean(m.rows for m in moved),
        "bytes_moved": _mean(m.bytes for m in moved),
        "rows_whole": _mean(m.rows_whole for m in moved),
        "bytes_whole": _mean(m.bytes_whole for m in moved),
        "share_moved": _mean(m.share for m in moved),
        "share_moved_max": max(m.share for m in moved),
        "mismatches": mismatches,
    }


async def _timed_query(
    index: SpatialIndex, box: BBox, *, exact_at_owner: bool
) -> tuple[set[ChunkId], tuple[float, QueryStats]]:
    """The chunks (mission rows and tiles) one query finds, its wall time in ms
    and its stats."""
    stats = QueryStats()
    began = time.perf_counter()
    refs = await index.query(box, exact_at_owner=exact_at_owner, stats=stats)
    elapsed = (time.perf_counter() - began) * 1e3
    return {ref.chunk for ref in refs}, (elapsed, stats)


def _mean(values: Iterable[float]) -> float:
    return round(statistics.fmean(values), 3)
