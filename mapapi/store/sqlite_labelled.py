"""`LabelledSqliteStore`: the SQLite store with the application's label index
(`mapapi.store.labels`, tables in `mapapi.store.sqlite_labels`).

It writes what `SqliteStore` writes, and in the same SQL transaction (nested
write sections join the outer one) indexes it: every path that applies a
commit (a local commit, a holder's batch, a Raft entry), installs a replica
(participation, catch-up) or drops one goes through `apply_commit`,
`install_chunk` or `drop_chunk`, so the index and the summaries follow every
replica whatever path changed it.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, PeerId
from mapapi.store import sqlite_labels
from mapapi.store.labels import Labels, LabelSummary
from mapapi.store.sqlite import SqliteStore

log = logging.getLogger(__name__)


class LabelledSqliteStore(SqliteStore):
    """A `SqliteStore` that keeps a label index (`LabelledStore`).

    Args:
        labels: how rows are labelled (the application's).
    """

    def __init__(self, path: str | Path, labels: Labels, *, create: bool = False) -> None:
        super().__init__(path, create=create)
        self.labels = labels
        con = self._con()
        if not sqlite_labels.ready(con):
            with self._write(con):
                if not sqlite_labels.ready(con):
                    sqlite_labels.setup(con)
        self._complete()

    def _complete(self) -> None:
        """Bring the index up to date if it is not (see `sqlite_labels`)."""
        con = self._con()
        if sqlite_labels.complete(con, self.labels):
            return
        with self._write(con):
            if not sqlite_labels.complete(con, self.labels):
                log.info("labelling the store %s (once, after a change it missed)", self.path)
                read = sqlite_labels.relabel(con, self.path, self.labels)
                log.info("labelled %d revisions of %s", read, self.path)

    def apply_commit(self, record: CommitRecord, revisions: Sequence[Revision]) -> None:
        """Write the record and its revisions, and index them, in one SQL transaction."""
        con = self._con()
        with self._write(con):
            was_complete = sqlite_labels.complete(con, self.labels)
            fresh = sqlite_labels.unwritten(con, record, revisions)
            super().apply_commit(record, revisions)
            if was_complete:
                sqlite_labels.committed(con, fresh, self.labels, self.tables())
                sqlite_labels.mark_complete(con, self.labels)

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
        """Take in a replica, and index it in place of what the index had of it."""
        con = self._con()
        with self._write(con):
            was_complete = sqlite_labels.complete(con, self.labels)
            super().install_chunk(chunk_id, table, type_name, revisions, commits, holders, base)
            if was_complete:
                fn = self.labels.of(type_name)
                sqlite_labels.installed(con, chunk_id, revisions, fn)
                sqlite_labels.mark_complete(con, self.labels)

    def drop_chunk(self, chunk_id: ChunkId) -> None:
        """Forget a chunk's replica and what the index has of it."""
        con = self._con()
        with self._write(con):
            was_complete = sqlite_labels.complete(con, self.labels)
            super().drop_chunk(chunk_id)
            sqlite_labels.dropped(con, chunk_id)
            if was_complete:
                sqlite_labels.mark_complete(con, self.labels)

    def scan_labelled(
        self, time: int, label: str, *, table: str | None = None, chunk: ChunkId | None = None
    ) -> list[Revision]:
        """The items labelled `label` visible at `time` (in a table or chunk), by id."""
        self._complete()
        con = self._con()
        sets = [s for s, _ in sqlite_labels.label_sets(con, label, table, chunk)]
        if not sets:
            return []
        rows = con.execute(sqlite_labels.scan_sql(len(sets)), [*sets, time])
        return [self._revision(row) for row in rows]

    def label_chunks(self, label: str, table: str | None = None) -> list[ChunkId]:
        """The chunks that hold or held rows labelled `label` (of `table`)."""
        self._complete()
        return [c for _, c in sqlite_labels.label_sets(self._con(), label, table, None)]

    def label_summaries(self, labels: Sequence[str] | None = None) -> list[LabelSummary]:
        """Every label's summary per chunk now (of `labels`, if given)."""
        self._complete()
        return sqlite_labels.summaries(self._con(), labels)
