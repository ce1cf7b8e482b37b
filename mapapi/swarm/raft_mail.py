"""How the Raft groups of one peer reach other peers (DESIGN §13): one `RaftBatch`
notification per peer per round, carrying that peer's messages of every group they
share (CockroachDB's coalesced heartbeats), addressed by `PeerId`.

Node ids in the groups are the top 63 bits of peer ids (`raft_wire.node_id`); the
mail maps them back through the member list, looked up again on a miss, and asks
for the peer's address when it sends, so a peer that restarted on another port is
reached as soon as the swarm knows its new address.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable

from mapapi.core.errors import MapError
from mapapi.core.ids import ChunkId, PeerId
from mapapi.net.messages import RaftBatch, RaftMessage
from mapapi.net.rpc import Rpc
from mapapi.swarm.group_state import AddressFn
from mapapi.swarm.raft_types import NONE, Message
from mapapi.swarm.raft_wire import node_id, to_wire

log = logging.getLogger(__name__)


class RaftMail:
    """The outbox of every group of one peer.

    Args:
        rpc: sends the notifications.
        address: where a peer is reached now.
        peers: every peer a node id may stand for (the member list).
    """

    def __init__(self, rpc: Rpc, address: AddressFn, peers: Callable[[], Iterable[PeerId]]) -> None:
        self.rpc = rpc
        self._address = address
        self._peers = peers
        self._outbox: dict[int, list[RaftMessage]] = {}
        self._by_node: dict[int, PeerId] = {}
        self.frames_sent = 0  # RaftBatch notifications ...
        self.messages_sent = 0  # ... and the Raft messages they carried

    def post(self, chunk: ChunkId, message: Message) -> None:
        """Queue one group's message until the next `flush`."""
        self._outbox.setdefault(message.to, []).append(to_wire(chunk, message))

    def flush(self) -> bool:
        """Send each peer its queued messages as one notification; whether any were queued."""
        outbox, self._outbox = self._outbox, {}
        for to, messages in outbox.items():
            peer = self.peer(to)
            if peer is None:
                log.debug("no known peer for node %d; %d message(s) dropped", to, len(messages))
                continue
            try:
                self.rpc.notify(self._address(peer), RaftBatch(tuple(messages)))
                self.frames_sent += 1
                self.messages_sent += len(messages)
            except MapError as exc:  # Raft retries by itself: a lost message is a late one
                log.debug("raft messages to %s not sent: %s", peer.short, exc)
        return bool(outbox)

    def peers(self, nodes: Iterable[int]) -> list[PeerId]:
        """The peers these node ids stand for, in node order (unknown ones left out)."""
        found = (self.peer(n) for n in sorted(nodes))
        return [p for p in found if p is not None]

    def peer(self, node: int) -> PeerId | None:
        """The peer a node id stands for (None for no node, or one no member matches)."""
        if node == NONE:
            return None
        if node not in self._by_node:
            self._by_node = {node_id(p): p for p in self._peers()}
        return self._by_node.get(node)
