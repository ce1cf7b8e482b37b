"""`mapctl bench triggers`: the bytes a subscriber receives to stay up to date
about a region, with triggers, polling and replication (the Map API paper,
Cieslewski et al., ICRA 2015, Fig. 6; issue 6 §5).

The map is `AREA` (200 m x 200 m), the region of interest `REGION` (20 m x
20 m, across 4 of the index's 20 m cells). W writers each hold one chunk of
items (``google.protobuf.Struct`` with a "bbox"; `INSIDE_SHARE` of them lie
inside the region, the others at least `_MARGIN` outside it) and, once per
round, commit a small update of one of them: a seeded `fraction` of each
writer's commits nudge an inside item (it stays inside), the others an outside
one (it stays outside). S subscribers follow the region in one of the `MODES`:

- ``triggers``: each subscribes to the region (DESIGN §8); a committer pushes
  it the matching revisions;
- ``polling``: after each round, each asks the spatial index for the chunks
  overlapping the region and fetches every one with `Peer.participate` (the
  fetch the API has: the chunk's full state with its history, as its group's
  snapshot and log), then leaves it, so that it receives no commit it did not poll for;
- ``replication``: each holds every writer's chunk and receives every commit;
- ``idle``, the baseline: it does not follow the region, and receives only
  what it serves as a node of the Chord ring while the writers commit (their
  lookups, their chunks' boxes in its cells). That part is the same in every
  mode (the ring and the workload are seeded) and is reported as
  ``ring_bytes``.

Freshness is equal: a push is acknowledged before its commit returns, a poll
runs right after each round's commits, and a replica is caught up with its
chunk's leader (ReadIndex) before it is read. So after every round each subscriber knows every
commit so far, and the bench checks it: the commits a subscriber learned of
(pushed, or found inside the region in its fetched or replicated history by
the rule a committer applies, `SubscriptionSpec.matches`) must equal the
writers' commits whose item lay inside before or after, computed from the
workload (`check_triggers` turns a difference into an error).

Each (fraction, mode) runs on a fresh swarm of the same seeded peers
(`mapbench.peers.settled_peers`) whose Chord rounds and announcement
refreshes are parked, so the counters hold only what the run itself costs.
Bytes are what the subscriber's transport received (`mapapi.net.stats`),
requests and replies alike. Nothing here asserts them; the figures go to
docs/benchmarks.md.
"""

from __future__ import annotations

import asyncio
import logging
import random
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from mapapi.core.errors import MapError, UsageError
from mapapi.core.ids import ChunkId, CommitId, ItemId
from mapapi.lookup.spatial import BBox, SpatialGrid
from mapapi.service.peer import Peer
from mapapi.swarm.subscriptions import Subscription, SubscriptionSpec
from mapbench.peers import received_bytes, settled_peers, stats_of, swarm_of
from mapbench.trigger_workload import AREA, Update, Workload, item_at, plan_workload

log = logging.getLogger(__name__)

GRID = SpatialGrid(AREA, (10, 10, 1))
"""Every bench peer's spatial index: 20 m cells."""

MODES = ("triggers", "polling", "replication", "idle")
"""How the subscribers follow the region (see the module docstring)."""

FRACTIONS = (0.05, 0.1, 0.25, 0.5)
"""Shares of each writer's commits inside the region, of `mapctl bench triggers`."""

TARGET_RATIO = 0.2
"""Issue 6 §5: triggers send at most 1/5 of polling's bytes."""

DEFAULT_WRITERS = 2
DEFAULT_SUBSCRIBERS = 2
DEFAULT_PEERS = 8
DEFAULT_ITEMS = 100
DEFAULT_COMMITS = 20
"""Commits per writer, one per round: with the other defaults, the 16 runs of
`mapctl bench triggers` take about 20 s on 2 cores, mostly setting up swarms."""

TABLE = "landmarks"


class TriggersCheckFailed(MapError):
    """A subscriber did not learn exactly the commits inside its region."""


# -- measurement -------------------------------------------------------------------------


