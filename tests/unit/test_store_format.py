"""A store of format 1 is brought to format 2 when it is opened, and reads the same.

Format 2 keys revisions by item bytes and the store's numbers of their chunk and
commit (a third of the bytes per row). `tests/data/store-format1.sqlite` was
written by the last mapapi to write format 1 (`tests/data/make_store_format1.py`
says how), with what its reads returned then in `store-format1.json`.
"""

from __future__ import annotations

import json
import shutil
import sqlite3
from dataclasses import asdict, replace
from pathlib import Path

import pytest

from mapapi.core import chain
from mapapi.core.errors import CorruptRepoError, UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.store import SqliteStore
from tests.data.make_store_format1 import _plain

DATA = Path(__file__).parent.parent / "data"


def _format1(tmp_path: Path) -> Path:
    """A copy of the format-1 store (with its mark) in `tmp_path`."""
    path = tmp_path / "store.sqlite"
    shutil.copy(DATA / "store-format1.sqlite", path)
    shutil.copy(DATA / "store-format1.mark", path.with_suffix(".mark"))
    return path


def _dump(path: Path) -> list[str]:
    con = sqlite3.connect(path)
    try:
        return list(con.iterdump())
    finally:
        con.close()


def test_a_format_1_store_reads_as_it_did_and_takes_new_commits(tmp_path: Path) -> None:
    want = json.loads((DATA / "store-format1.json").read_text())
    store = SqliteStore(_format1(tmp_path))
    try:
        assert store.get_meta("version") == "2"
        # the old tables' pages were given back, not left free in the file
        assert store._con().execute("PRAGMA freelist_count").fetchone() == (0,)
        assert store.clock() == want["clock"]
        assert [_plain(asdict(c)) for c in store.commits()] == want["commits"]
        for item, history in want["history"].items():
            assert [_plain(asdict(r)) for r in store.history(ItemId(item))] == history
        assert [_plain(asdict(r)) for r in store.scan(2)] == want["scan_at_2"]
        assert store.holdings() == want["holdings"]
        assert [_plain(asdict(c)) for c in store.chunks()] == want["chunks"]
        assert {c: store.replication(ChunkId(c)) for c in want["replication"]} == want[
            "replication"
        ]
        for chunk in store.chunk_ids():  # every chain links the history it holds
            records = {c.id: c for c in store.chunk_commits(chunk)}
            rebuilt = chain.rebuild(chunk, records, store.chunk_revisions(chunk), [])
            assert store.chain_links(chunk) == rebuilt
        assert store.integrity() == []

        newest = store.commits(1)[0]
        (chunk,) = newest.chunks
        before = store.scan(store.clock(), chunk=chunk)
        record = CommitRecord(CommitId.new(), 9, newest.author, "after", (chunk,))
        old = before[0]
        update = Revision(
            old.item_id,
            old.table,
            chunk,
            b"new",
            old.insert_time,
            9,
            False,
            record.author,
            record.id,
        )
        store.apply_commit(record, [update])
        assert store.read(old.item_id, 9) == update
        assert store.commit_revisions(record.id) == [update]
        assert store.resolve_prefix("item", old.item_id[:7]) == [old.item_id]
    finally:
        store.close()


def test_a_format_1_store_whose_revision_has_no_commit_is_refused_unchanged(
    tmp_path: Path,
) -> None:
    path = _format1(tmp_path)
    con = sqlite3.connect(path)
    with con:
        con.execute("DELETE FROM commits WHERE time = 5")
    con.close()
    before = _dump(path)

    with pytest.raises(CorruptRepoError, match=r"2 revision\(s\) name a commit it has no record"):
        SqliteStore(path)

    assert _dump(path) == before  # still format 1, every row there


@pytest.mark.parametrize("field", ["author", "commit_id"])
def test_a_revision_that_is_not_its_commits_is_refused_and_nothing_is_written(
    tmp_path: Path, field: str
) -> None:
    store = SqliteStore(tmp_path / "store.sqlite", create=True)
    try:
        store.add_table("t", "google.protobuf.Struct")
        chunk = ChunkId.new()
        store.add_chunk(chunk, "t")
        record = CommitRecord(CommitId.new(), 1, PeerId.new(), "", (chunk,))
        good = Revision(ItemId.new(), "t", chunk, b"a", 1, 1, False, record.author, record.id)
        other = {"author": PeerId.new(), "commit_id": CommitId.new()}[field]
        bad = replace(good, item_id=ItemId.new(), **{field: other})

        with pytest.raises(UsageError, match=f"sent as part of commit {record.id.short}"):
            store.apply_commit(record, [good, bad])

        assert store.commits() == []  # a row keeps its commit's author and id: none written
        assert store.history(good.item_id) == []
        assert store.clock() == 0
    finally:
        store.close()
