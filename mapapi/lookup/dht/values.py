"""The sets of members the Chord ring stores under its keys, at one node (DESIGN §7).

Soft state (`storage.Storage`, each member with a time-to-live): the owner of a
key applies `add` / `remove` itself, atomically, and copies the change down its
successor list; `get` asks the owner, filtered there by a named member filter.
`ChordNode` routes and keeps the ring; it holds one `RingValues` and registers
its `rpc_*` handlers.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING, TypeVar

from mapapi.core import limits
from mapapi.core.errors import NetworkError, ProtocolError
from mapapi.lookup.dht import ring
from mapapi.lookup.dht.ring_wire import Node, key_bytes, key_from
from mapapi.net.asking import ask_all
from mapapi.net.messages import (
    Ack,
    ChordAdd,
    ChordEntry,
    ChordGet,
    ChordRemove,
    ChordStore,
    ChordValues,
)
from mapapi.net.rpc import Request

if TYPE_CHECKING:
    from mapapi.lookup.dht.chord import ChordNode

log = logging.getLogger(__name__)

T = TypeVar("T")

_ATTEMPTS = 4

MemberFilter = Callable[[bytes], Callable[[bytes], bool]]
"""A named server-side filter of `ChordNode.get`: given the query's argument, the
predicate each stored member must pass. It raises ValueError on a bad argument."""


class RingValues:
    """The values part of `node`: its stored sets, and their replication."""

    def __init__(self, node: ChordNode) -> None:
        self._node = node
        self._filters: dict[str, MemberFilter] = {}
        self._replicated: set[Node] = set()
        self._replicated_for: Node | None = None  # the predecessor when last replicated

    async def add(self, key: int, member: bytes, ttl: float) -> None:
        """Add `member` to the set under `key` for `ttl` seconds (re-add to refresh).

        Raises:
            NetworkError: the key's owner could not be reached.
            LimitExceeded: `ttl` is not in (0, limits.MAX_TTL] (a ValueError).
        """
        limits.ttl(ttl)
        await self._at_owner(key, ChordAdd(key_bytes(key), member, ttl), Ack)

    async def remove(self, key: int, member: bytes) -> None:
        """Remove `member` from the set under `key`."""
        await self._at_owner(key, ChordRemove(key_bytes(key), member), Ack)

    def register_filter(self, name: str, member_filter: MemberFilter) -> None:
        """Let `get(key, filter=name, ...)` keep only the members `member_filter`
        passes, evaluated at the key's owner. Every node of the ring must
        register the same filters (the peers of one version do)."""
        self._filters[name] = member_filter

    async def get(self, key: int, filter: str = "", argument: bytes = b"") -> set[bytes]:
        """The live members under `key`; with `filter`, those the owner's filter of
        that name keeps for `argument`.

        Raises:
            NetworkError: the key's owner could not be reached.
            ProtocolError: the owner has no such filter, or refused the argument.
        """
        body = ChordGet(key_bytes(key), filter, argument)
        values = await self._at_owner(key, body, ChordValues)
        return set(values.members)

    async def _at_owner(self, key: int, body: object, expect: type[T]) -> T:
        error: NetworkError | None = None
        for _ in range(_ATTEMPTS):
            owner, _ = await self._node.lookup(key, self._node.me)
            try:
                return await self._node.call(owner, body, expect)
            except NetworkError as exc:
                error = exc
                self._node.suspect(owner)
        assert error is not None
        raise error

    def entries(self, where: Callable[[int], bool] = lambda _key: True) -> tuple[ChordEntry, ...]:
        return tuple(
            ChordEntry(key_bytes(k), m, ttl)
            for k, m, ttl in self._node.storage.entries(self._node.clock(), where)
        )

    def owns(self, key: int) -> bool:
        pred = self._node.predecessor
        return pred is None or ring.responsible(key, self._node.key, pred.key)

    async def _replicate(self, body: object, targets: list[Node] | None = None) -> None:
        """Copy `body` to each of `targets` (the successors by default) but this node,
        once each: in a ring of at most k + 1 nodes the predecessor is a successor
        too, and a repeated key in the dict below would drop a call unawaited."""
        wanted = self._node.successors if targets is None else targets
        once = [s for s in dict.fromkeys(wanted) if s != self._node.me]
        answers = await ask_all({s: self._node.call(s, body, Ack) for s in once})
        for node, error in answers.failed.items():
            log.debug("replica %s missed an update: %s", node.address, error)

    async def replicate_to_new_successors(self) -> None:
        """Copy the keys this node owns to successors that may lack them: new ones
        in the list, or all of them once the predecessor changed (a crashed
        predecessor's keys are ours now, and its successors beyond ours never had
        them), so every key is back at k + 1 nodes after each repair."""
        if self._node.predecessor != self._replicated_for:
            self._replicated = set()
            self._replicated_for = self._node.predecessor
        new = [s for s in self._node.successors if s != self._node.me and s not in self._replicated]
        self._replicated = set(self._node.successors)
        entries = self.entries(self.owns)
        if new and entries:
            await self._replicate(ChordStore(entries), new)

    # -- handlers (registered by ChordNode) -------------------------------------------
    async def rpc_add(self, req: Request) -> Ack:
        """Add a member, atomically here; the owner copies it down the successor list."""
        body: ChordAdd = req.body
        key = key_from(body.key)
        self._node.storage.add(key, body.member, body.ttl, self._node.clock())
        if not body.replica:
            copy = ChordAdd(body.key, body.member, body.ttl, replica=True)
            await self._replicate(copy, self._copy_targets(key))
        return Ack()

    async def rpc_remove(self, req: Request) -> Ack:
        """Remove a member here; the owner copies the removal down the successor list."""
        body: ChordRemove = req.body
        key = key_from(body.key)
        self._node.storage.remove(key, body.member)
        if not body.replica:
            copy = ChordRemove(body.key, body.member, replica=True)
            await self._replicate(copy, self._copy_targets(key))
        return Ack()

    def _copy_targets(self, key: int) -> list[Node]:
        """Where an update of `key` sent here goes on: the successor list, and the
        predecessor if that owns the key. A lookup through routes that predate a
        join ends here, at the joiner's successor, after this node handed the
        joiner its keys (`rpc_notify`): without the copy the owner would miss it."""
        pred = self._node.predecessor
        if pred is None or self.owns(key):
            return list(self._node.successors)
        return [pred, *self._node.successors]

    def rpc_get(self, req: Request) -> ChordValues:
        """The live members of a key stored here (those the filter keeps, if any)."""
        body: ChordGet = req.body
        members = self._node.storage.get(key_from(body.key), self._node.clock())
        if body.filter:
            make = self._filters.get(body.filter)
            if make is None:
                raise ProtocolError(f"no member filter {body.filter!r} on this node")
            try:
                keep = make(body.argument)
            except ValueError as exc:
                raise ProtocolError(f"bad argument to filter {body.filter!r}: {exc}") from exc
            members = {m for m in members if keep(m)}
        return ChordValues(tuple(sorted(members)))

    async def rpc_store(self, req: Request) -> Ack:
        """Store handed-over or replicated entries; with `replicate`, copy them on."""
        body: ChordStore = req.body
        now = self._node.clock()
        for entry in body.entries:  # all checked before any is stored
            key_from(entry.key)
            limits.ttl(entry.ttl)
        for entry in body.entries:
            self._node.storage.add(key_from(entry.key), entry.member, entry.ttl, now)
        if body.replicate and body.entries:
            await self._replicate(ChordStore(body.entries))
        return Ack()
