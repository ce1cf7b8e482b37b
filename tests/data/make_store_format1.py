"""Make `store-format1.sqlite` and `store-format1.json`: a store written by mapapi
in store format 1 (run with the code of commit b45a518, the last to write it),
and what its reads returned then, for `tests/unit/test_store_format.py`.

    git worktree add --detach /tmp/old b45a518
    PYTHONPATH=/tmp/old python tests/data/make_store_format1.py tests/data
"""

from __future__ import annotations

import json
import sys
from dataclasses import asdict
from pathlib import Path

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.store import SqliteStore


def main(folder: Path) -> None:
    """Write the store and its reads into `folder`."""
    path = folder / "store-format1.sqlite"
    path.unlink(missing_ok=True)
    path.with_suffix(".mark").unlink(missing_ok=True)
    store = SqliteStore(path, create=True)
    store.add_table("t", "google.protobuf.Struct")
    store.add_table("u", "mapapi.v1.Counter", replication=2)
    a, b, u = ChunkId.new(), ChunkId.new(), ChunkId.new()
    for chunk, table in ((a, "t"), (b, "t"), (u, "u")):
        store.add_chunk(chunk, table)
    authors = [PeerId.new(), PeerId.new()]
    items = [ItemId.new() for _ in range(6)]
    newest: dict[ItemId, Revision] = {}

    def commit(time: int, writes: list[tuple[ItemId, ChunkId, bytes | None]]) -> None:
        author = authors[time % 2]
        chunks = tuple(sorted({c for _, c, _ in writes}))
        record = CommitRecord(CommitId.new(), time, author, f"commit {time}", chunks, "ann", "")
        revisions = []
        for item, chunk, data in writes:
            before = newest.get(item)
            revision = Revision(
                item,
                "u" if chunk == u else "t",
                chunk,
                data or b"",
                before.insert_time if before else time,
                time,
                data is None,
                author,
                record.id,
            )
            newest[item] = revision
            revisions.append(revision)
        store.apply_commit(record, revisions)

    commit(1, [(items[0], a, b"a0"), (items[1], a, b"a1"), (items[2], b, b"b2")])
    commit(2, [(items[3], u, b"u3"), (items[4], b, b"b4")])  # two tables, three chunks
    commit(3, [(items[0], a, b"a0 again"), (items[2], b, None)])  # an update, a removal
    commit(5, [(items[5], u, b"u5"), (items[3], u, b"u3 again")])
    store.set_holders(a, [authors[0]])
    store.set_holders(u, authors)
    reads = {
        "clock": store.clock(),
        "commits": [_plain(asdict(c)) for c in store.commits()],
        "history": {i: [_plain(asdict(r)) for r in store.history(i)] for i in items},
        "scan_at_2": [_plain(asdict(r)) for r in store.scan(2)],
        "holdings": store.holdings(),
        "chunks": [_plain(asdict(c)) for c in store.chunks()],
        "replication": {c: store.replication(c) for c in (a, b, u)},
    }
    store.checkpoint()
    store.close()
    (folder / "store-format1.json").write_text(json.dumps(reads, indent=1) + "\n")


def _plain(value: object) -> object:
    """JSON's form of a dataclass dict (bytes as hex, tuples as lists)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value.hex() if isinstance(value, bytes) else value


if __name__ == "__main__":
    main(Path(sys.argv[1]))