def measure_triggers(
    *,
    fractions: Sequence[float] = FRACTIONS,
    modes: Sequence[str] = MODES,
    writers: int = DEFAULT_WRITERS,
    subscribers: int = DEFAULT_SUBSCRIBERS,
    peers: int = DEFAULT_PEERS,
    items: int = DEFAULT_ITEMS,
    commits: int = DEFAULT_COMMITS,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """Run the workload of each fraction once per mode, each on a fresh swarm.

    Args:
        fractions: shares of each writer's commits inside the region.
        modes: some of `MODES`.
        writers: peers committing, one chunk each.
        subscribers: peers following the region.
        peers: the ring's size (the peers beyond writers and subscribers only
            serve the ring).
        items: items per chunk.
        commits: commits per writer, one per round.
        seed: seeds the peers' ids and the workload.

    Returns:
        One JSON-ready row per (fraction, mode), in that order: mode,
        inside_fraction, writers, subscribers, peers, items, commits (in
        all), inside_commits; per subscriber, on average: bytes and messages
        received, bytes_per_commit, ring_bytes (the idle row's bytes: what it
        serves as a ring node) and own_bytes (bytes beyond those; both None
        without an idle row), setup_bytes (received when subscribing or
        taking the replicas, not in bytes), query_bytes (polling: the part of
        bytes its spatial queries took), changes (inside revisions
        learned), revisions (revisions received), bytes_by_round
        (cumulative) and bytes_by_type; then network_bytes (received by all
        peers), ratio_to_polling (bytes over polling's bytes at the same
        fraction; None without a polling row), seconds, and the check:
        missed and extra commits and stale_rounds (rounds after which a
        subscriber's knowledge differed from the commits so far), summed
        over the subscribers.

    Raises:
        UsageError: an unknown mode, no subscriber, or fewer peers than
            writers and subscribers.
        ValueError: a bad workload size (see `plan_workload`).
        RingNotStable: a ring did not converge (a Chord bug).
    """
    unknown = set(modes) - set(MODES)
    if unknown:
        raise UsageError(f"unknown modes {sorted(unknown)}; choose from {', '.join(MODES)}")
    if subscribers < 1 or peers < writers + subscribers:
        raise UsageError(
            f"{peers} peers cannot hold {writers} writers and {subscribers} subscribers "
            "(at least 1); give more --peers"
        )
    rows = []
    for fraction in fractions:
        workload = plan_workload(writers, items, commits, fraction, seed=seed)
        mine = [asyncio.run(_run(mode, workload, peers, subscribers, seed)) for mode in modes]
        _compare(mine)
        rows.extend(mine)
    return rows


def _compare(rows: Sequence[dict[str, Any]]) -> None:
    """Fill in the figures of one fraction's rows that need its other modes."""
    polling = next((r["bytes"] for r in rows if r["mode"] == "polling"), None)
    idle = next((r["bytes"] for r in rows if r["mode"] == "idle"), None)
    for row in rows:
        row["ring_bytes"] = idle
        row["own_bytes"] = None if idle is None else round(row["bytes"] - idle, 1)
        row["ratio_to_polling"] = round(row["bytes"] / polling, 4) if polling else None


def check_triggers(rows: Sequence[dict[str, Any]]) -> None:
    """Fail unless every subscriber learned exactly the commits inside its
    region, after every round.

    Raises:
        TriggersCheckFailed: some row counts a missed, extra or stale commit.
    """
    bad = [r for r in rows if r["missed"] or r["extra"] or r["stale_rounds"]]
    if bad:
        where = ", ".join(
            f"{r['mode']} at {r['inside_fraction']:g} ({r['missed']} missed, "
            f"{r['extra']} extra, {r['stale_rounds']} stale rounds)"
            for r in bad
        )
        raise TriggersCheckFailed(
            f"subscribers did not learn exactly the commits inside their region: {where}; "
            "reproduce with tests/net/test_bench_triggers.py"
        )


Learned = tuple[CommitId, tuple[ItemId, ...]]
"""A commit as a subscriber learns of it: its id and its items inside the region."""


@dataclass
class _Follower:
    """One subscriber: what it learned and what it received."""

    peer: Peer
    since: dict[ChunkId, int]  # per chunk, the newest commit time learned of
    subscription: Subscription | None = None
    learned: list[Learned] = field(default_factory=list)
    revisions: int = 0
    stale_rounds: int = 0
    setup_bytes: int = 0
    query_bytes: int = 0
    by_round: list[int] = field(default_factory=list)


async def _run(
    mode: str, workload: Workload, count: int, subscribers: int, seed: int
) -> dict[str, Any]:
    """One mode on a fresh swarm: its row, but for the figures of `_compare`."""
    writers = len(workload.items)
    async with settled_peers(count, random.Random(seed), grid=GRID) as peers:
        chunks, items, since = await _populate(peers[:writers], workload)
        owners = dict(zip(chunks, peers[:writers], strict=True))
        followers = [_Follower(p, dict(since)) for p in peers[writers : writers + subscribers]]
        for follower in followers:
            before = received_bytes(follower.peer)
            await _set_up(mode, follower, workload.region, chunks)
            follower.setup_bytes = received_bytes(follower.peer) - before
        for peer in peers:
            stats_of(peer).reset()
        expected: list[Learned] = []
        started = time.perf_counter()
        for updates in workload.rounds:
            inside = await _commit(peers[:writers], chunks, items, updates, workload.region)
            if mode != "idle":
                expected += inside
            for follower in followers:
                await _observe(mode, follower, workload.region, owners)
                follower.stale_rounds += Counter(follower.learned) != Counter(expected)
                follower.by_round.append(received_bytes(follower.peer))
        seconds = time.perf_counter() - started
        row = _row(mode, workload, peers, followers, expected)
    log.info("%s at %g: %s bytes per subscriber", mode, workload.fraction, row["bytes"])
    row["seconds"] = round(seconds, 3)
    return row


async def _populate(
    writers: Sequence[Peer], workload: Workload
) -> tuple[list[ChunkId], list[list[ItemId]], dict[ChunkId, int]]:
    """Each writer's chunk with its items, in one commit; returns the chunks,
    their item ids and the time of that commit (what is not newer is no news)."""
    chunks, items, since = [], [], {}
    for writer, boxes in zip(writers, workload.items, strict=True):
        await writer.create_table(TABLE, "google.protobuf.Struct")
        chunk = await writer.create_chunk(TABLE)
        tx = writer.begin()
        ids = [tx.insert(TABLE, item_at(box, 0), chunk) for box in boxes]
        record = await tx.commit(f"{writer.name}: {len(ids)} landmarks")
        assert record is not None  # it inserts
        chunks.append(chunk)
        items.append(ids)
        since[chunk] = record.time
    return chunks, items, since


async def _set_up(mode: str, follower: _Follower, region: BBox, chunks: list[ChunkId]) -> None:
    """Subscribe, or take the replicas; polling and idle need nothing."""
    if mode == "triggers":
        follower.subscription = await follower.peer.subscribe(SubscriptionSpec(region, TABLE))
    elif mode == "replication":
        for chunk in chunks:
            await follower.peer.participate(chunk)


async def _commit(
    writers: Sequence[Peer],
    chunks: Sequence[ChunkId],
    items: Sequence[Sequence[ItemId]],
    updates: Sequence[Update],
    region: BBox,
) -> list[Learned]:
    """One round, every writer committing at once; returns its commits inside
    `region`, as a subscriber should learn of them."""

    async def one(writer: Peer, chunk: ChunkId, ids: Sequence[ItemId], update: Update) -> Learned:
        tx = writer.begin()
        tx.update(TABLE, ids[update.item], item_at(update.after, 1))
        record = await tx.commit(f"{writer.name}: nudge item {update.item}")
        assert record is not None  # it updates
        return record.id, (ids[update.item],)

    plans = zip(writers, chunks, items, updates, strict=True)
    done = await asyncio.gather(*(one(*each) for each in plans))
    return [learned for learned, u in zip(done, updates, strict=True) if u.inside(region)]


async def _observe(
    mode: str, follower: _Follower, region: BBox, owners: dict[ChunkId, Peer]
) -> None:
    """What `follower` learns after a round: the pushes queued, a poll, the
    commits its replicas applied, or (idle) nothing. `owners` maps each chunk
    to its writer."""
    peer = follower.peer
    if mode == "triggers":
        assert follower.subscription is not None
        events = follower.subscription.events
        while not events.empty():
            event = events.get_nowait()
            follower.learned.append((event.record.id, tuple(r.item_id for r in event.revisions)))
            follower.revisions += len(event.revisions)
    elif mode == "polling":
        before = received_bytes(peer)
        found = await peer.query_bbox(region, TABLE)
        follower.query_bytes += received_bytes(peer) - before
        for placed in found:
            chunk = placed.ref.chunk
            await peer.participate(chunk)
            # The holder sent its whole history; count it there: a MemoryStore
            # that held the chunk before keeps only the revisions new to it (so
            # `_learn` may lack an update's previous revision; no item of the
            # workload crosses the region's border, so its new box decides).
            follower.revisions += len(owners[chunk].store.chunk_revisions(chunk))
            _learn(follower, chunk, region)
            await peer.leave_chunk(chunk)
    elif mode == "replication":
        for chunk in owners:
            await swarm_of(peer).groups.catch_up(chunk)  # the round's commits are applied
            follower.revisions += _learn(follower, chunk, region)


def _learn(follower: _Follower, chunk: ChunkId, region: BBox) -> int:
    """Learn of the commits to `chunk`, in the subscriber's copy, newer than the
    last learned that change an item inside `region` (by the rule a committer
    applies to subscriptions); returns the revisions of those newer commits."""
    peer, spec = follower.peer, SubscriptionSpec(region, TABLE)
    descriptor = peer.table(TABLE)
    since, newer = follower.since[chunk], 0
    for record in peer.store.chunk_commits(chunk):
        if record.time <= since:
            continue
        revisions = [r for r in peer.commit_revisions(record.id) if r.chunk_id == chunk]
        newer += len(revisions)
        matched = tuple(
            r.item_id
            for r in revisions
            if spec.matches(descriptor, r, peer.read_local(r.item_id, record.time - 1))
        )
        if matched:
            follower.learned.append((record.id, matched))
        follower.since[chunk] = max(follower.since[chunk], record.time)
    return newer


def _row(
    mode: str,
    workload: Workload,
    peers: Sequence[Peer],
    followers: Sequence[_Follower],
    expected: list[Learned],
) -> dict[str, Any]:
    """One run's figures, per subscriber on average (see `measure_triggers`)."""
    n = len(followers)
    by_type: Counter[str] = Counter()
    for follower in followers:
        by_type.update({t: c.bytes for t, c in stats_of(follower.peer).received_by_type().items()})
    want = Counter(expected)
    commits = sum(len(updates) for updates in workload.rounds)
    received = sum(received_bytes(f.peer) for f in followers) / n
    messages = sum(c.messages for f in followers for c in stats_of(f.peer).received.values())
    return {
        "mode": mode,
        "inside_fraction": workload.fraction,
        "writers": len(workload.items),
        "subscribers": n,
        "peers": len(peers),
        "items": len(workload.items[0]),
        "commits": commits,
        "inside_commits": workload.inside_commits(),
        "bytes": round(received, 1),
        "bytes_per_commit": round(received / commits, 1),
        "messages": round(messages / n, 1),
        "ring_bytes": None,  # these three need the other modes: `_compare`
        "own_bytes": None,
        "ratio_to_polling": None,
        "setup_bytes": round(sum(f.setup_bytes for f in followers) / n, 1),
        "query_bytes": round(sum(f.query_bytes for f in followers) / n, 1),
        "changes": round(sum(len(i) for f in followers for _, i in f.learned) / n, 1),
        "revisions": round(sum(f.revisions for f in followers) / n, 1),
        "network_bytes": sum(received_bytes(p) for p in peers),
        "missed": sum(sum((want - Counter(f.learned)).values()) for f in followers),
        "extra": sum(sum((Counter(f.learned) - want).values()) for f in followers),
        "stale_rounds": sum(f.stale_rounds for f in followers),
        "seconds": None,
        "bytes_by_round": [
            round(sum(b) / n, 1) for b in zip(*(f.by_round for f in followers), strict=True)
        ],
        "bytes_by_type": {t: round(b / n, 1) for t, b in sorted(by_type.items())},
    }
