"""A mapping robot inside a `mapbench.worker` process: the workload of `mapctl
bench mapping` (see `mapbench.mapping`), driven over the worker's line protocol:

    robot INDEX                   -> robot {"mission", "vertices", "edges"}
    seed N                        -> seeded {"items"}
    stream S LOW HIGH CROSS ALONE SEED [MISSION=CHUNK ...]
                                  -> streamed {"items", "items_first_half",
                                               "single_ms", "multi_ms",
                                               "retries", "seconds", "cpu_s", "acked"}
    digest                        -> digest {"chunks": {chunk: [count, hash]}}

`robot` creates the map tables if missing and this robot's two chunks: one of
the `vertices` table, one of `edges` (a chunk belongs to one table), its
mission named after the peer. `seed N` commits vertices 0..N-1, which the other
robots' inter-robot edges may end at. `stream` then writes for S seconds:
a commit of LOW..HIGH new vertices into the vertex chunk, then a commit of
their edges into the edge chunk, and so on. Each edge is, with probability
CROSS, an inter-robot edge to a seeded vertex of one of the other missions
named, written into this robot's edge chunk and, as a copy, into that robot's:
the edge commit then writes several chunks (a two-phase commit across their
groups). With ALONE = 1 each inter-robot edge is committed on its own instead
(two items, two chunks), and the edge commit holds the odometry edges alone.

Every item acknowledged is remembered per chunk as a digest (count, and the sum
of a 64-bit hash of each item id), which `digest` computes on a holder from its
replica, caught up with the chunk's leader: equal digests, the same items.
"""

from __future__ import annotations

import hashlib
import math
import random
import time
from collections import Counter as Tally
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from google.protobuf.message import Message

from mapapi.core.errors import (
    ChunkBusy,
    ConflictError,
    MapError,
    NotChunkLeader,
    ProposalLost,
    UsageError,
)
from mapapi.core.ids import ChunkId, ItemId
from mapapi.maps.importer import ensure_tables
from mapapi.maps.schema import EDGES, VERTICES, Edge, Pose3, Vertex
from mapapi.service.peer import Peer

COMMANDS = ("robot", "seed", "stream", "digest")
"""The worker's verbs this module answers."""
MAX_ATTEMPTS = 50
"""Attempts of one commit before the stream gives up (every retry is counted)."""
INFORMATION = tuple(100.0 if row == col else 0.0 for row in range(6) for col in range(row, 6))
"""An identity-like 6x6 information matrix, upper triangle (21 values)."""
_MASK = (1 << 64) - 1
STEP, RADIUS, CELL = 0.1, 15.0, 64.0
"""Metres between poses (10 Hz at 1 m/s), of the circle each robot drives round
(its box stops growing after the first lap, 942 poses), and of a cell of the
default spatial grid (`mapapi.lookup.spatial.DEFAULT_CELLS`): each robot drives
inside its own cell, so its chunks' boxes, which peers announce in the spatial
index each time they grow, soon stop changing."""


def item_hash(item: str) -> int:
    """The 64-bit hash of an item id that digests add up."""
    return int.from_bytes(hashlib.blake2b(item.encode(), digest_size=8).digest(), "big")


@dataclass(slots=True)
class Digest:
    """Items of one chunk, order-free: how many, and the sum of their hashes."""

    count: int = 0
    total: int = 0

    def add(self, items: Sequence[str]) -> None:
        """Count `items`."""
        self.count += len(items)
        self.total = (self.total + sum(item_hash(i) for i in items)) & _MASK

    def merge(self, pair: Sequence[int]) -> None:
        """Count the items of another digest's `pair()` too."""
        self.count += pair[0]
        self.total = (self.total + pair[1]) & _MASK

    def pair(self) -> list[int]:
        """[count, hash sum], as JSON carries it."""
        return [self.count, self.total]


@dataclass(slots=True)
class _Run:
    """What one `stream` did."""

    items: int = 0
    single_ms: list[float] = field(default_factory=list)
    multi_ms: list[float] = field(default_factory=list)
    retries: Tally[str] = field(default_factory=Tally)


Writes = list[tuple[str, ChunkId, list[Message]]]


