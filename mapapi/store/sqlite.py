"""The default `Store`: one SQLite file in WAL mode, one SQL transaction per commit.

Several threads and several processes may open the same file. Each thread
gets its own connection; committers serialise on SQLite's write lock
(`BEGIN IMMEDIATE`), which makes validation plus apply atomic across processes.
WAL with `synchronous=NORMAL` survives a killed process with every acknowledged
commit intact; only an OS crash or power loss may drop the last few commits.
"""

from __future__ import annotations

import sqlite3
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from mapapi.core.errors import ChunkNotFound, CorruptRepoError, LockTimeout, UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.store import raft_sql
from mapapi.store.base import ChunkInfo, IdKind, LogRow, RaftRecord
from mapapi.store.file_check import check_file, check_schema, storage_error

FORMAT = "mapapi-store"
SCHEMA_VERSION = 1
BUSY_TIMEOUT_MS = 30_000

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS tables (name TEXT PRIMARY KEY, type_name TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS chunks (
    id TEXT PRIMARY KEY, table_name TEXT NOT NULL REFERENCES tables(name));
CREATE TABLE IF NOT EXISTS revisions (
    item_id TEXT NOT NULL, update_time INTEGER NOT NULL, table_name TEXT NOT NULL,
    chunk_id TEXT NOT NULL, data BLOB NOT NULL, insert_time INTEGER NOT NULL,
    removed INTEGER NOT NULL, author TEXT NOT NULL, commit_id TEXT NOT NULL,
    PRIMARY KEY (item_id, update_time)) WITHOUT ROWID;
CREATE INDEX IF NOT EXISTS revisions_chunk ON revisions (chunk_id, item_id);
CREATE INDEX IF NOT EXISTS revisions_table ON revisions (table_name, item_id);
CREATE INDEX IF NOT EXISTS revisions_commit ON revisions (commit_id);
CREATE INDEX IF NOT EXISTS revisions_time ON revisions (update_time);
CREATE TABLE IF NOT EXISTS commits (
    id TEXT PRIMARY KEY, time INTEGER NOT NULL, author TEXT NOT NULL,
    message TEXT NOT NULL, chunks TEXT NOT NULL,
    author_name TEXT NOT NULL DEFAULT '', view TEXT NOT NULL DEFAULT '');
CREATE INDEX IF NOT EXISTS commits_time ON commits (time);
CREATE TABLE IF NOT EXISTS views (name TEXT PRIMARY KEY, body BLOB NOT NULL);
CREATE TABLE IF NOT EXISTS holders (
    chunk_id TEXT NOT NULL REFERENCES chunks(id) ON DELETE CASCADE, peer_id TEXT NOT NULL,
    PRIMARY KEY (chunk_id, peer_id)) WITHOUT ROWID;
"""

# Columns added since format 1, with how to add them to an older store (its
# records then name no author and no view: `log` falls back to other names).
_ADDED_COLUMNS = {
    "commits": (
        ("author_name", "TEXT NOT NULL DEFAULT ''"),
        ("view", "TEXT NOT NULL DEFAULT ''"),
    ),
}
_COMMIT_COLUMNS = "id, time, author, message, chunks, author_name, view"

_REV_COLUMNS = (
    "item_id, table_name, chunk_id, data, insert_time, update_time, removed, author, commit_id"
)


def _scope(table: str | None, chunk: ChunkId | None) -> tuple[str, list[object]]:
    clauses: list[str] = []
    args: list[object] = []
    if table is not None:
        clauses.append("table_name = ?")
        args.append(table)
    if chunk is not None:
        clauses.append("chunk_id = ?")
        args.append(chunk)
    return "".join(f" AND r.{c}" for c in clauses), args


class SqliteStore:
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
        self._local = threading.local()
        self._all: list[sqlite3.Connection] = []
        self._all_lock = threading.Lock()
        try:
            self._setup(create)
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

    def _setup(self, create: bool) -> None:
        con = self._con()
        if create and con.execute("SELECT 1 FROM sqlite_master").fetchone() is None:
            # Only an empty database becomes a new store: never add our tables to
            # another application's database (it fails the marker check below).
            con.execute("PRAGMA journal_mode=WAL")
            with self._write(con):
                for statement in _SCHEMA.split(";"):
                    if statement.strip():
                        con.execute(statement)
                con.execute(
                    "INSERT OR IGNORE INTO meta VALUES "
                    "('format', ?), ('version', ?), ('clock', '0')",
                    (FORMAT, str(SCHEMA_VERSION)),
                )
        self._add_columns(con)
        self._add_raft_tables(con)
        check_schema(con, self.path, _SCHEMA + raft_sql.RAFT_SCHEMA, FORMAT, SCHEMA_VERSION)

    def _add_raft_tables(self, con: sqlite3.Connection) -> None:
        """Give a mapapi store written before Raft its group tables (no write
        transaction when they are there: most opens are reads)."""
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if "raft_state" in tables or "meta" not in tables:
            return
        marker = con.execute("SELECT value FROM meta WHERE key = 'format'").fetchone()
        if marker is None or marker[0] != FORMAT:
            return  # not ours: check_schema refuses it untouched
        with self._write(con):
            for statement in raft_sql.RAFT_SCHEMA.split(";"):
                if statement.strip():
                    con.execute(statement)

    def _add_columns(self, con: sqlite3.Connection) -> None:
        """Bring a store written before `_ADDED_COLUMNS` up to date (idempotent).

        Only a file marked as a mapapi store is touched; `check_schema` then
        refuses anything else unchanged."""
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if "meta" not in tables:
            return
        marker = con.execute("SELECT value FROM meta WHERE key = 'format'").fetchone()
        if marker is None or marker[0] != FORMAT:
            return
        for table, columns in _ADDED_COLUMNS.items():
            have = {row[1] for row in con.execute(f"PRAGMA table_info({table})")}
            missing = [(n, t) for n, t in columns if have and n not in have]
            if missing:
                with self._write(con):
                    for name, definition in missing:
                        con.execute(f"ALTER TABLE {table} ADD COLUMN {name} {definition}")

    def _con(self) -> sqlite3.Connection:
        con: sqlite3.Connection | None = getattr(self._local, "con", None)
        if con is None:
            con = sqlite3.connect(
                self.path, isolation_level=None, check_same_thread=False, timeout=30
            )
            con.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_MS}")
            con.execute("PRAGMA synchronous=NORMAL")
            con.execute("PRAGMA foreign_keys=ON")
            self._local.con = con
            self._local.depth = 0
            with self._all_lock:
                self._all.append(con)
        return con

    @contextmanager
    def _write(self, con: sqlite3.Connection) -> Iterator[None]:
        """One write transaction; nested uses join the outer one."""
        if self._local.depth:
            self._local.depth += 1
            try:
                yield
            finally:
                self._local.depth -= 1
            return
        try:
            con.execute("BEGIN IMMEDIATE")
        except sqlite3.OperationalError as exc:
            locked = LockTimeout(f"repository {self.path} stayed locked: {exc}")
            raise storage_error(self.path, exc) or locked from exc
        self._local.depth = 1
        try:
            yield
            con.execute("COMMIT")
        except BaseException as exc:
            if con.in_transaction:  # on a full disk SQLite may have rolled back already
                con.execute("ROLLBACK")
            if isinstance(exc, sqlite3.Error) and (honest := storage_error(self.path, exc)):
                raise honest from exc
            raise
        finally:
            self._local.depth = 0

    def close(self) -> None:
        """Close every connection opened by any thread."""
        with self._all_lock:
            for con in self._all:
                con.close()
            self._all.clear()
        self._local = threading.local()

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

    def add_table(self, name: str, type_name: str) -> None:
        """Register a table."""
        con = self._con()
        with self._write(con):
            try:
                con.execute("INSERT INTO tables VALUES (?, ?)", (name, type_name))
            except sqlite3.IntegrityError:
                raise UsageError(f"table {name!r} already exists") from None

    def tables(self) -> dict[str, str]:
        """Table name -> type name."""
        return dict(self._con().execute("SELECT name, type_name FROM tables ORDER BY name"))

    def add_chunk(self, chunk_id: ChunkId, table: str) -> None:
        """Register a chunk."""
        con = self._con()
        with self._write(con):
            try:
                con.execute("INSERT OR IGNORE INTO chunks VALUES (?, ?)", (chunk_id, table))
            except sqlite3.IntegrityError:
                raise UsageError(f"no table {table!r}") from None

    def chunks(self, table: str | None = None) -> list[ChunkInfo]:
        """Chunks with their live item counts now."""
        sql = """
            SELECT c.id, c.table_name, COUNT(r.item_id) FROM chunks c
            LEFT JOIN revisions r ON r.chunk_id = c.id AND r.removed = 0
             AND r.update_time = (SELECT MAX(update_time) FROM revisions WHERE item_id = r.item_id)
            WHERE ? IS NULL OR c.table_name = ?
            GROUP BY c.id ORDER BY c.id"""
        rows = self._con().execute(sql, (table, table))
        return [ChunkInfo(ChunkId(cid), t, n) for cid, t, n in rows]

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
                f"SELECT {_REV_COLUMNS} FROM revisions WHERE item_id = ? AND update_time <= ? "
                "ORDER BY update_time DESC LIMIT 1",
                (item_id, time),
            )
            .fetchone()
        )
        return None if row is None else self._revision(row)

    def history(self, item_id: ItemId) -> list[Revision]:
        """All revisions of an item."""
        rows = self._con().execute(
            f"SELECT {_REV_COLUMNS} FROM revisions WHERE item_id = ? ORDER BY update_time",
            (item_id,),
        )
        return [self._revision(r) for r in rows]

    def scan(
        self, time: int, *, table: str | None = None, chunk: ChunkId | None = None
    ) -> list[Revision]:
        """Items visible at `time`."""
        where, args = _scope(table, chunk)
        sql = (
            f"SELECT {_REV_COLUMNS.replace('item_id', 'r.item_id', 1)} FROM revisions r "
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
            batch = list(item_ids[start : start + 500])
            marks = ",".join("?" * len(batch))
            sql = (
                f"SELECT {_REV_COLUMNS.replace('item_id', 'r.item_id', 1)} FROM revisions r "
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
        """Revisions written after `time`."""
        where, args = _scope(table, chunk)
        sql = (
            f"SELECT {_REV_COLUMNS} FROM revisions r WHERE r.update_time > ?{where} "
            "ORDER BY r.update_time, r.item_id"
        )
        return [self._revision(row) for row in self._con().execute(sql, [time, *args])]

    def apply_commit(self, record: CommitRecord, revisions: Sequence[Revision]) -> None:
        """Write the record and its revisions in one SQL transaction."""
        con = self._con()
        with self._write(con):
            # Idempotent and additive: a commit that spans chunks reaches a holder
            # as one batch per chunk, each applied on its own.
            con.execute(
                f"INSERT OR IGNORE INTO commits ({_COMMIT_COLUMNS}) VALUES (?, ?, ?, ?, ?, ?, ?)",
                (
                    record.id,
                    record.time,
                    record.author,
                    record.message,
                    ",".join(record.chunks),
                    record.author_name,
                    record.view,
                ),
            )
            # In primary-key order: random ids inserted as they come touch pages all
            # over the table's B-tree; sorted, a large commit writes in half the time.
            con.executemany(
                "INSERT OR IGNORE INTO revisions (item_id, update_time, table_name, chunk_id, "
                "data, insert_time, removed, author, commit_id) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                sorted(
                    (
                        r.item_id,
                        r.update_time,
                        r.table,
                        r.chunk_id,
                        r.data,
                        r.insert_time,
                        int(r.removed),
                        r.author,
                        r.commit_id,
                    )
                    for r in revisions
                ),
            )
            con.execute(
                "UPDATE meta SET value = MAX(CAST(value AS INTEGER), ?) WHERE key = 'clock'",
                (record.time,),
            )

    def _revision(self, row: sqlite3.Row | tuple) -> Revision:
        item_id, table, chunk, data, inserted, updated, removed, author, commit = row
        try:
            return Revision(
                ItemId(item_id),
                table,
                ChunkId(chunk),
                bytes(data),
                inserted,
                updated,
                bool(removed),
                PeerId(author),
                CommitId(commit),
            )
        except (TypeError, ValueError) as exc:
            raise self._damaged_row("revision", exc) from exc

    def _damaged_row(self, what: str, exc: Exception) -> CorruptRepoError:
        return CorruptRepoError(
            f"a {what} in {self.path} is damaged: {exc}; restore the store from a backup "
            "or clone the repository again"
        )

    def _record(self, row: tuple) -> CommitRecord:
        cid, time, author, message, chunks, author_name, view = row
        try:
            return CommitRecord(
                CommitId(cid),
                time,
                PeerId(author),
                message,
                tuple(ChunkId(c) for c in chunks.split(",") if c),
                author_name,
                view,
            )
        except (AttributeError, TypeError, ValueError) as exc:
            raise self._damaged_row("commit record", exc) from exc

    def commits(self, limit: int | None = None) -> list[CommitRecord]:
        """Newest first."""
        rows = self._con().execute(
            f"SELECT {_COMMIT_COLUMNS} FROM commits ORDER BY time DESC, id DESC LIMIT ?",
            (-1 if limit is None else limit,),
        )
        return [self._record(r) for r in rows]

    def commit_record(self, commit_id: CommitId) -> CommitRecord | None:
        """One record."""
        row = (
            self._con()
            .execute(f"SELECT {_COMMIT_COLUMNS} FROM commits WHERE id = ?", (commit_id,))
            .fetchone()
        )
        return None if row is None else self._record(row)

    def commit_revisions(self, commit_id: CommitId) -> list[Revision]:
        """What one commit wrote."""
        rows = self._con().execute(
            f"SELECT {_REV_COLUMNS} FROM revisions WHERE commit_id = ? ORDER BY item_id",
            (commit_id,),
        )
        return [self._revision(r) for r in rows]

    def resolve_prefix(self, kind: IdKind, prefix: str) -> list[str]:
        """Ids starting with `prefix`."""
        table, column = {
            "item": ("revisions", "item_id"),
            "chunk": ("chunks", "id"),
            "commit": ("commits", "id"),
        }[kind]
        hi = prefix + "g"  # every hex id with this prefix sorts below prefix + 'g'
        rows = self._con().execute(
            f"SELECT DISTINCT {column} FROM {table} WHERE {column} >= ? AND {column} < ? "
            f"ORDER BY {column} LIMIT 2",
            (prefix, hi),
        )
        return [r[0] for r in rows]

    def load_view(self, name: str) -> bytes | None:
        """A view."""
        row = self._con().execute("SELECT body FROM views WHERE name = ?", (name,)).fetchone()
        return None if row is None else bytes(row[0])

    def save_view(self, name: str, blob: bytes) -> None:
        """Store a view."""
        con = self._con()
        with self._write(con):
            con.execute("INSERT OR REPLACE INTO views VALUES (?, ?)", (name, blob))

    def delete_view(self, name: str) -> None:
        """Drop a view."""
        con = self._con()
        with self._write(con):
            con.execute("DELETE FROM views WHERE name = ?", (name,))

    def views(self) -> dict[str, bytes]:
        """All views."""
        return {n: bytes(b) for n, b in self._con().execute("SELECT name, body FROM views")}

    # -- replication -------------------------------------------------------------
    def holders(self, chunk_id: ChunkId) -> list[PeerId]:
        """The peers that hold a chunk, in id order."""
        rows = self._con().execute(
            "SELECT peer_id FROM holders WHERE chunk_id = ? ORDER BY peer_id", (chunk_id,)
        )
        return [PeerId(r[0]) for r in rows]

    def holdings(self) -> dict[ChunkId, list[PeerId]]:
        """Every chunk's holders, in id order (chunks with a recorded holder set)."""
        rows = self._con().execute("SELECT chunk_id, peer_id FROM holders ORDER BY 1, 2")
        found: dict[ChunkId, list[PeerId]] = {}
        for chunk, peer in rows:
            found.setdefault(ChunkId(chunk), []).append(PeerId(peer))
        return found

    def set_holders(self, chunk_id: ChunkId, peers: Sequence[PeerId]) -> None:
        """Replace a chunk's holder set."""
        con = self._con()
        with self._write(con):
            con.execute("DELETE FROM holders WHERE chunk_id = ?", (chunk_id,))
            con.executemany(
                "INSERT OR IGNORE INTO holders VALUES (?, ?)", [(chunk_id, p) for p in peers]
            )

    def chunk_revisions(self, chunk_id: ChunkId) -> list[Revision]:
        """Every revision of every item of a chunk (its full history)."""
        rows = self._con().execute(
            f"SELECT {_REV_COLUMNS} FROM revisions WHERE chunk_id = ? "
            "ORDER BY item_id, update_time",
            (chunk_id,),
        )
        return [self._revision(r) for r in rows]

    def chunk_commits(self, chunk_id: ChunkId) -> list[CommitRecord]:
        """The records of every commit that wrote to a chunk, oldest first."""
        rows = self._con().execute(
            f"SELECT {_COMMIT_COLUMNS} FROM commits WHERE id IN "
            "(SELECT DISTINCT commit_id FROM revisions WHERE chunk_id = ?) ORDER BY time",
            (chunk_id,),
        )
        return [self._record(r) for r in rows]

    def item_chunk(self, item_id: ItemId) -> ChunkId | None:
        """The chunk an item belongs to, if this store has it."""
        row = (
            self._con()
            .execute("SELECT chunk_id FROM revisions WHERE item_id = ? LIMIT 1", (item_id,))
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
    ) -> None:
        """Take in a replica received from a holder, atomically (all or nothing).

        The replica replaces what this store had of the chunk: a revision the
        holder lacks (a commit the swarm never decided, applied here alone
        before a crash) goes, and so does the record of a commit left with no
        revision at all.

        Raises:
            UsageError: this repository has a table of that name with another type.
        """
        con = self._con()
        with self._write(con):
            known = con.execute("SELECT type_name FROM tables WHERE name = ?", (table,)).fetchone()
            if known is not None and known[0] != type_name:
                raise UsageError(
                    f"table {table!r} holds {known[0]} here but {type_name} in the swarm; "
                    "rename one of them"
                )
            con.execute("INSERT OR IGNORE INTO tables VALUES (?, ?)", (table, type_name))
            con.execute("INSERT OR IGNORE INTO chunks VALUES (?, ?)", (chunk_id, table))
            had = [
                CommitId(r[0])
                for r in con.execute(
                    "SELECT DISTINCT commit_id FROM revisions WHERE chunk_id = ?", (chunk_id,)
                )
            ]
            con.execute("DELETE FROM revisions WHERE chunk_id = ?", (chunk_id,))
            by_commit: dict[CommitId, list[Revision]] = {c.id: [] for c in commits}
            for revision in revisions:
                by_commit.setdefault(revision.commit_id, []).append(revision)
            for record in commits:
                self.apply_commit(record, by_commit[record.id])
            con.executemany(
                "DELETE FROM commits WHERE id = ? AND NOT EXISTS "
                "(SELECT 1 FROM revisions WHERE commit_id = ?)",
                [(c, c) for c in had if c not in by_commit],
            )
            self.set_holders(chunk_id, holders)

    def raft_load(self, chunk_id: ChunkId) -> RaftRecord | None:
        """The persisted state of the chunk's Raft group, or None."""
        return raft_sql.load(self._con(), chunk_id)

    def raft_save(
        self,
        chunk_id: ChunkId,
        *,
        hard: tuple[int, int, int] | None = None,
        entries: Sequence[LogRow] = (),
        snapshot: tuple[int, int, bytes, bytes] | None = None,
    ) -> None:
        """Persist one Ready's snapshot, entries and hard state in one transaction."""
        con = self._con()
        with self._write(con):
            raft_sql.save(con, chunk_id, hard=hard, entries=entries, snapshot=snapshot)

    def raft_applied(self, chunk_id: ChunkId, index: int, time: int = 0) -> None:
        """Record the applied index and time (joins the caller's `exclusive()`)."""
        con = self._con()
        with self._write(con):
            raft_sql.set_applied(con, chunk_id, index, time)

    def raft_time(self, chunk_id: ChunkId) -> int:
        """The newest commit time applied from the chunk's log."""
        return raft_sql.chunk_time(self._con(), chunk_id)

    def raft_drop(self, chunk_id: ChunkId) -> None:
        """Forget the chunk's group state."""
        con = self._con()
        with self._write(con):
            raft_sql.drop(con, chunk_id)

    def drop_chunk(self, chunk_id: ChunkId) -> None:
        """Forget a chunk's replica (this peer left it); commit records stay."""
        con = self._con()
        with self._write(con):
            con.execute("DELETE FROM revisions WHERE chunk_id = ?", (chunk_id,))
            con.execute("DELETE FROM chunks WHERE id = ?", (chunk_id,))
