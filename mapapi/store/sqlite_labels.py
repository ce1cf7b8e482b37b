"""The label index in SQLite (see `mapapi.store.labels`): its tables, and how a
commit, an installed replica and a dropped one change them.

`label_sets` has one row per label and chunk: its id, and the summary of its
live rows now (how many, their weight, their box). `labelled` lists every
revision of a labelled row under its set, keyed (set, item, time), so a read
of one label seeks to its sets' rows and joins each to its revision by the
revisions' primary key. A revision that removes an item is not listed: no
read at any time returns it. Functions that write expect the caller's write
transaction.

`meta` holds the signature of the labels the index is complete for (key
`labels`). Every write of revisions or drop of a replica through the plain
store deletes it (`sqlite_rows.write_commit`, `sqlite_replica`), and the
labelled store sets it again after labelling what it wrote, if it held
before; a labelled store that finds it missing or different labels the whole
store again (`relabel`), so a commit applied by a process that keeps no
labels, or by an older version, is never missed.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId
from mapapi.store import sqlite_replica, sqlite_rows
from mapapi.store.file_check import schema_tables
from mapapi.store.labels import Box, LabelFn, Labels, LabelSummary, RowLabel, Tally, union

LABEL_SCHEMA = """
CREATE TABLE IF NOT EXISTS label_sets (
    id INTEGER PRIMARY KEY, label TEXT NOT NULL, chunk_id TEXT NOT NULL,
    items INTEGER NOT NULL DEFAULT 0, weight INTEGER NOT NULL DEFAULT 0,
    xmin REAL, ymin REAL, zmin REAL, xmax REAL, ymax REAL, zmax REAL,
    UNIQUE (label, chunk_id));
CREATE INDEX IF NOT EXISTS label_sets_chunk ON label_sets (chunk_id);
CREATE TABLE IF NOT EXISTS labelled (
    label_set INTEGER NOT NULL, item_id BLOB NOT NULL, update_time INTEGER NOT NULL,
    PRIMARY KEY (label_set, item_id, update_time)) WITHOUT ROWID;
"""

LABEL_TABLES = ("label_sets", "labelled")
"""The tables above; an older store gains them."""

FLAG = "labels"
"""The `meta` key holding the signature of the labels the index is complete for."""

_BOX = "xmin, ymin, zmin, xmax, ymax, zmax"


def ready(con: sqlite3.Connection) -> bool:
    """Whether the index's tables are there as `LABEL_SCHEMA` makes them."""
    wanted = schema_tables(LABEL_SCHEMA)
    return wanted == {n: [r[1] for r in con.execute(f"PRAGMA table_info({n})")] for n in wanted}


def setup(con: sqlite3.Connection) -> None:
    """Make the index's tables anew (inside the caller's write transaction):
    they are derived data, labelled again on first use."""
    for name in LABEL_TABLES:
        con.execute(f"DROP TABLE IF EXISTS {name}")
    for statement in LABEL_SCHEMA.split(";"):
        if statement.strip():
            con.execute(statement)
    con.execute("DELETE FROM meta WHERE key = ?", (FLAG,))


def complete(con: sqlite3.Connection, labels: Labels) -> bool:
    """Whether the index is complete for `labels`."""
    row = con.execute("SELECT value FROM meta WHERE key = ?", (FLAG,)).fetchone()
    return row is not None and row[0] == labels.signature


def mark_complete(con: sqlite3.Connection, labels: Labels) -> None:
    """Record that the index is complete for `labels`."""
    con.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (FLAG, labels.signature))


def unwritten(
    con: sqlite3.Connection, record: CommitRecord, revisions: Sequence[Revision]
) -> list[Revision]:
    """The revisions of `record` the store does not hold yet (a commit may
    reach a holder twice, or one chunk's part at a time)."""
    parts = {(r.chunk_id, r.update_time) for r in revisions}
    held = set(sqlite_rows.of_commit(con, record.id, parts, columns="r.item_id, r.update_time"))
    return [r for r in revisions if (sqlite_rows.item_key(r.item_id), r.update_time) not in held]


