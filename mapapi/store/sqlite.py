"""The default `Store`: one SQLite file in WAL mode, one SQL transaction per commit.

Several threads and processes may open the file, each thread with its own
connection; committers serialise on SQLite's write lock (`BEGIN IMMEDIATE`),
which makes validation plus apply atomic across processes. WAL with `synchronous=NORMAL`
keeps every acknowledged commit through a killed process; an OS crash may drop the last few."""

from __future__ import annotations

import sqlite3
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from mapapi._pb.mapapi.v1 import core_pb2
from mapapi.core import chain
from mapapi.core.errors import ChunkNotFound, CorruptRepoError, UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.store import chain_sql, raft_sql, sqlite_replica, sqlite_rows, sqlite_schema
from mapapi.store.base import ChunkInfo, IdKind, RaftRecord, TxRow
from mapapi.store.file_check import check_file, storage_error
from mapapi.store.mark import HighWater
from mapapi.store.sqlite_chain import SqliteChains
from mapapi.store.sqlite_connection import Connections
from mapapi.store.sqlite_rows import COMMIT_COLUMNS as _COMMIT_COLUMNS
from mapapi.store.sqlite_rows import REV_COLUMNS as _REV_COLUMNS
from mapapi.store.sqlite_rows import REV_FROM as _REV_FROM
from mapapi.store.sqlite_views import SqliteViews


