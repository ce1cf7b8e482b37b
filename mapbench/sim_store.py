"""The commit path in the simulator (`mapbench.sim`): a real `MemoryStore` replica per node.

Each simulated node holds one chunk of table "bank" (a counter and `ACCOUNTS` accounts, the
same genesis commit on every node). Its Raft state persists in the store through `raft_save`,
as `RaftGroups._persist` does, and reads back as `RaftGroups.resume` does (`StoreDisk`);
its messages travel as real ones do, through `raft_wire` and the envelope codec (`wire`). Committed
entries are proposals, decided by `apply_proposal` on the node's store in one `exclusive()`
transaction per Ready with `raft_applied(index, time)`, as `RaftGroups._apply_committed` does
(`ChunkReplica`). The store survives a crash (it is on disk): a restarted node resumes from the
store's applied index, and applying anything twice is a `Violation`.

A snapshot (log compaction, catch-up) carries the chunk's revisions and commit records in the
storage codec, installed with `install_chunk` like a chunk transfer, and its hash chain (the
receiver's must be a prefix of it).
"""

from __future__ import annotations

import json
from collections.abc import Hashable, Iterator
from contextlib import contextmanager

from mapapi._pb.mapapi.v1 import core_pb2
from mapapi.core import codec
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.proposal import Proposal
from mapapi.net import codec as net_codec
from mapapi.net.codec import Kind
from mapapi.net.messages import RaftBatch
from mapapi.store.memory import MemoryStore
from mapapi.swarm.apply import Outcome, apply_proposal
from mapapi.swarm.raft_types import NONE, Config, Entry, Message, PersistentState, Ready, Snapshot
from mapapi.swarm.raft_wire import from_wire, rows, state_of, to_wire
from mapbench.sim_world import A0, ACCOUNTS, BALANCE, Violation, step

TABLE, TYPE_NAME = "bank", "google.protobuf.Struct"
CHUNK = ChunkId(f"{0xC << 124 | 1:032x}")
COUNTER = ItemId(f"{0xA << 124:032x}")
ACCOUNT_IDS = tuple(ItemId(f"{0xA << 124 | i + 1:032x}") for i in range(ACCOUNTS))
AUDIT = ItemId(f"{0xB << 124:032x}")
"""Where audits write the bank total they read (a serializable scan of the chunk)."""
ITEMS = (COUNTER, AUDIT, *ACCOUNT_IDS)
TOTAL = ACCOUNTS * BALANCE
GENESIS = CommitId(f"{0xE << 124:032x}")
GENESIS_TIME = 1


def peer(nid: int) -> PeerId:
    """The peer id of simulated node `nid`."""
    return PeerId(f"{nid:032x}")


def commit_id(n: int) -> CommitId:
    """The id of the `n`th proposal of a run (ids come from the run, never from the OS)."""
    return CommitId(f"{n:032x}")


def value(revision: Revision | None) -> int:
    """An item's payload as the integer it holds."""
    if revision is None or revision.removed:
        raise Violation(f"a bank item is missing: {revision}")
    return int(revision.data)


def new_store(config: Config | None) -> MemoryStore:
    """A node's store at the start: the chunk with its genesis commit, and the group's state
    as `RaftGroups.found` (a founding voter, `config` given) or `join` (None) leave it."""
    store = MemoryStore()
    store.add_table(TABLE, TYPE_NAME)
    store.add_chunk(CHUNK, TABLE)
    record = CommitRecord(GENESIS, GENESIS_TIME, peer(0), "genesis", (CHUNK,))
    data = [str(A0).encode(), str(TOTAL).encode()] + [str(BALANCE).encode()] * ACCOUNTS
    revisions = [
        Revision(i, TABLE, CHUNK, d, GENESIS_TIME, GENESIS_TIME, False, peer(0), GENESIS)
        for i, d in zip(ITEMS, data, strict=True)
    ]
    store.apply_commit(record, revisions)
    if config is None:
        store.raft_save(CHUNK, hard=(0, NONE, 0))
        store.raft_applied(CHUNK, 0, GENESIS_TIME)
    else:
        store.raft_save(
            CHUNK, hard=(1, NONE, 1), entries=rows(PersistentState.bootstrap(config).entries)
        )
        store.raft_applied(CHUNK, 1, GENESIS_TIME)
    return store


