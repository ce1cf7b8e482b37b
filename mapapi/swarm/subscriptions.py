"""Remote subscriptions (DESIGN §8): a peer asks to hear about a region.

A subscription is declarative (`mapapi.v1.Subscription`: a region, an optional
table, optional ``field == value`` filters; never code). The subscriber stores
it in every cell of the "subscriptions" spatial index its region overlaps and
keeps it alive there (`Announcements`, so it vanishes a time-to-live after its
subscriber does). A committing peer, once the chunks' logs acknowledged its
commit and before the commit returns, asks the cells around the commit's items
for the subscriptions whose region overlaps them (the owner filters by region),
evaluates each one's table and filters itself, and pushes only the matching
revisions to the subscriber. One writer's pushes arrive in its commit order;
two writers committing to one chunk at once push independently (each push
carries its commit's time). The subscriber queues them as they arrive.

An item counts as inside a region when its box overlaps it, before or after
the commit (an item that leaves the region, or is removed from it, is news).
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from google.protobuf import json_format, struct_pb2
from google.protobuf.message import DecodeError

from mapapi._pb.mapapi.v1 import lookup_pb2
from mapapi.core import limits
from mapapi.core.errors import MapError, UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import PeerId
from mapapi.core.table import TableDescriptor
from mapapi.lookup.dht.announce import Announcements, Entry
from mapapi.lookup.extent import item_box
from mapapi.lookup.spatial import BBox
from mapapi.lookup.spatial_index import (
    SpatialIndex,
    box3,
    box_of,
    decode_filter,
    encode_filter,
)
from mapapi.net.messages import Ack, TableInfo, TriggerPush
from mapapi.store.offload import off_loop
from mapapi.swarm.triggers import CommitEvent, commit_event

if TYPE_CHECKING:
    from collections.abc import Callable

    from mapapi.lookup.dht.chord import ChordNode
    from mapapi.lookup.spatial import SpatialGrid
    from mapapi.net.rpc import Request, Rpc
    from mapapi.store.base import ReplicaStore
    from mapapi.swarm.membership import Members

log = logging.getLogger(__name__)

INDEX_NAME = "subscriptions"
"""The spatial index subscriptions are stored in (its cells differ from the chunks')."""

REGION_FILTER = "region"
"""The member filter a cell owner applies: subscriptions whose region overlaps a box."""

PUSH_TIMEOUT = 2.0
"""Seconds a committer waits for a subscriber to take a push (its commit waits too)."""


def parse_where(text: str) -> tuple[str, Any]:
    """``FIELD=VALUE`` as ``(field, value)``: VALUE is read as JSON when it is
    JSON (``3``, ``true``, ``"x"``), else as a string (``door``).

    Raises:
        UsageError: no ``=``, or an empty field name.
    """
    name, sep, raw = text.partition("=")
    if not sep or not name.strip():
        raise UsageError(f"a filter is FIELD=VALUE, got {text!r}")
    try:
        value = json.loads(raw)
    except ValueError:
        value = raw
    return name.strip(), value


@dataclass(frozen=True)
class SubscriptionSpec:
    """What a subscriber wants to hear about.

    Attributes:
        region: the box; an item is inside when its box overlaps it.
        table: only this table's items (None: every table).
        where: ``(field, value)`` pairs, all of which an item must match (its
            top-level field in the protobuf JSON mapping, as `Transaction.find`).
    """

    region: BBox
    table: str | None = None
    where: tuple[tuple[str, Any], ...] = ()

    def to_pb(self, sub_id: bytes, subscriber: PeerId, address: str) -> lookup_pb2.Subscription:
        """The stored form of this spec for one subscription."""
        message = lookup_pb2.Subscription(
            id=sub_id,
            subscriber=subscriber.to_bytes(),
            address=address,
            region=box3(self.region),
            table=self.table or "",
        )
        for name, value in self.where:
            equals = struct_pb2.Value()
            json_format.ParseDict(value, equals)
            message.where.add(field=name, equals=equals)
        return message

    @classmethod
    def from_pb(cls, message: lookup_pb2.Subscription) -> SubscriptionSpec:
        """The spec a stored subscription carries.

        Raises:
            ValueError: no region, or a malformed one.
        """
        if not message.HasField("region"):
            raise ValueError("a subscription needs a region")
        where = tuple((w.field, json_format.MessageToDict(w.equals)) for w in message.where)
        return cls(box_of(message.region), message.table or None, where)

    def matches(
        self, descriptor: TableDescriptor, revision: Revision, before: Revision | None
    ) -> bool:
        """Whether `revision` (with the item's previous revision `before`) is news
        for this subscription: of its table, inside its region before or after,
        and matching its filters after (or, for a removal, before)."""
        if self.table is not None and revision.table != self.table:
            return False
        now = None if revision.removed else descriptor.decode(revision.data)
        then = None if before is None or before.removed else descriptor.decode(before.data)
        boxes = [b for m in (now, then) if m is not None and (b := item_box(m)) is not None]
        if not any(b.overlaps(self.region) for b in boxes):
            return False
        shown = now if now is not None else then
        assert shown is not None  # a removal has an earlier live revision
        return all(
            descriptor.field_json(shown, name) == descriptor.canonical_json(value)
            for name, value in self.where
        )


def decode_subscription(raw: bytes) -> lookup_pb2.Subscription:
    """A stored subscription.

    Raises:
        ValueError: not one, or one with a malformed region or more field filters
            than `limits.MAX_COUNT["where"]` (every commit would evaluate them).
    """
    message = lookup_pb2.Subscription()
    try:
        message.ParseFromString(raw)
    except DecodeError as exc:
        raise ValueError(f"not a subscription: {exc}") from exc
    if len(message.id) != 16 or len(message.subscriber) != 16 or not message.HasField("region"):
        raise ValueError("a subscription needs a 16-byte id, a subscriber and a region")
    box_of(message.region)  # InvalidBBox (a ValueError) for NaN or inverted bounds
    limits.count("where", len(message.where))
    return message


def region_filter(argument: bytes) -> Callable[[bytes], bool]:
    """The "region" member filter: keep the subscriptions whose region overlaps
    the box of `argument` (a `mapapi.v1.SpatialFilter`; its table is ignored).

    Raises:
        ValueError: the argument is no box.
    """
    box, _ = decode_filter(argument)

    def keep(member: bytes) -> bool:
        try:
            return box_of(decode_subscription(member).region).overlaps(box)
        except ValueError:
            return False

    return keep


@dataclass
class Subscription:
    """A subscription this peer made: pushes arrive in `events`, in order."""

    id: bytes
    spec: SubscriptionSpec
    events: asyncio.Queue[CommitEvent] = field(default_factory=asyncio.Queue)

    async def next(self) -> CommitEvent:
        """The next change pushed to this subscription (wrap the wait in
        `asyncio.timeout` to bound it)."""
        return await self.events.get()


class Subscriptions:
    """Both sides of remote subscriptions for one peer (see the module docstring).

    Args:
        rpc: the peer's endpoint (pushes arrive and leave through it).
        members: the swarm's members (this peer's current address is `members.me`).
        store: the peer's store (tables, and the revisions before a commit).
        ttl: lifetime of a subscription's entries, refreshed every third of it.
    """

    def __init__(self, rpc: Rpc, members: Members, store: ReplicaStore, ttl: float) -> None:
        self.rpc = rpc
        self.members = members
        self.store = store
        self.ttl = ttl
        self.index: SpatialIndex | None = None
        self.mine: dict[bytes, Subscription] = {}
        self.announced: Announcements[bytes] = Announcements(self._entries, ttl, "subscription")
        self.pushes = 0  # pushes tried, to others and to itself (for tests and benchmarks)
        self.newest = 0  # the newest commit pushed here: a view begun now includes it
        self._descriptors: dict[str, TableDescriptor] = {}
        rpc.register(TriggerPush, self.rpc_trigger_push)

    def start(self, chord: ChordNode, grid: SpatialGrid) -> None:
        """Store and find subscriptions in `chord`'s ring with `grid`'s cells."""
        chord.register_filter(REGION_FILTER, region_filter)
        self.index = SpatialIndex(chord, grid, INDEX_NAME)
        self.announced.start(chord, list(self.mine))

    # -- the subscriber ------------------------------------------------------------------
    async def subscribe(self, spec: SubscriptionSpec) -> Subscription:
        """Store `spec` in the region's cells and keep it alive; returns the
        subscription, whose `events` receive every matching commit from now on.

        Raises:
            UsageError: not on the network, or the region lies outside the index.
            LimitExceeded: more field filters than `limits.MAX_COUNT["where"]`.
        """
        if self.index is None:
            raise UsageError("subscriptions need the peer on the network; start it first")
        if not self.index.cell_keys(spec.region):
            raise UsageError(
                f"the region lies outside the spatial index ({self.index.grid.describe()})"
            )
        limits.count("where", len(spec.where))  # the committers would refuse it
        subscription = Subscription(os.urandom(16), spec)
        self.mine[subscription.id] = subscription
        await self.announced.add(subscription.id)
        return subscription

    async def cancel(self, sub_id: bytes) -> bool:
        """Withdraw a subscription; returns whether it was this peer's."""
        if self.mine.pop(sub_id, None) is None:
            return False
        await self.announced.remove(sub_id)
        return True

    def _entries(self, sub_id: bytes) -> list[Entry]:
        subscription = self.mine.get(sub_id)
        if subscription is None or self.index is None:
            return []
        me = self.members.me
        member = subscription.spec.to_pb(sub_id, me.id, me.address).SerializeToString(
            deterministic=True
        )
        return [(key, member) for key in self.index.cell_keys(subscription.spec.region)]

    def rpc_trigger_push(self, req: Request) -> Ack:
        """A committer pushes revisions for one of our subscriptions."""
        self._deliver(req.body)
        return Ack()

    async def call_trigger_push(self, address: str, push: TriggerPush) -> None:
        """Push revisions to the subscriber at `address` (its `rpc_trigger_push`)."""
        await self.rpc.request(address, push, timeout=PUSH_TIMEOUT, expect=Ack)

    def _deliver(self, push: TriggerPush) -> None:
        subscription = self.mine.get(push.subscription)
        if subscription is None:  # cancelled: a push may still arrive late
            return
        self.newest = max(self.newest, push.record.time)  # heard of here (`Peer.now`)
        types = {t.name: t.type_name for t in push.tables}
        event = commit_event(push.record, push.revisions, types)
        if event is not None:
            subscription.events.put_nowait(event)

    # -- the committer -------------------------------------------------------------------
    async def notify(self, record: CommitRecord, revisions: Sequence[Revision]) -> int:
        """Push `record`'s revisions to every subscription they match (call while
        holding the commit's locks); returns the pushes sent. Never raises for a
        subscriber that does not answer (logged)."""
        if self.index is None:
            return 0
        # decoding every revision of a large commit takes seconds: not on the loop
        placed, around = await off_loop(self.store, self._placed, record, revisions)
        if around is None:
            return 0
        try:
            members = await self.index.members(around, REGION_FILTER, encode_filter(around))
        except MapError as exc:
            log.warning("no subscriptions for commit %s: %s", record.id.short, exc)
            return 0
        pushes = []
        for sub_id, message in {m.id: m for m in _decoded(members)}.items():
            try:  # a malformed subscription (anyone may store one) must not fail a commit
                spec = SubscriptionSpec.from_pb(message)
                matched = await off_loop(self.store, self._matching, spec, placed)
            except (MapError, ValueError) as exc:
                log.warning("skipping subscription %s: %s", sub_id.hex()[:8], exc)
                continue
            if matched:
                pushes.append(self._push(sub_id, message, record, matched))
        await asyncio.gather(*pushes)
        return len(pushes)

    def _placed(
        self, record: CommitRecord, revisions: Sequence[Revision]
    ) -> tuple[list[tuple[Revision, Revision | None, BBox]], BBox | None]:
        """The revisions whose item has a box before or after the commit, with the
        previous revision and the box around both; and the box around them all
        (None: none has a box). Any thread."""
        found = []
        for revision in revisions:
            descriptor = self._descriptor(revision.table)
            before = (
                None
                if revision.kind == "inserted"
                else self.store.read(revision.item_id, record.time - 1)
            )
            boxes = [
                b
                for r in (revision, before)
                if r is not None and not r.removed and (b := _box(descriptor, r.data)) is not None
            ]
            if boxes:
                found.append((revision, before, BBox.enclosing(boxes)))
        return found, BBox.enclosing(box for _, _, box in found) if found else None

    def _matching(
        self, spec: SubscriptionSpec, placed: list[tuple[Revision, Revision | None, BBox]]
    ) -> tuple[Revision, ...]:
        """The revisions of `placed` that `spec` matches (any thread)."""
        return tuple(
            r for r, before, _ in placed if spec.matches(self._descriptor(r.table), r, before)
        )

    def _descriptor(self, table: str) -> TableDescriptor:
        if table not in self._descriptors:  # a table's type never changes: read it once
            self._descriptors[table] = TableDescriptor.named(table, self.store.tables()[table])
        return self._descriptors[table]

    async def _push(
        self,
        sub_id: bytes,
        message: lookup_pb2.Subscription,
        record: CommitRecord,
        revisions: tuple[Revision, ...],
    ) -> None:
        names = sorted({r.table for r in revisions})
        tables = tuple(TableInfo(t, self.store.tables()[t]) for t in names)
        body = TriggerPush(sub_id, record, revisions, tables)
        self.pushes += 1
        if PeerId.from_bytes(message.subscriber) == self.members.me.id:
            self._deliver(body)
            return
        try:
            await self.call_trigger_push(message.address, body)
        except MapError as exc:
            log.warning(
                "subscriber at %s missed commit %s: %s", message.address, record.id.short, exc
            )

    async def withdraw_all(self) -> None:
        """Withdraw every subscription of this peer (a graceful stop)."""
        await self.announced.withdraw_all()

    async def close(self) -> None:
        """Stop refreshing (the entries expire by themselves)."""
        await self.announced.close()


def _box(descriptor: TableDescriptor, data: bytes) -> BBox | None:
    try:
        return item_box(descriptor.decode(data))
    except (MapError, ValueError) as exc:
        log.warning("an item of %s has no usable box: %s", descriptor.name, exc)
        return None


def _decoded(members: Sequence[bytes]) -> list[lookup_pb2.Subscription]:
    found = []
    for raw in members:
        try:
            found.append(decode_subscription(raw))
        except ValueError as exc:
            log.warning("skipping a bad subscription entry: %s", exc)
    return found
