"""A chunk's state in and out of a store, as Raft snapshots carry it (DESIGN §13).

A holder that joins a chunk's group, or lags behind what its leader's log still
holds after compaction, receives a snapshot: the chunk's whole history (revisions
and commit records, since its last `gc`, and the chain's links for what `gc` took),
its clock, and what its log recorded of multi-chunk
transactions (a prepare that still holds the chunk, and every decision, so a late
prepare or decision is decided here as everywhere else). Installing it replaces
the replica in one store transaction with the applied index, and rebuilds the
hash chain from the history, which is the chain its sender holds: commit times
grow in log order, so history order is log order.
"""

from __future__ import annotations

from mapapi.core import codec
from mapapi.core.chunk_state import ChunkState, TxState
from mapapi.core.errors import ChunkNotFound
from mapapi.core.ids import ChunkId
from mapapi.store.base import ReplicaStore, TxRow


class StoreStates:
    """Takes a chunk's state from, and installs one into, a peer's store."""

    def __init__(self, store: ReplicaStore) -> None:
        self.store = store

    def take(self, chunk: ChunkId) -> bytes:
        """The chunk's state as this replica holds it now (at its applied index).

        The history is read before the chain's compacted part: a `gc` in between
        leaves the history a superset of what the part's links leave to rebuild
        (its commits after them are whole), so the receiver's chain is ours."""
        store = self.store
        table = store.chunk_table(chunk)
        revisions = store.chunk_revisions_pb(chunk)  # as messages: no typed revisions between
        commits = tuple(store.chunk_commits(chunk))
        txs = tuple(TxState(c, r.state, r.time, r.data) for c, r in store.raft_txs(chunk))
        state = ChunkState(
            table,
            store.tables()[table],
            store.raft_time(chunk),
            (),  # given as `revisions` below
            commits,
            txs,
            store.replication(chunk),
            tuple(store.chain_base(chunk)),
        )
        return codec.encode_chunk_state(state, revisions)

    def install(self, chunk: ChunkId, data: bytes, index: int) -> None:
        """Make this replica the snapshot's state at log `index`, atomically.

        Raises:
            CorruptRepoError: the snapshot does not parse.
            UsageError: this repository has the chunk's table with another type.
        """
        state = codec.decode_chunk_state(data)
        store = self.store
        with store.exclusive():
            store.install_chunk(
                chunk,
                state.table,
                state.type_name,
                state.revisions,
                state.commits,
                [],
                state.compacted,
            )
            # The sender's records are a superset of ours: ours came from entries before
            # the snapshot's index, and a chunk's log never forgets a transaction.
            for tx in state.txs:
                store.raft_tx_put(chunk, tx.commit_id, TxRow(tx.state, tx.time, tx.data))
            store.set_replication(chunk, state.replication)
            store.raft_applied(chunk, index, state.time)

    def knows(self, chunk: ChunkId) -> bool:
        """Whether the store has the chunk (a founder with a state to hand on: its
        table at least, and any history from before the group)."""
        try:
            self.store.chunk_table(chunk)
        except ChunkNotFound:
            return False
        return True
