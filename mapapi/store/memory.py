"""An in-memory `Store` for unit tests and scratch peers."""

from __future__ import annotations

import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import replace

from mapapi._pb.mapapi.v1 import core_pb2
from mapapi.core import chain, codec
from mapapi.core.errors import ChunkNotFound, UsageError
from mapapi.core.history import CommitRecord, ItemHistory, Revision, revision_at
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.store.base import ChunkInfo, Divergence, IdKind, LogRow, RaftRecord, TxRow, newest_first
from mapapi.store.memory_chain import MemoryChains


class MemoryStore(MemoryChains):
    """Keeps everything in dicts; a re-entrant lock makes commits atomic."""

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self._clock = 0
        self._tables: dict[str, str] = {}
        self._chunks: dict[ChunkId, str] = {}
        self._factors: dict[str, int] = {}  # a table's or a chunk's replication factor, if set
        self._items: dict[ItemId, ItemHistory] = {}
        self._commits: dict[CommitId, tuple[CommitRecord, list[Revision]]] = {}
        self._views: dict[str, bytes] = {}
        self._holders: dict[ChunkId, set[PeerId]] = {}
        self._raft: dict[ChunkId, RaftRecord] = {}
        self._tx: dict[tuple[ChunkId, CommitId], TxRow] = {}
        self._chains: dict[ChunkId, list[tuple[CommitId, bytes]]] = {}
        self._compacted: dict[ChunkId, int] = {}  # of each chain, the links `gc` left bare
        self._diverged: dict[tuple[ChunkId, PeerId], Divergence] = {}

    def close(self) -> None:
        """Nothing to release."""

    def clock(self) -> int:
        """The highest applied commit time."""
        return self._clock

    @contextmanager
    def exclusive(self) -> Iterator[None]:
        """Hold the store's lock."""
        with self._lock:
            yield

    def add_table(self, name: str, type_name: str, replication: int = 0) -> None:
        """Register a table (`replication`: its chunks' factor, 0 for the default)."""
        with self._lock:
            if name in self._tables:
                raise UsageError(f"table {name!r} already exists")
            self._tables[name] = type_name
            self._factors[name] = replication

    def tables(self) -> dict[str, str]:
        """Table name -> type name."""
        return dict(self._tables)

    def add_chunk(self, chunk_id: ChunkId, table: str, replication: int = 0) -> None:
        """Register a chunk (`replication`: its factor, 0 for its table's)."""
        with self._lock:
            if table not in self._tables:
                raise UsageError(f"no table {table!r}")
            if chunk_id not in self._chunks:
                self._chunks[chunk_id] = table
                self._factors[chunk_id] = replication or self._factors.get(table, 0)

    def replication(self, chunk_id: ChunkId) -> int:
        """The chunk's replication factor (0: the swarm's default); raises ChunkNotFound."""
        self.chunk_table(chunk_id)
        return self._factors.get(chunk_id, 0)

    def set_replication(self, chunk_id: ChunkId, factor: int) -> None:
        """Set the chunk's replication factor (as its holders have it)."""
        with self._lock:
            self._factors[chunk_id] = factor

    def chunks(self, table: str | None = None, only: ChunkId | None = None) -> list[ChunkInfo]:
        """The chunks, with their live items' count and bytes now (`only`: that one, if held)."""
        counts: dict[ChunkId, list[int]] = {cid: [0, 0] for cid in self._chunks}
        for history in self._items.values():
            latest = history.latest()
            if latest is not None and not latest.removed:
                counts[latest.chunk_id][0] += 1
                counts[latest.chunk_id][1] += len(latest.data)
        return [
            ChunkInfo(cid, t, *counts[cid])
            for cid, t in sorted(self._chunks.items())
            if (table is None or t == table) and (only is None or cid == only)
        ]

    def chunk_ids(self, table: str | None = None) -> list[ChunkId]:
        """The ids of `chunks(table)`, in order, without counting their items."""
        return [cid for cid, t in sorted(self._chunks.items()) if table is None or t == table]

    def chunk_table(self, chunk_id: ChunkId) -> str:
        """The table of a chunk."""
        try:
            return self._chunks[chunk_id]
        except KeyError:
            raise ChunkNotFound(f"no chunk {chunk_id} here") from None

    def read(self, item_id: ItemId, time: int) -> Revision | None:
        """Newest revision at or before `time`."""
        history = self._items.get(item_id)
        if history is None:
            return None
        return revision_at(history.revisions, time)

    def history(self, item_id: ItemId) -> list[Revision]:
        """All revisions of an item."""
        history = self._items.get(item_id)
        return list(history.revisions) if history else []

    def _in_scope(self, r: Revision, table: str | None, chunk: ChunkId | None) -> bool:
        return (table is None or r.table == table) and (chunk is None or r.chunk_id == chunk)

    def scan(
        self, time: int, *, table: str | None = None, chunk: ChunkId | None = None
    ) -> list[Revision]:
        """Items visible at `time`."""
        with self._lock:
            found = [h.at(time) for h in self._items.values()]
        return sorted(
            (r for r in found if r is not None and self._in_scope(r, table, chunk)),
            key=lambda r: r.item_id,
        )

    def latest(self, item_ids: Sequence[ItemId]) -> dict[ItemId, Revision]:
        """Newest revision per item."""
        out = {}
        for item_id in item_ids:
            history = self._items.get(item_id)
            latest = history.latest() if history else None
            if latest is not None:
                out[item_id] = latest
        return out

    def changed_since(
        self, time: int, *, table: str | None = None, chunk: ChunkId | None = None
    ) -> list[Revision]:
        """Revisions written after `time`."""
        with self._lock:
            found = [r for h in self._items.values() for r in h.revisions if r.update_time > time]
        return sorted(
            (r for r in found if self._in_scope(r, table, chunk)),
            key=lambda r: (r.update_time, r.item_id),
        )

    def apply_commit(self, record: CommitRecord, revisions: Sequence[Revision]) -> None:
        """Apply atomically under the lock, linking the commit into the chain of each
        chunk whose part of it is new here (as the SQLite store)."""
        with self._lock:
            had = {r.chunk_id for r in self._commits.get(record.id, (record, []))[1]}
            self._write(record, revisions)
            fresh = {r.chunk_id for r in revisions} - had
            for chunk, link in chain.extend(self.chain_head, record, revisions, fresh):
                self._chains.setdefault(chunk, []).append((record.id, link))

    def _write(self, record: CommitRecord, revisions: Sequence[Revision]) -> None:
        with self._lock:
            # Idempotent and additive, like the SQLite store.
            applied = self._commits.setdefault(record.id, (record, []))[1]
            known = {(r.item_id, r.update_time) for r in applied}
            for revision in revisions:
                if (revision.item_id, revision.update_time) in known:
                    continue
                self._items.setdefault(revision.item_id, ItemHistory()).add(revision)
                applied.append(revision)
            self._clock = max(self._clock, record.time)

    def commits(self, limit: int | None = None) -> list[CommitRecord]:
        """Newest first."""
        records = newest_first([c for c, _ in self._commits.values()])
        return records[:limit] if limit is not None else records

    def commit_record(self, commit_id: CommitId) -> CommitRecord | None:
        """One record."""
        entry = self._commits.get(commit_id)
        return entry[0] if entry else None

    def commit_revisions(self, commit_id: CommitId) -> list[Revision]:
        """What one commit wrote."""
        entry = self._commits.get(commit_id)
        return list(entry[1]) if entry else []

    def resolve_prefix(self, kind: IdKind, prefix: str) -> list[str]:
        """Ids starting with `prefix`."""
        pool: dict[str, object] = {
            "item": self._items,
            "chunk": self._chunks,
            "commit": self._commits,
        }[kind]  # type: ignore[assignment]
        return sorted(i for i in pool if i.startswith(prefix))[:2]

    def load_view(self, name: str) -> bytes | None:
        """A view."""
        return self._views.get(name)

    def save_view(self, name: str, blob: bytes) -> None:
        """Store a view."""
        self._views[name] = blob

    def delete_view(self, name: str) -> None:
        """Drop a view."""
        self._views.pop(name, None)

    def views(self) -> dict[str, bytes]:
        """All views."""
        return dict(self._views)

    # -- replication -------------------------------------------------------------
    def holders(self, chunk_id: ChunkId) -> list[PeerId]:
        """The peers that hold a chunk, in id order."""
        return sorted(self._holders.get(chunk_id, ()))

    def holdings(self) -> dict[ChunkId, list[PeerId]]:
        """Every chunk's holders, in id order (chunks with a recorded holder set)."""
        return {c: sorted(p) for c, p in sorted(self._holders.items()) if p}

    def set_holders(self, chunk_id: ChunkId, peers: Sequence[PeerId]) -> None:
        """Replace a chunk's holder set."""
        self._holders[chunk_id] = set(peers)

    def chunk_revisions(self, chunk_id: ChunkId) -> list[Revision]:
        """The full history of a chunk's items."""
        with self._lock:
            found = [r for h in self._items.values() for r in h.revisions if r.chunk_id == chunk_id]
        return sorted(found, key=lambda r: (r.item_id, r.update_time))

    def chunk_revisions_pb(self, chunk_id: ChunkId) -> list[core_pb2.Revision]:
        """`chunk_revisions` as wire messages (what a Raft snapshot carries)."""
        return [codec.revision_to_pb(r) for r in self.chunk_revisions(chunk_id)]

    def chunk_commits(self, chunk_id: ChunkId) -> list[CommitRecord]:
        """Records of the commits that wrote to a chunk, oldest first."""
        ids = {r.commit_id for r in self.chunk_revisions(chunk_id)}
        return sorted((self._commits[i][0] for i in ids), key=lambda c: c.time)

    def item_chunk(self, item_id: ItemId) -> ChunkId | None:
        """The chunk of an item."""
        history = self._items.get(item_id)
        latest = history.latest() if history else None
        return latest.chunk_id if latest else None

    def install_chunk(
        self,
        chunk_id: ChunkId,
        table: str,
        type_name: str,
        revisions: Sequence[Revision],
        commits: Sequence[CommitRecord],
        holders: Sequence[PeerId],
        base: Sequence[tuple[CommitId, bytes]] = (),
    ) -> None:
        """Take in a replica received from a holder, replacing what this store had
        of the chunk (as `SqliteStore.install_chunk`)."""
        with self._lock:
            known = self._tables.get(table)
            if known is not None and known != type_name:
                raise UsageError(f"table {table!r} holds {known} here but {type_name} in the swarm")
            records = {c.id: c for c in commits}
            had = {r.commit_id for r in self.chunk_revisions(chunk_id)}
            self.drop_chunk(chunk_id)
            for commit_id in had - set(records):
                if not self._commits[commit_id][1]:
                    del self._commits[commit_id]
            self._tables.setdefault(table, type_name)
            self._chunks.setdefault(chunk_id, table)
            for revision in revisions:
                self._write(records[revision.commit_id], [revision])
            self.set_holders(chunk_id, holders)
            self._chains[chunk_id] = chain.rebuild(chunk_id, records, revisions, base)
            self._compacted[chunk_id] = len(base)
            self._diverged = {k: v for k, v in self._diverged.items() if k[0] != chunk_id}

    def drop_chunk(self, chunk_id: ChunkId) -> None:
        """Forget a chunk's replica."""
        with self._lock:
            self._chunks.pop(chunk_id, None)
            self._holders.pop(chunk_id, None)
            for item_id in [
                i for i, h in self._items.items() if h.revisions[0].chunk_id == chunk_id
            ]:
                del self._items[item_id]
            # commit records stay (as in SQLite) but forget the dropped revisions, or
            # installing the chunk again would skip them as applied already
            for _, applied in self._commits.values():
                applied[:] = [r for r in applied if r.chunk_id != chunk_id]
            # so do the chain (installing the chunk again rebuilds it); what other
            # holders' chains showed of this replica goes with it
            self._diverged = {k: v for k, v in self._diverged.items() if k[0] != chunk_id}

    # -- the Raft group of each chunk ---------------------------------------------------
    def raft_load(self, chunk_id: ChunkId) -> RaftRecord | None:
        """The kept state of the chunk's Raft group, or None."""
        with self._lock:
            return self._raft.get(chunk_id)

    def raft_save(
        self,
        chunk_id: ChunkId,
        *,
        hard: tuple[int, int, int] | None = None,
        entries: Sequence[LogRow] = (),
        snapshot: tuple[int, int, bytes, bytes] | None = None,
        compacted: bool = False,
    ) -> None:
        """Keep a snapshot, then entries, then the hard state (as `raft_sql.save`)."""
        with self._lock:
            kept = self._raft.get(chunk_id) or RaftRecord(0, 0, 0, 0, 0, 0, b"", b"", (), 0)
            if snapshot is not None and (not compacted or kept.snap_index < snapshot[0]):
                index, term, config, data = snapshot
                # our own snapshot keeps the entries after it; a leader's replaces the log
                after = tuple(e for e in kept.entries if e.index > index) if compacted else ()
                commit = kept.commit if compacted else max(kept.commit, index)
                kept = replace(
                    kept,
                    snap_index=index,
                    snap_term=term,
                    snap_config=config,
                    snap_data=data,
                    commit=commit,
                    entries=after,
                )
            if entries:
                first = entries[0].index
                kept = replace(
                    kept, entries=(*(e for e in kept.entries if e.index < first), *entries)
                )
            if hard is not None:
                kept = replace(kept, term=hard[0], vote=hard[1], commit=hard[2])
            self._raft[chunk_id] = kept

    def raft_applied(self, chunk_id: ChunkId, index: int, time: int = 0) -> None:
        """Keep the applied index and the chunk's newest commit time.

        Raises:
            ValueError: it goes backwards, or the chunk has no group state.
        """
        with self._lock:
            kept = self._raft.get(chunk_id)
            if kept is None:
                raise ValueError(f"chunk {chunk_id} has no Raft state to apply to")
            if index < kept.applied:
                raise ValueError(
                    f"chunk {chunk_id}: applied index {index} is behind {kept.applied}"
                )
            self._raft[chunk_id] = replace(kept, applied=index, time=max(kept.time, time))

    def integrity(self) -> list[str]:
        """Nothing to check in memory."""
        return []

    def raft_applied_index(self, chunk_id: ChunkId) -> int | None:
        """The chunk's applied log index, or None without a Raft group."""
        with self._lock:
            kept = self._raft.get(chunk_id)
            return None if kept is None else kept.applied

    def raft_time(self, chunk_id: ChunkId) -> int:
        """The newest commit time applied from the chunk's log."""
        with self._lock:
            kept = self._raft.get(chunk_id)
            return 0 if kept is None else kept.time

    def raft_tx(self, chunk_id: ChunkId, commit_id: CommitId) -> TxRow | None:
        """What the chunk's log recorded of a multi-chunk transaction, or None."""
        with self._lock:
            return self._tx.get((chunk_id, commit_id))

    def raft_tx_put(self, chunk_id: ChunkId, commit_id: CommitId, row: TxRow) -> None:
        """Record what the chunk's log did with a transaction."""
        with self._lock:
            self._tx[(chunk_id, commit_id)] = row

    def raft_tx_prepared(self, chunk_id: ChunkId) -> list[tuple[CommitId, TxRow]]:
        """The transactions prepared on the chunk and not decided there yet."""
        return [(c, row) for c, row in self.raft_txs(chunk_id) if row.state == "prepared"]

    def raft_txs(self, chunk_id: ChunkId) -> list[tuple[CommitId, TxRow]]:
        """Every transaction the chunk's log recorded, prepared or decided."""
        with self._lock:
            return sorted((c, row) for (chunk, c), row in self._tx.items() if chunk == chunk_id)

    def raft_drop(self, chunk_id: ChunkId) -> None:
        """Forget the chunk's group state."""
        with self._lock:
            self._raft.pop(chunk_id, None)
            self._tx = {k: v for k, v in self._tx.items() if k[0] != chunk_id}