def committed(
    con: sqlite3.Connection, revisions: Sequence[Revision], labels: Labels, types: Mapping[str, str]
) -> None:
    """Index a commit's new revisions (written already) and bring the summaries
    of the sets they touch up to date: inserts add to their set; an update or
    a removal makes its set (and the set the item left) count again."""
    rows: list[tuple[tuple[str, ChunkId], Revision]] = []
    grown: dict[tuple[str, ChunkId], list[RowLabel]] = {}
    recount: dict[tuple[str, ChunkId], LabelFn] = {}
    for revision in revisions:
        fn = labels.of(types.get(revision.table, ""))
        if fn is None:
            continue
        chunk = revision.chunk_id
        if revision.kind != "inserted":
            before = _live_before(con, revision)
            old = None if before is None else fn(before)
            if old is not None:
                recount[(old.label, chunk)] = fn
        row = None if revision.removed else fn(revision.data)
        if row is None:
            continue
        rows.append(((row.label, chunk), revision))
        if revision.kind == "inserted":
            grown.setdefault((row.label, chunk), []).append(row)
        else:
            recount[(row.label, chunk)] = fn
    ids = _set_ids(con, {key for key, _ in rows} | set(recount))
    con.executemany(
        "INSERT OR IGNORE INTO labelled VALUES (?, ?, ?)",
        sorted((ids[key], sqlite_rows.item_key(r.item_id), r.update_time) for key, r in rows),
    )
    for key, added in grown.items():
        if key not in recount:
            _grow(con, ids[key], added)
    for key, fn in recount.items():
        _recount(con, ids[key], fn)


def installed(
    con: sqlite3.Connection, chunk: ChunkId, revisions: Sequence[Revision], fn: LabelFn | None
) -> None:
    """Index a replica installed whole (`revisions`: its full history), in place
    of what the index had of the chunk."""
    dropped(con, chunk)
    if fn is None:
        return
    newest: dict[str, Revision] = {}
    for revision in revisions:
        kept = newest.get(revision.item_id)
        if kept is None or revision.update_time > kept.update_time:
            newest[revision.item_id] = revision
    rows: list[tuple[str, Revision]] = []
    tallies: dict[str, Tally] = {}
    for revision in revisions:
        row = None if revision.removed else fn(revision.data)
        if row is None:
            continue
        rows.append((row.label, revision))
        if newest[revision.item_id] is revision:
            tallies.setdefault(row.label, Tally()).add(row)
    ids = _set_ids(con, {(label, chunk) for label, _ in rows})
    con.executemany(
        "INSERT OR IGNORE INTO labelled VALUES (?, ?, ?)",
        sorted(
            (ids[(label, chunk)], sqlite_rows.item_key(r.item_id), r.update_time)
            for label, r in rows
        ),
    )
    for label, tally in tallies.items():
        _set(con, ids[(label, chunk)], tally)


def dropped(con: sqlite3.Connection, chunk: ChunkId) -> None:
    """Forget what the index has of a chunk."""
    con.execute(
        "DELETE FROM labelled WHERE label_set IN (SELECT id FROM label_sets WHERE chunk_id = ?)",
        (chunk,),
    )
    con.execute("DELETE FROM label_sets WHERE chunk_id = ?", (chunk,))


def relabel(con: sqlite3.Connection, path: Path, labels: Labels) -> int:
    """Index the whole store anew, chunk by chunk; returns the revisions read."""
    con.execute("DELETE FROM labelled")
    con.execute("DELETE FROM label_sets")
    read = 0
    chunks = con.execute(
        "SELECT c.id, t.type_name FROM chunks c JOIN tables t ON t.name = c.table_name"
    ).fetchall()
    for chunk, type_name in chunks:
        fn = labels.of(type_name)
        if fn is not None:
            revisions = sqlite_replica.chunk_revisions(path, con, ChunkId(chunk))
            installed(con, ChunkId(chunk), revisions, fn)
            read += len(revisions)
    mark_complete(con, labels)
    return read


def label_sets(
    con: sqlite3.Connection, label: str, table: str | None, chunk: ChunkId | None
) -> list[tuple[int, ChunkId]]:
    """The (set id, chunk) of `label`, of `table` and `chunk` if given."""
    rows = con.execute(
        "SELECT s.id, s.chunk_id FROM label_sets s JOIN chunks c ON c.id = s.chunk_id "
        "WHERE s.label = ? AND (? IS NULL OR c.table_name = ?) AND (? IS NULL OR s.chunk_id = ?) "
        "ORDER BY s.chunk_id",
        (label, table, table, chunk, chunk),
    )
    return [(int(i), ChunkId(c)) for i, c in rows]


def scan_sql(sets: int) -> str:
    """The read of the items of `sets` label sets visible at a time: parameters
    the set ids, then the time."""
    marks = ",".join("?" * sets)
    return (
        f"SELECT {sqlite_rows.REV_COLUMNS} FROM labelled l "
        "JOIN revisions r ON r.item_id = l.item_id AND r.update_time = l.update_time "
        f"{sqlite_rows.REV_JOINS} "
        f"WHERE l.label_set IN ({marks}) AND r.removed = 0 AND r.update_time = "
        "(SELECT MAX(update_time) FROM revisions WHERE item_id = l.item_id AND update_time <= ?) "
        "ORDER BY l.item_id"
    )