class StoreDisk:
    """A node's Raft state kept in its store, written and read as `RaftGroups` does."""

    def __init__(self, store: MemoryStore) -> None:
        self.store = store

    def save(self, rd: Ready) -> None:
        """Persist a Ready (as `RaftGroups._persist`: snapshot, entries, hard state)."""
        if rd.snapshot is None and not rd.entries and rd.hard_state is None:
            return
        hs = rd.hard_state
        self.store.raft_save(
            CHUNK,
            hard=None if hs is None else (hs.term, hs.vote, hs.commit),
            entries=rows(rd.entries),
            snapshot=None if rd.snapshot is None else _snapshot_row(rd.snapshot),
        )

    def save_snapshot(self, snap: Snapshot) -> None:
        """Persist a compaction: the snapshot, and the entries after it again (a snapshot
        handed over by a `Ready` replaces the whole log; one of compaction keeps the rest)."""
        kept = self.store.raft_load(CHUNK)
        after = [] if kept is None else [e for e in kept.entries if e.index > snap.index]
        self.store.raft_save(CHUNK, snapshot=_snapshot_row(snap), entries=after)

    def state(self) -> PersistentState:
        """What a restarted node reads back (`RaftGroups.resume`)."""
        kept = self.store.raft_load(CHUNK)
        if kept is None:
            raise Violation("a node's store lost its chunk's Raft state")
        return state_of(kept)


def _snapshot_row(snap: Snapshot) -> tuple[int, int, bytes, bytes]:
    return snap.index, snap.term, snap.config.encode(), snap.data


def wire(m: Message, envelope: bool = True) -> Message:
    """A message after the trip a real one makes: `to_wire`, the envelope codec (with its
    limits) if `envelope`, `from_wire`."""
    batch = RaftBatch((to_wire(CHUNK, m),))
    if envelope:
        sent = net_codec.encode(net_codec.Envelope(0, peer(m.sender), 0, Kind.NOTIFY, batch))
        received = net_codec.decode(sent).body
        if not isinstance(received, RaftBatch) or len(received.messages) != 1:
            raise Violation(f"a RaftBatch came out of the codec as {received!r}")
        batch = received
    return from_wire(batch.messages[0])


class CommitHistory:
    """The one history of commit ids in the chunk: every replica's is a prefix of it, and
    the counter moves by exactly the increment of each commit (no lost update)."""

    def __init__(self) -> None:
        self.ids: list[CommitId] = []
        self.index: dict[CommitId, int] = {}  # commit -> the log index that committed it
        self.increments: dict[CommitId, int] = {}  # filled by the clients
        self.counter = A0  # after the last commit of the history

    def saw(self, nid: int, commits: list[CommitId], index: int, counter: int) -> None:
        """Node `nid` committed `commits[-1]` at log `index`, leaving `counter`."""
        position, cid = len(commits) - 1, commits[-1]
        if position < len(self.ids):
            if self.ids[position] != cid:
                other = self.ids[position].short
                raise Violation(f"node {nid}: commit #{position} is {cid.short}, others {other}")
        elif position == len(self.ids):
            expected = self.counter + self.increments.get(cid, 0)
            if counter != expected:
                raise Violation(
                    f"node {nid}: counter {counter} after {cid.short}, not {expected}: "
                    "a lost update"
                )
            self.ids.append(cid)
            self.index[cid] = index
            self.counter = counter
        else:
            raise Violation(f"node {nid}: commit #{position} past the history ({len(self.ids)})")
        if self.index[cid] != index:
            raise Violation(f"node {nid}: {cid.short} at index {index}, others {self.index[cid]}")

    def check(self, nid: int, commits: list[CommitId]) -> None:
        """A replica's whole list of commits is a prefix of the history."""
        if commits != self.ids[: len(commits)]:
            raise Violation(f"node {nid}: its commits are not a prefix of the one history")