class SqliteStore(SqliteChains, SqliteViews):
    """A `Store` in one SQLite file (see the module docstring)."""

    def __init__(self, path: str | Path, *, create: bool = False) -> None:
        """Open (or with `create`, create) the store at `path`.

        Raises:
            CorruptRepoError: the file is not a SQLite database, not a mapapi store,
                of a newer store format, or lacks a table (`file_check`).
            RepoError: the file cannot be read.
        """
        self.path = Path(path)
        if not create and not self.path.exists():
            raise CorruptRepoError(f"store file {self.path} is missing")
        if self.path.exists() and (not create or self.path.stat().st_size):
            check_file(self.path)
        self.mark = HighWater(self.path)  # `store.mark`, beside the file: see store/mark.py
        self._db = Connections(self.path, self.mark.committed, self.mark.rolled_back)
        self._con = self._db.con
        self._write = self._db.write
        self.worker = self._db.worker  # a worker thread's use, which `close` waits for
        self.no_wait, self.checkpoint = self._db.no_wait, self._db.checkpoint  # store/wal.py
        try:
            sqlite_schema.setup(self._db, create)
        except CorruptRepoError:
            self.close()
            raise
        except sqlite3.DatabaseError as exc:
            self.close()
            # A full or failing disk is no damage of the store: say so (issue 18).
            raise storage_error(self.path, exc) or CorruptRepoError(
                f"{self.path} is not a mapapi store ({exc}); restore it from a backup "
                "or clone the repository again"
            ) from exc

    def close(self) -> None:
        """Close every connection of any thread, once no `worker` thread runs."""
        self._db.close()

    def clock(self) -> int:
        """The highest applied commit time."""
        row = self._con().execute("SELECT value FROM meta WHERE key = 'clock'").fetchone()
        return int(row[0])

    @contextmanager
    def exclusive(self) -> Iterator[None]:
        """Hold SQLite's write lock (other processes' committers wait)."""
        with self._write(self._con()):
            yield

    def get_meta(self, key: str) -> str | None:
        """A value of the store's key-value metadata."""
        row = self._con().execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else str(row[0])

    def add_table(self, name: str, type_name: str, replication: int = 0) -> None:
        """Register a table (`replication`: its chunks' factor, 0 for the default)."""
        con = self._con()
        with self._write(con):
            try:
                sql = "INSERT INTO tables (name, type_name, replication) VALUES (?, ?, ?)"
                con.execute(sql, (name, type_name, replication))
            except sqlite3.IntegrityError:
                raise UsageError(f"table {name!r} already exists") from None

    def tables(self) -> dict[str, str]:
        """Table name -> type name."""
        return dict(self._con().execute("SELECT name, type_name FROM tables ORDER BY name"))

    def add_chunk(self, chunk_id: ChunkId, table: str, replication: int = 0) -> None:
        """Register a chunk (`replication`: its factor, 0 for its table's)."""
        con = self._con()
        with self._write(con):
            try:
                sqlite_replica.add_chunk(con, chunk_id, table, replication)
            except sqlite3.IntegrityError:
                raise UsageError(f"no table {table!r}") from None

    def replication(self, chunk_id: ChunkId) -> int:
        """The chunk's replication factor (0: the swarm's default); raises ChunkNotFound."""
        return sqlite_replica.replication(self._con(), chunk_id)

    def set_replication(self, chunk_id: ChunkId, factor: int) -> None:
        """Set the chunk's replication factor (as its holders have it)."""
        con = self._con()
        with self._write(con):
            con.execute("UPDATE chunks SET replication = ? WHERE id = ?", (factor, chunk_id))

    def chunks(self, table: str | None = None, only: ChunkId | None = None) -> list[ChunkInfo]:
        """Chunks with their live item counts and bytes now (`only`: just that one, if held)."""
        sql = """
            SELECT c.id, c.table_name, COUNT(r.item_id), COALESCE(SUM(LENGTH(r.data)), 0)
            FROM chunks c
            LEFT JOIN revisions r ON r.chunk_no = c.no AND r.removed = 0
             AND r.update_time = (SELECT MAX(update_time) FROM revisions WHERE item_id = r.item_id)
            WHERE (? IS NULL OR c.table_name = ?) AND (? IS NULL OR c.id = ?)
            GROUP BY c.id ORDER BY c.id"""
        rows = self._con().execute(sql, (table, table, only, only))
        return [ChunkInfo(ChunkId(c), t, n, b) for c, t, n, b in rows]

    def chunk_ids(self, table: str | None = None) -> list[ChunkId]:
        """The ids of `chunks(table)`, in order, without counting their items."""
        sql = "SELECT id FROM chunks WHERE ? IS NULL OR table_name = ? ORDER BY id"
        return [ChunkId(cid) for (cid,) in self._con().execute(sql, (table, table))]

    def chunk_table(self, chunk_id: ChunkId) -> str:
        """The table of a chunk."""
        row = (
            self._con()
            .execute("SELECT table_name FROM chunks WHERE id = ?", (chunk_id,))
            .fetchone()
        )
        if row is None:
            raise ChunkNotFound(f"no chunk {chunk_id} here")
        return str(row[0])

    def read(self, item_id: ItemId, time: int) -> Revision | None:
        """Newest revision at or before `time`."""
        row = (
            self._con()
            .execute(
                f"SELECT {_REV_COLUMNS} FROM {_REV_FROM} WHERE r.item_id = ? "
                "AND r.update_time <= ? ORDER BY r.update_time DESC LIMIT 1",
                (sqlite_rows.item_key(item_id), time),
            )
            .fetchone()
        )
        return None if row is None else self._revision(row)

    def history(self, item_id: ItemId) -> list[Revision]:
        """All revisions of an item."""
        rows = self._con().execute(
            f"SELECT {_REV_COLUMNS} FROM {_REV_FROM} WHERE r.item_id = ? ORDER BY r.update_time",
            (sqlite_rows.item_key(item_id),),
        )
        return [self._revision(r) for r in rows]

    def scan(
        self, time: int, *, table: str | None = None, chunk: ChunkId | None = None
    ) -> list[Revision]:
        """Items visible at `time`."""
        where, args = sqlite_rows.scope(table, chunk)
        sql = (
            f"SELECT {_REV_COLUMNS} FROM {_REV_FROM} "
            "WHERE r.update_time = (SELECT MAX(update_time) FROM revisions "
            "  WHERE item_id = r.item_id AND update_time <= ?) "
            f"AND r.removed = 0{where} ORDER BY r.item_id"
        )
        return [self._revision(row) for row in self._con().execute(sql, [time, *args])]

    def latest(self, item_ids: Sequence[ItemId]) -> dict[ItemId, Revision]:
        """Newest revision per item."""
        out: dict[ItemId, Revision] = {}
        con = self._con()
        for start in range(0, len(item_ids), 500):
            batch = [sqlite_rows.item_key(i) for i in item_ids[start : start + 500]]
            marks = ",".join("?" * len(batch))
            sql = (
                f"SELECT {_REV_COLUMNS} FROM {_REV_FROM} "
                f"WHERE r.item_id IN ({marks}) AND r.update_time = "
                "(SELECT MAX(update_time) FROM revisions WHERE item_id = r.item_id)"
            )
            for row in con.execute(sql, batch):
                revision = self._revision(row)
                out[revision.item_id] = revision
        return out

    def changed_since(
        self, time: int, *, table: str | None = None, chunk: ChunkId | None = None
    ) -> list[Revision]:
        """Revisions written after `time` (to `chunk`, or to `table`'s chunks): what
        each chunk got since, through its time index, whatever other chunks got."""
        sql, args = sqlite_rows.since(time, table, chunk)
        sql = (
            f"SELECT {_REV_COLUMNS} FROM {_REV_FROM} WHERE {sql} ORDER BY r.update_time, r.item_id"
        )
        return [self._revision(row) for row in self._con().execute(sql, args)]

    def apply_commit(self, record: CommitRecord, revisions: Sequence[Revision]) -> None:
        """Write the record, its revisions and its chain links, in one transaction."""
        con = self._con()
        with self._write(con):
            self.mark.before_write(con)
            if sqlite_rows.write_record(con, record):
                self.mark.wrote(record.id, record.time)
                fresh = {r.chunk_id for r in revisions}  # none of it was here
            else:
                fresh = chain_sql.unwritten(con, record, revisions)
            sqlite_rows.write_revisions(con, record, revisions)
            chain_sql.extend(con, record, revisions, fresh)

    def _revision(self, row: sqlite3.Row | tuple) -> Revision:
        return sqlite_rows.revision(self.path, row)

    def commits(self, limit: int | None = None) -> list[CommitRecord]:
        """Newest first."""
        rows = self._con().execute(
            f"SELECT {_COMMIT_COLUMNS} FROM commits ORDER BY time DESC, id DESC LIMIT ?",
            (-1 if limit is None else limit,),
        )
        return [sqlite_rows.record(self.path, r) for r in rows]

    def commit_record(self, commit_id: CommitId) -> CommitRecord | None:
        """One record."""
        return sqlite_rows.commit_record(self.path, self._con(), commit_id)

    def commit_revisions(self, commit_id: CommitId) -> list[Revision]:
        """What one commit wrote (held here), by item."""
        record = self.commit_record(commit_id)
        rows = [] if record is None else sqlite_rows.of_record(self._con(), record)
        return sorted((self._revision(r) for r in rows), key=lambda r: r.item_id)

    def resolve_prefix(self, kind: IdKind, prefix: str) -> list[str]:
        """Ids starting with `prefix`."""
        if kind == "item":
            return sqlite_rows.item_prefix(self._con(), prefix)
        table = {"chunk": "chunks", "commit": "commits"}[kind]
        hi = prefix + "g"  # every hex id with this prefix sorts below prefix + 'g'
        rows = self._con().execute(
            f"SELECT id FROM {table} WHERE id >= ? AND id < ? ORDER BY id LIMIT 2", (prefix, hi)
        )
        return [r[0] for r in rows]

    # -- replication -------------------------------------------------------------
    def holders(self, chunk_id: ChunkId) -> list[PeerId]:
        """The peers that hold a chunk, in id order."""
        return sqlite_replica.holders(self._con(), chunk_id)

    def holdings(self) -> dict[ChunkId, list[PeerId]]:
        """Every chunk's holders, in id order (chunks with a recorded holder set)."""
        return sqlite_replica.holdings(self._con())

    def set_holders(self, chunk_id: ChunkId, peers: Sequence[PeerId]) -> None:
        """Replace a chunk's holder set."""
        con = self._con()
        with self._write(con):
            sqlite_replica.set_holders(con, chunk_id, peers)

    def chunk_revisions(self, chunk_id: ChunkId) -> list[Revision]:
        """Every revision of every item of a chunk (its full history)."""
        return sqlite_replica.chunk_revisions(self.path, self._con(), chunk_id)

    def chunk_revisions_pb(self, chunk_id: ChunkId) -> list[core_pb2.Revision]:
        """`chunk_revisions` as wire messages, built straight from the rows."""
        return sqlite_replica.chunk_revisions_pb(self.path, self._con(), chunk_id)

    def chunk_commits(self, chunk_id: ChunkId) -> list[CommitRecord]:
        """The records of every commit that wrote to a chunk, oldest first."""
        return sqlite_replica.chunk_commits(self.path, self._con(), chunk_id)

    def item_chunk(self, item_id: ItemId) -> ChunkId | None:
        """The chunk an item belongs to, if this store has it."""
        row = (
            self._con()
            .execute(
                "SELECT c.id FROM revisions r JOIN chunks c ON c.no = r.chunk_no "
                "WHERE r.item_id = ? LIMIT 1",
                (sqlite_rows.item_key(item_id),),
            )
            .fetchone()
        )
        return None if row is None else ChunkId(row[0])

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
        """Take in a replica received from a holder, atomically (all or nothing).

        It replaces what this store had of the chunk: a revision the holder lacks
        goes, and so does the record of a commit left with no revision at all.
        `base` is the holder's compacted chain (`chain_base`).

        Raises:
            UsageError: this repository has a table of that name with another type.
        """
        try:  # hashed before the write lock is taken: installs hold it long enough
            links = chain.rebuild(chunk_id, {c.id: c for c in commits}, revisions, base)
        except KeyError:  # a revision of a commit recorded only here: from the store
            links = None
        con = self._con()
        with self._write(con):
            self.mark.before_write(con)
            replica = (table, type_name, revisions, commits, holders)
            sqlite_replica.install(self.path, con, chunk_id, *replica)
            if links is None:
                chain_sql.replace(con, chunk_id, list(base), len(base))
                chain_sql.rebuild(con, self.path, chunk_id)
            else:
                chain_sql.replace(con, chunk_id, links, len(base))
            chain_sql.forget(con, chunk_id)
            if commits:
                newest = max(commits, key=lambda c: (c.time, c.id))
                self.mark.wrote(newest.id, newest.time)

    def raft_load(self, chunk_id: ChunkId) -> RaftRecord | None:
        """The persisted state of the chunk's Raft group, or None."""
        return raft_sql.load(self._con(), chunk_id)

    def raft_save(self, chunk_id: ChunkId, **parts: Any) -> None:
        """Persist one Ready's snapshot, entries and hard state in one transaction
        (the keywords of `Store.raft_save`)."""
        self._in_write(raft_sql.save, chunk_id, **parts)

    def raft_applied(self, chunk_id: ChunkId, index: int, time: int = 0) -> None:
        """Record the applied index and time (joins the caller's `exclusive()`)."""
        self._in_write(raft_sql.set_applied, chunk_id, index, time)

    def raft_applied_index(self, chunk_id: ChunkId) -> int | None:
        """The chunk's applied log index; None if it has no group (reads no log)."""
        return raft_sql.applied_index(self._con(), chunk_id)

    def integrity(self) -> list[str]:
        """SQLite's own check of the file (`PRAGMA quick_check`); empty when sound."""
        rows = [str(r[0]) for r in self._con().execute("PRAGMA quick_check") if r[0] != "ok"]
        return [f"{self.path}: {r}" for r in rows]

    def raft_time(self, chunk_id: ChunkId) -> int:
        """The newest commit time applied from the chunk's log."""
        return raft_sql.chunk_time(self._con(), chunk_id)

    def raft_tx(self, chunk_id: ChunkId, commit_id: CommitId) -> TxRow | None:
        """What the chunk's log recorded of a multi-chunk transaction, or None."""
        return raft_sql.tx_get(self._con(), chunk_id, commit_id)

    def raft_tx_put(self, chunk_id: ChunkId, commit_id: CommitId, row: TxRow) -> None:
        """Record what the chunk's log did with a transaction (joins `exclusive()`)."""
        self._in_write(raft_sql.tx_put, chunk_id, commit_id, row)

    def raft_tx_prepared(self, chunk_id: ChunkId) -> list[tuple[CommitId, TxRow]]:
        """The transactions prepared on the chunk and not decided there yet."""
        return [(CommitId(c), r) for c, r in raft_sql.tx_rows(self._con(), chunk_id, True)]

    def raft_txs(self, chunk_id: ChunkId) -> list[tuple[CommitId, TxRow]]:
        """Every transaction the chunk's log recorded, prepared or decided."""
        return [(CommitId(c), r) for c, r in raft_sql.tx_rows(self._con(), chunk_id, False)]

    def raft_drop(self, chunk_id: ChunkId) -> None:
        """Forget the chunk's group state."""
        self._in_write(raft_sql.drop, chunk_id)

    def _in_write(self, fn: Callable[..., None], *args: Any, **kwargs: Any) -> None:
        """`fn(connection, *args, **kwargs)` in a write (joining `exclusive()`)."""
        con = self._con()
        with self._write(con):
            fn(con, *args, **kwargs)

    def drop_chunk(self, chunk_id: ChunkId) -> None:
        """Forget a chunk's replica and divergences; its commit records and chain stay."""
        con = self._con()
        with self._write(con):
            sqlite_replica.drop(con, chunk_id)
            chain_sql.forget(con, chunk_id)