def summaries(con: sqlite3.Connection, labels: Sequence[str] | None) -> list[LabelSummary]:
    """The summaries of the sets with live rows (of `labels`, if given)."""
    sql = (
        f"SELECT s.label, s.chunk_id, c.table_name, s.items, s.weight, {_BOX} "
        "FROM label_sets s JOIN chunks c ON c.id = s.chunk_id WHERE s.items > 0"
    )
    args: list[str] = []
    if labels is not None:
        sql += f" AND s.label IN ({','.join('?' * len(labels))})"
        args = list(labels)
    found = [
        LabelSummary(label, ChunkId(chunk), table, items, weight, _box(box))
        for label, chunk, table, items, weight, *box in con.execute(sql, args)
    ]
    return sorted(found, key=lambda s: (s.label, s.table, s.chunk))


def _box(values: Sequence[float | None]) -> Box | None:
    if any(v is None for v in values):
        return None
    x0, y0, z0, x1, y1, z1 = (float(v) for v in values if v is not None)
    return (x0, y0, z0, x1, y1, z1)


def _live_before(con: sqlite3.Connection, revision: Revision) -> bytes | None:
    """The payload of the item's newest revision before `revision`, if live."""
    row = con.execute(
        "SELECT data, removed FROM revisions WHERE item_id = ? AND update_time < ? "
        "ORDER BY update_time DESC LIMIT 1",
        (sqlite_rows.item_key(revision.item_id), revision.update_time),
    ).fetchone()
    return None if row is None or row[1] else bytes(row[0])


def _set_ids(
    con: sqlite3.Connection, keys: Iterable[tuple[str, ChunkId]]
) -> dict[tuple[str, ChunkId], int]:
    """The id of each (label, chunk) set, made where missing."""
    ids: dict[tuple[str, ChunkId], int] = {}
    for label, chunk in sorted(keys):
        con.execute(
            "INSERT OR IGNORE INTO label_sets (label, chunk_id) VALUES (?, ?)", (label, chunk)
        )
        row = con.execute(
            "SELECT id FROM label_sets WHERE label = ? AND chunk_id = ?", (label, chunk)
        ).fetchone()
        ids[(label, chunk)] = int(row[0])
    return ids


def _grow(con: sqlite3.Connection, set_id: int, added: Sequence[RowLabel]) -> None:
    """Add inserted rows to a set's summary."""
    con.execute(
        "UPDATE label_sets SET items = items + ?, weight = weight + ? WHERE id = ?",
        (len(added), sum(r.weight for r in added), set_id),
    )
    box = union(r.box for r in added)
    if box is not None:
        con.execute(
            "UPDATE label_sets SET xmin = MIN(COALESCE(xmin, ?1), ?1), "
            "ymin = MIN(COALESCE(ymin, ?2), ?2), zmin = MIN(COALESCE(zmin, ?3), ?3), "
            "xmax = MAX(COALESCE(xmax, ?4), ?4), ymax = MAX(COALESCE(ymax, ?5), ?5), "
            "zmax = MAX(COALESCE(zmax, ?6), ?6) WHERE id = ?7",
            (*box, set_id),
        )


def _recount(con: sqlite3.Connection, set_id: int, fn: LabelFn) -> None:
    """Count a set's live rows again (after an update or a removal in it)."""
    rows = con.execute(
        "SELECT r.data FROM labelled l "
        "JOIN revisions r ON r.item_id = l.item_id AND r.update_time = l.update_time "
        "WHERE l.label_set = ? AND r.removed = 0 AND NOT EXISTS (SELECT 1 FROM revisions n "
        "WHERE n.item_id = l.item_id AND n.update_time > l.update_time)",
        (set_id,),
    )
    tally = Tally()
    for (data,) in rows:
        row = fn(bytes(data))
        if row is not None:
            tally.add(row)
    _set(con, set_id, tally)


def _set(con: sqlite3.Connection, set_id: int, tally: Tally) -> None:
    box = tally.box or (None,) * 6
    con.execute(
        f"UPDATE label_sets SET items = ?, weight = ?, ({_BOX}) = (?, ?, ?, ?, ?, ?) WHERE id = ?",
        (tally.items, tally.weight, *box, set_id),
    )