class ChunkReplica:
    """A node's replica of the chunk: a `MemoryStore` written only through `apply_proposal`."""

    def __init__(self, nid: int, store: MemoryStore, history: CommitHistory) -> None:
        self.nid, self.store, self.history = nid, store, history
        kept = store.raft_load(CHUNK)
        if kept is None:
            raise Violation(f"node {nid}: no Raft state in its store")
        self.applied, self.time = kept.applied, kept.time
        self._batch_time = 0
        self.installed = 0  # snapshots installed since this (re)start
        self.commits = self._stored_commits()
        history.check(nid, self.commits)

    def _stored_commits(self) -> list[CommitId]:
        return [c.id for c in self.store.chunk_commits(CHUNK) if c.id != GENESIS]

    @contextmanager
    def batch(self) -> Iterator[None]:
        """The transaction of `RaftGroups._apply_committed`: the entries' effects and the
        applied index and clock, together."""
        with self.store.exclusive():
            first, self._batch_time = self.applied, 0
            yield
            if self.applied > first:
                self.store.raft_applied(CHUNK, self.applied, self._batch_time)

    def apply(self, entry: Entry) -> object:
        """Decide the entry's proposal on this store; the `Outcome` (None for other kinds)."""
        if not step(self, entry):
            return None
        proposal = codec.decode_entry(entry.data)
        if not isinstance(proposal, Proposal):
            raise Violation(f"entry {entry.index} carries {proposal!r}, not a proposal")
        if self.store.commit_record(proposal.commit_id) is not None:
            raise Violation(f"{proposal.commit_id.short} applied twice (index {entry.index})")
        outcome: Outcome = apply_proposal(self.store, CHUNK, proposal)
        if outcome.record is not None:
            if outcome.record.time <= self.time:
                raise Violation(f"commit time {outcome.record.time} not past {self.time}")
            self.time = self._batch_time = outcome.record.time
            self.commits.append(outcome.record.id)
            counter = value(self.store.latest([COUNTER]).get(COUNTER))
            self.history.saw(self.nid, self.commits, entry.index, counter)
        return outcome

    def install(self, snap: Snapshot) -> None:
        """Take a leader's snapshot: the chunk's state at `snap.index`, as a chunk transfer."""
        time, revisions, records, links = decode_snapshot(snap.data)
        with self.store.exclusive():
            self.store.install_chunk(CHUNK, TABLE, TYPE_NAME, revisions, records, [])
            own = self.store.chain_links(CHUNK)
            if own != links[: len(own)]:
                raise Violation(f"node {self.nid}: its hash chain is not the snapshot's")
            for commit, link in links[len(own) :]:
                self.store.chain_link(CHUNK, commit, link)
            self.store.raft_applied(CHUNK, snap.index, time)
        self.applied, self.time = snap.index, time
        self.installed += 1
        self.commits = self._stored_commits()
        self.history.check(self.nid, self.commits)

    def snapshot_data(self) -> bytes:
        """The chunk's state at `applied` (the store holds exactly that)."""
        return encode_snapshot(
            self.time,
            self.store.chunk_revisions(CHUNK),
            self.store.chunk_commits(CHUNK),
            self.store.chain_links(CHUNK),
        )

    def values(self) -> tuple[int, list[int]]:
        """The counter and the accounts, latest."""
        latest = self.store.latest(ITEMS)
        return value(latest.get(COUNTER)), [value(latest.get(i)) for i in ACCOUNT_IDS]

    def digest(self) -> Hashable:
        """Every item's latest value and time, the chunk's clock and its chain's head."""
        latest = self.store.latest(ITEMS)
        items = tuple((r.data, r.update_time, r.commit_id) for r in latest.values())
        return self.time, len(self.commits), items, self.store.chain_head(CHUNK)

    def check(self) -> None:
        """The bank total is conserved, no account is overdrawn, audits saw the total."""
        _, accounts = self.values()
        if sum(accounts) != TOTAL or min(accounts) < 0:
            raise Violation(f"bank accounts {accounts} at {self.applied}")
        audit = value(self.store.latest([AUDIT]).get(AUDIT))
        if audit != TOTAL:
            raise Violation(f"an audit committed a bank total of {audit}")


Links = list[tuple[CommitId, bytes]]


def encode_snapshot(
    time: int, revisions: list[Revision], records: list[CommitRecord], links: Links
) -> bytes:
    """A snapshot payload: the chunk's clock, revisions and commit records (storage codec),
    and its hash chain."""
    return json.dumps(
        {
            "time": time,
            "revisions": [codec.revision_to_pb(r).SerializeToString().hex() for r in revisions],
            "commits": [codec.commit_record_to_pb(c).SerializeToString().hex() for c in records],
            "chain": [[c, link.hex()] for c, link in links],
        }
    ).encode()


def decode_snapshot(data: bytes) -> tuple[int, list[Revision], list[CommitRecord], Links]:
    """The inverse of `encode_snapshot`."""
    raw = json.loads(data)
    revisions = [
        codec.revision_from_pb(core_pb2.Revision.FromString(bytes.fromhex(h)))
        for h in raw["revisions"]
    ]
    records = [
        codec.commit_record_from_pb(core_pb2.CommitRecord.FromString(bytes.fromhex(h)))
        for h in raw["commits"]
    ]
    links = [(CommitId(c), bytes.fromhex(h)) for c, h in raw["chain"]]
    return raw["time"], revisions, records, links
