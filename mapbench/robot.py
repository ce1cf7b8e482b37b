"""A mapping robot inside a `mapbench.worker` process: the workload of `mapctl
bench mapping` (see `mapbench.mapping`), driven over the worker's line protocol:

    robot                         -> robot {"mission", "vertices", "edges"}
    seed N                        -> seeded {"items"}
    stream S LOW HIGH CROSS SEED [MISSION=CHUNK ...]
                                  -> streamed {"items", "single_ms", "multi_ms",
                                               "retries", "seconds", "cpu_s", "acked"}
    digest                        -> digest {"chunks": {chunk: [count, hash]}}

`robot` creates the map tables if missing and this robot's two chunks: one of
the `vertices` table, one of `edges` (a chunk belongs to one table), its
mission named after the peer. `seed N` commits vertices 0..N-1, which the other
robots' inter-robot edges may end at. `stream` then writes for S seconds:
a commit of LOW..HIGH new vertices into the vertex chunk, then a commit of
their odometry edges into the edge chunk, and so on; each edge is, with
probability CROSS, an inter-robot edge to a seeded vertex of one of the other
missions named, committed on its own into this robot's edge chunk and that
robot's (a two-chunk transaction: two-phase commit across both groups).

Every item acknowledged is remembered per chunk as a digest (count, and the sum
of a 64-bit hash of each item id), which `digest` computes on a holder from its
replica, caught up with the chunk's leader: equal digests, the same items.
"""

from __future__ import annotations

import hashlib
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

    async def handle(self, verb: str, args: list[str]) -> tuple[str, dict[str, Any]]:
        """Run one command of the module docstring; returns the reply word and body."""
        if verb == "robot":
            return "robot", await self.create()
        if verb == "seed":
            return "seeded", {"items": await self.seed(int(args[0]))}
        if verb == "stream":
            if len(args) < 5:
                raise UsageError("stream takes SECONDS LOW HIGH CROSS SEED [MISSION=CHUNK ...]")
            low, high, cross, seed = int(args[1]), int(args[2]), float(args[3]), int(args[4])
            targets = dict(t.split("=", 1) for t in args[5:])
            return "streamed", await self.stream(float(args[0]), (low, high), cross, seed, targets)
        if verb == "digest":
            return "digest", {"chunks": await self.digest()}
        raise UsageError(f"unknown robot command {verb!r}")

    async def create(self) -> dict[str, Any]:
        """The map tables (if missing) and this robot's vertex and edge chunks."""
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

    async def stream(
        self,
        seconds: float,
        batch: tuple[int, int],
        cross: float,
        seed: int,
        targets: dict[str, str],
    ) -> dict[str, Any]:
        """Commit vertices and their edges for `seconds` (module docstring)."""
        vertices, edges = self._chunks()
        rng = random.Random(seed)
        run = _Run()
        cpu0, clock = time.process_time(), time.perf_counter
        started = clock()
        while clock() - started < seconds:
            first = self.next_index
            new = self._new_vertices(rng.randint(*batch))
            await self._commit([(VERTICES, vertices, new)], run)
            odometry: list[Message] = []
            for index in range(max(first, 1), self.next_index):
                if targets and self.seeded and rng.random() < cross:
                    mission = rng.choice(sorted(targets))
                    edge = self._edge(index, (mission, rng.randrange(self.seeded)))
                    pair = [(EDGES, edges, [edge]), (EDGES, ChunkId(targets[mission]), [edge])]
                    await self._commit(pair, run)
                else:
                    odometry.append(self._edge(index - 1, (self.mission, index)))
            if odometry:
                await self._commit([(EDGES, edges, odometry)], run)
        return {
            "items": run.items,
            "single_ms": [round(x, 3) for x in run.single_ms],
            "multi_ms": [round(x, 3) for x in run.multi_ms],
            "retries": dict(run.retries),
            "seconds": clock() - started,
            "cpu_s": time.process_time() - cpu0,
            "acked": {chunk: digest.pair() for chunk, digest in self.acked.items()},
        }

    def _new_vertices(self, count: int) -> list[Message]:
        first, self.next_index = self.next_index, self.next_index + count
        return [
            Vertex(
                mission=self.mission,
                index=i,
                pose=Pose3(x=0.5 * i, y=0.1 * (i % 7), qw=1.0),
                timestamp=0.1 * i,
            )
            for i in range(first, self.next_index)
        ]

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
        for info in self.peer.chunks():
            if info.table not in (VERTICES, EDGES):
                continue
            at = await self.peer.catch_up(self.peer.now(), chunk=info.id)
            digest = Digest()
            digest.add([r.item_id for r in await self.peer.scan(at, info.table, info.id)])
            found[str(info.id)] = digest.pair()
        return found


def _retry_kind(exc: MapError) -> str:
    kinds: tuple[tuple[type[MapError], str], ...] = (
        (ConflictError, "conflict"),
        (ChunkBusy, "chunk_busy"),
        (NotChunkLeader, "not_leader"),
        (ProposalLost, "proposal_lost"),
    )
    return next((name for cls, name in kinds if isinstance(exc, cls)), type(exc).__name__)
