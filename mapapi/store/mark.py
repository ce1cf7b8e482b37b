"""The store's high-water mark (issue 18 §3): a record, outside the store, of how
many commits it held.

SQLite in WAL mode keeps the newest commits in the `-wal` file until a
checkpoint copies them into the database. A damaged or lost `-wal`, or an older
copy of the files put back, takes the store back to an earlier state with no
error at all (the probe of issue 18: 30 of 40 commits gone, nothing said).

So the store counts the commit records it ever wrote (`meta` key "applied"; one
that a fetched replica drops later still counts), and after every write
transaction that added one, rewrites `store.mark` beside `store.sqlite` with
that count and the newest commit (its time and id): one line of fixed width
written over the old one in place, with its own checksum, so a torn write is
seen as no mark rather than a wrong one. (Writing a new file and renaming it
over the old one costs 1.6 ms per commit on ext4, which flushes a file renamed
over another; the write in place costs 4 µs.) A store behind its mark was
rolled back: `mapctl fsck` says by how many commits, and so does the peer when
it starts. The first write after a rollback records it in the store
(`meta` key "rollbacks") before the mark moves on, so it stays known until
`mapctl fsck --accept`.

The mark is never synced to disk on its own (a commit is not either, see
docs/guarantees.md "Durability"): after a power loss it may be older than the
store (a rollback then goes unseen) or newer (the store lost its last commits,
and says so). Several processes on one repository each write it after their own
commits; one may put back a slightly older mark, never a newer one than the
store holds.
"""

from __future__ import annotations

import json
import logging
import os
import re
import sqlite3
import threading
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mapapi.store.base import Rollback

log = logging.getLogger(__name__)

APPLIED, ROLLBACKS = "applied", "rollbacks"
"""The `meta` keys of the commit count and of the rollbacks found."""


@dataclass(frozen=True, slots=True)
class Mark:
    """What the mark file says: commit records written, the newest commit's time and id."""

    applied: int
    time: int
    commit: str


_WIDTH = 160
_LINE = re.compile(r"mapapi-mark applied=(\d+) time=(\d+) commit=([0-9a-f]*) crc=([0-9a-f]{8})")


def encode(mark: Mark) -> bytes:
    """The mark as one line of `_WIDTH` bytes, its checksum last."""
    body = f"mapapi-mark applied={mark.applied} time={mark.time} commit={mark.commit}"
    return f"{body} crc={zlib.crc32(body.encode()):08x}".ljust(_WIDTH - 1).encode() + b"\n"


def decode(raw: bytes) -> Mark | None:
    """The mark in `raw`, or None if it is no whole mark (a torn or foreign write)."""
    found = _LINE.match(raw.decode("ascii", errors="replace"))
    if found is None:
        return None
    applied, at, commit, crc = found.groups()
    body = f"mapapi-mark applied={applied} time={at} commit={commit}"
    if zlib.crc32(body.encode()) != int(crc, 16):
        return None
    return Mark(int(applied), int(at), commit)


def read(path: Path) -> Mark | None:
    """The mark at `path`, or None if there is none (or it is unreadable: logged)."""
    for _ in range(3):  # a write in place may be under way: read again
        try:
            mark = decode(path.read_bytes())
        except FileNotFoundError:
            return None
        except OSError as exc:
            log.warning("the store's high-water mark %s cannot be read (%s); ignored", path, exc)
            return None
        if mark is not None:
            return mark
    log.warning("the store's high-water mark %s is damaged; ignored until the next commit", path)
    return None


def write(path: Path, mark: Mark) -> None:
    """Write the mark at `path` over the old one; a failure is logged, never raised
    (the commit it follows is in the store already)."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT, 0o644)
        try:
            os.pwrite(fd, encode(mark), 0)
        finally:
            os.close(fd)
    except OSError as exc:
        log.warning("could not write the store's high-water mark %s: %s", path, exc)


def applied(con: sqlite3.Connection) -> int:
    """How many commit records the store has written."""
    row = con.execute("SELECT value FROM meta WHERE key = ?", (APPLIED,)).fetchone()
    return 0 if row is None else int(row[0])


class HighWater:
    """The mark of the store at `store_path` (see the module docstring)."""

    def __init__(self, store_path: Path) -> None:
        self.store_path = store_path
        self.path = store_path.with_suffix(".mark")
        self._checked = False
        self._local = threading.local()  # the newest commit written in this thread's transaction

    def before_write(self, con: sqlite3.Connection) -> None:
        """Inside a write transaction, before it adds a commit: the first time, record
        a rollback found (the mark is about to move on past the evidence)."""
        if self._checked:
            return
        self._checked = True
        found = self.behind(con)
        if found is not None:
            log.error(
                "the store %s is behind what it had recorded: %d commit(s) missing (rolled "
                "back); recorded in the store, see `mapctl fsck`",
                self.store_path,
                found.missing,
            )
            notes = [*self._notes(con), {**_as_json(found), "noticed": time.time()}]
            con.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (ROLLBACKS, json.dumps(notes)))

    def wrote(self, commit: str, time: int) -> None:
        """This thread's transaction added `commit` (at `time`): mark it once it is
        committed."""
        self._local.commit = (commit, time)

    def committed(self, con: sqlite3.Connection) -> None:
        """After a write transaction: rewrite the mark if the transaction added a commit."""
        newest = getattr(self._local, "commit", None)
        if newest is None:
            return
        self._local.commit = None
        write(self.path, Mark(applied(con), newest[1], newest[0]))

    def rolled_back(self) -> None:
        """The transaction was undone: nothing to mark."""
        self._local.commit = None

    def behind(self, con: sqlite3.Connection) -> Rollback | None:
        """How far the store is behind its mark now, or None."""
        mark = read(self.path)  # before the count: a mark is written after its commit
        stored = applied(con)
        if mark is None or mark.applied <= stored:
            return None
        return Rollback(mark.applied, stored, mark.commit)

    def rollbacks(self, con: sqlite3.Connection) -> list[Rollback]:
        """The rollbacks recorded in the store, then the one found now (if any)."""
        found = [
            Rollback(int(n["recorded"]), int(n["stored"]), str(n["commit"]), float(n["noticed"]))
            for n in self._notes(con)
        ]
        now = self.behind(con)
        return [*found, *([now] if now is not None else [])]

    def accept(self, con: sqlite3.Connection) -> None:
        """Inside a write transaction: forget the rollbacks and mark the store as it is."""
        con.execute("DELETE FROM meta WHERE key = ?", (ROLLBACKS,))
        row = con.execute(
            "SELECT id, time FROM commits ORDER BY time DESC, id DESC LIMIT 1"
        ).fetchone()
        self.wrote(*(("", 0) if row is None else (str(row[0]), int(row[1]))))

    @staticmethod
    def _notes(con: sqlite3.Connection) -> list[dict[str, Any]]:
        row = con.execute("SELECT value FROM meta WHERE key = ?", (ROLLBACKS,)).fetchone()
        return [] if row is None else list(json.loads(row[0]))


def _as_json(found: Rollback) -> dict[str, object]:
    return {"recorded": found.recorded, "stored": found.stored, "commit": found.commit}