@dataclass(frozen=True, slots=True)
class Stream:
    """What one `stream` writes (module docstring).

    Attributes:
        seconds: how long it streams.
        batch: the fewest and most vertices of one commit.
        cross: the share of edges that are inter-robot edges.
        alone: each inter-robot edge in a commit of its own, not with the others.
        seed: seeds the choices.
        targets: mission -> edge chunk of the robots whose chunks this one holds.
    """

    seconds: float
    batch: tuple[int, int]
    cross: float
    alone: bool
    seed: int
    targets: dict[str, str]


class Robot:
    """One robot's mission, its two chunks and what it had acknowledged.

    Args:
        peer: the worker's started peer (with the map tables' rules).
    """

    def __init__(self, peer: Peer) -> None:
        self.peer = peer
        self.mission = peer.name
        self.vertices: ChunkId | None = None
        self.edges: ChunkId | None = None
        self.next_index = 0
        self.seeded = 0
        self.acked: dict[str, Digest] = {}
        self.centre = (0.0, 0.0)

    async def handle(self, verb: str, args: list[str]) -> tuple[str, dict[str, Any]]:
        """Run one command of the module docstring; returns the reply word and body."""
        if verb == "robot":
            return "robot", await self.create(int(args[0]) if args else 0)
        if verb == "seed":
            return "seeded", {"items": await self.seed(int(args[0]))}
        if verb == "stream":
            if len(args) < 6:
                raise UsageError(
                    "stream takes SECONDS LOW HIGH CROSS ALONE SEED [MISSION=CHUNK ...]"
                )
            spec = Stream(
                seconds=float(args[0]),
                batch=(int(args[1]), int(args[2])),
                cross=float(args[3]),
                alone=args[4] == "1",
                seed=int(args[5]),
                targets=dict(t.split("=", 1) for t in args[6:]),
            )
            return "streamed", await self.stream(spec)
        if verb == "digest":
            return "digest", {"chunks": await self.digest()}
        raise UsageError(f"unknown robot command {verb!r}")

    async def create(self, index: int) -> dict[str, Any]:
        """The map tables (if missing) and this robot's vertex and edge chunks;
        robot `index` drives round its own cell of the default spatial grid."""
        self.centre = (CELL * (index % 16 + 0.5), CELL * (index // 16 + 0.5))
        await ensure_tables(self.peer)
        self.vertices = await self.peer.create_chunk(VERTICES)
        self.edges = await self.peer.create_chunk(EDGES)
        return {"mission": self.mission, "vertices": self.vertices, "edges": self.edges}

    def _chunks(self) -> tuple[ChunkId, ChunkId]:
        if self.vertices is None or self.edges is None:
            raise UsageError("no chunks yet: send `robot` first")
        return self.vertices, self.edges

    async def seed(self, count: int) -> int:
        """Commit vertices 0..count-1 (the ends of other robots' edges)."""
        vertices, _ = self._chunks()
        await self._commit([(VERTICES, vertices, self._new_vertices(count))], _Run())
        self.seeded = count
        return count

    async def stream(self, spec: Stream) -> dict[str, Any]:
        """Commit vertices and their edges for `spec.seconds` (module docstring)."""
        vertices, _ = self._chunks()
        rng = random.Random(spec.seed)
        run = _Run()
        cpu0, clock = time.process_time(), time.perf_counter
        started = clock()
        half = 0  # items acknowledged in the first half of the time
        while clock() - started < spec.seconds:
            if clock() - started < spec.seconds / 2:
                half = run.items
            first = self.next_index
            new = self._new_vertices(rng.randint(*spec.batch))
            await self._commit([(VERTICES, vertices, new)], run)
            for writes in self._edge_commits(first, spec, rng):
                await self._commit(writes, run)
        return {
            "items": run.items,
            "items_first_half": half,
            "single_ms": [round(x, 3) for x in run.single_ms],
            "multi_ms": [round(x, 3) for x in run.multi_ms],
            "retries": dict(run.retries),
            "seconds": clock() - started,
            "cpu_s": time.process_time() - cpu0,
            "acked": {chunk: digest.pair() for chunk, digest in self.acked.items()},
        }

    def _edge_commits(self, first: int, spec: Stream, rng: random.Random) -> list[Writes]:
        """The commits of the edges ending at vertices `first`.. (the newest): the
        odometry edges and the inter-robot ones with their copies in the other
        robots' chunks, together or (`spec.alone`) each inter-robot edge apart."""
        _, edges = self._chunks()
        batch: list[Message] = []
        copies: dict[ChunkId, list[Message]] = {}
        alone: list[Writes] = []
        for index in range(max(first, 1), self.next_index):
            if not (spec.targets and self.seeded and rng.random() < spec.cross):
                batch.append(self._edge(index - 1, (self.mission, index)))
                continue
            mission = rng.choice(sorted(spec.targets))
            edge = self._edge(index, (mission, rng.randrange(self.seeded)))
            other = ChunkId(spec.targets[mission])
            if spec.alone:
                alone.append([(EDGES, edges, [edge]), (EDGES, other, [edge])])
            else:
                batch.append(edge)
                copies.setdefault(other, []).append(edge)
        together: Writes = [(EDGES, edges, batch)] if batch else []
        together += [(EDGES, chunk, messages) for chunk, messages in copies.items()]
        return [*alone, together] if together else alone

    def _new_vertices(self, count: int) -> list[Message]:
        first, self.next_index = self.next_index, self.next_index + count
        return [
            Vertex(
                mission=self.mission,
                index=i,
                pose=self._pose(i),
                timestamp=0.1 * i,
            )
            for i in range(first, self.next_index)
        ]

    def _pose(self, index: int) -> Message:
        """Where vertex `index` lies: `STEP` m further round a circle of `RADIUS` m."""
        angle = index * STEP / RADIUS
        x, y = self.centre[0] + RADIUS * math.cos(angle), self.centre[1] + RADIUS * math.sin(angle)
        return Pose3(x=x, y=y, qz=math.sin(angle / 2), qw=math.cos(angle / 2))

    def _edge(self, source: int, target: tuple[str, int]) -> Message:
        """An edge of this mission from its vertex `source` to `target`."""
        message = Edge(
            mission=self.mission,
            relative=Pose3(x=0.5, qw=1.0),
            kind=Edge.ODOMETRY if target[0] == self.mission else Edge.INTER_ROBOT,
        )
        message.from_vertex.mission, message.from_vertex.index = self.mission, source
        message.to_vertex.mission, message.to_vertex.index = target
        message.information.extend(INFORMATION)
        return message

    async def _commit(self, writes: Writes, run: _Run) -> None:
        """Commit `writes` as one transaction, again (same item ids) after a
        retriable error; count it in `run` and its items in the digests."""
        ids = [[ItemId.new() for _ in messages] for _, _, messages in writes]
        started = time.perf_counter()
        for attempt in range(MAX_ATTEMPTS):
            tx = self.peer.begin()
            for (table, chunk, messages), names in zip(writes, ids, strict=True):
                for message, item in zip(messages, names, strict=True):
                    tx.insert(table, message, chunk, item)
            try:
                await tx.commit(f"{self.mission}: {sum(map(len, ids))} items")
            except MapError as exc:
                if not exc.retriable or attempt == MAX_ATTEMPTS - 1:
                    raise
                run.retries[_retry_kind(exc)] += 1
                continue
            break
        multi = len({chunk for _, chunk, _ in writes}) > 1
        (run.multi_ms if multi else run.single_ms).append((time.perf_counter() - started) * 1e3)
        for (_, chunk, _), names in zip(writes, ids, strict=True):
            run.items += len(names)
            self.acked.setdefault(str(chunk), Digest()).add(names)

    async def digest(self) -> dict[str, list[int]]:
        """The digest of every map chunk held here, read once caught up with its leader."""
        found: dict[str, list[int]] = {}
        for chunk in self.peer.store.chunk_ids():  # not peer.chunks(): it counts items
            table = self.peer.chunk_table(chunk)
            if table not in (VERTICES, EDGES):
                continue
            at = await self.peer.catch_up(self.peer.now(), chunk=chunk)
            digest = Digest()
            digest.add([r.item_id for r in await self.peer.scan(at, table, chunk)])
            found[str(chunk)] = digest.pair()
        return found


def _retry_kind(exc: MapError) -> str:
    kinds: tuple[tuple[type[MapError], str], ...] = (
        (ConflictError, "conflict"),
        (ChunkBusy, "chunk_busy"),
        (NotChunkLeader, "not_leader"),
        (ProposalLost, "proposal_lost"),
    )
    return next((name for cls, name in kinds if isinstance(exc, cls)), type(exc).__name__)
