"""`mapctl bench fuzz`: hostile messages against a real peer (DESIGN §11).

Three peer processes (`mapbench.worker`) on loopback make the target's
world: the target T holds chunk A with a holder H, chunk B alone, and chunk C
with a member M; each chunk holds a counter with a few commits of history. The
fuzzer (`mapbench.fuzz_client`) sends T what `mapbench.hostile` makes,
as strangers (unknown peer ids) and as M (a known member and a holder of C
only), now and then a commit to C through T's log (`commit_flow`), and sorts
every answer: each must be the one the message calls for, an `ErrorReply`
saying "internal error" is a handler bug, and so is an ERROR line in a peer's
log (but T's report that M's hash chain of a chunk it holds differs from its own: M
may claim any).

Afterwards T must answer a Ping, H must commit to A through T (a real commit
round trip), T's store must pass `PRAGMA integrity_check` and hold exactly the
tables, chunks, holders, revisions and commits of A and B it held before. C may
have changed, but only if T acknowledged a commit or a holder change for it
(M holds C, so its messages about C are legitimate); the holders of A or B may
change only if T acknowledged M joining or leaving it (in an open swarm a
member may hold any chunk, and T cannot tell M's word from a forgery: a secure
swarm authenticates peers); and the whole store must still be consistent
(`mapbench.store_check`). The fuzzer never speaks as
T or H: a peer cannot tell an impersonation from the real thing in an open
swarm (a secure swarm authenticates peers with CurveZMQ).
"""

from __future__ import annotations

import os
import random
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from mapapi._pb.mapapi.v1.types_pb2 import Counter
from mapapi.core import codec
from mapapi.core.change import Change, Op
from mapapi.core.errors import MapError
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.proposal import Proposal
from mapapi.lookup.dht.chord import key_bytes
from mapapi.lookup.dht.ring import chunk_key, peer_key
from mapapi.lookup.spatial import SpatialGrid
from mapbench import store_check
from mapbench.fuzz_client import Fuzzer, Outcome
from mapbench.hostile import Generator, Pools
from mapbench.workers import WorkerProcess, spawn_workers

FLOW_EVERY = 20
"""One message in this many is a commit through T's log (`commit_flow`)."""


class FuzzFailed(MapError):
    """The fuzzed peer crashed, broke its store, or answered a message wrongly."""


@dataclass
class Target:
    """The three peer processes and what the check needs to know about them."""

    t: WorkerProcess
    h: WorkerProcess
    m: WorkerProcess
    store: Path
    chunks: dict[str, str]  # "A", "B", "C" -> chunk id
    items: dict[str, str]  # "A", "B", "C" -> counter item id
    folder: Path

    def pools(self) -> Pools:
        """The values "valid" messages draw from: T's real ids, keys and addresses."""
        with store_check.read_only(self.store) as con:
            items = [bytes(r[0]) for r in con.execute("SELECT DISTINCT item_id FROM revisions")]
            commits = [bytes.fromhex(r[0]) for r in con.execute("SELECT id FROM commits")]
            clock = max(r[0] or 0 for r in con.execute("SELECT max(time) FROM commits"))
        chunks = [ChunkId(c) for c in self.chunks.values()]
        peers = [PeerId(w.id) for w in (self.t, self.h, self.m)]
        keys = [peer_key(p) for p in peers] + [chunk_key(c) for c in chunks]
        return Pools(
            chunks=[c.to_bytes() for c in chunks],
            items=items,
            commits=commits,
            peers=[p.to_bytes() for p in peers],
            keys=[key_bytes(k) for k in keys],
            addresses=[w.address for w in (self.t, self.h, self.m)],
            tables=["counters"],
            type_names=["mapapi.v1.Counter", "google.protobuf.Struct"],
            index=SpatialGrid().config_fingerprint(),
            lamport=clock + 1,
        )

    def logged_errors(self) -> list[str]:
        """ERROR lines the three peers logged (a handler that failed, a dead reader),
        but for T saying that M's chain of a chunk differs from its own: M holds C
        (and any chunk T took it in for), so a link it claims is a holder's word,
        and reporting it loudly is T's job."""
        claimed = (
            "ERROR mapapi.swarm.chain_watch: chunk ",
            f"differs from peer {PeerId(self.m.id).short}'s",
        )
        found = []
        for log in sorted(self.folder.glob("worker-*.log")):
            lines = log.read_text(errors="replace").splitlines()
            found += [
                f"{log.name}: {line.strip()}"
                for line in lines
                if " ERROR " in line and not all(part in line for part in claimed)
            ]
        return found


@contextmanager
def target_swarm(folder: Path) -> Iterator[Target]:
    """T, H and M running with chunks A (T, H), B (T) and C (T, M) and some history."""
    with spawn_workers(3, folder) as (t, h, m):
        for other in (h, m):
            other.call("joined", "join", t.address)
        starts = {"A": 0, "B": 10, "C": 20}
        made = {name: t.call("created", "create", a0) for name, a0 in starts.items()}
        h.call("participating", "participate", made["A"]["chunk"])
        m.call("participating", "participate", made["C"]["chunk"])
        for name, n in zip("ABC", (3, 2, 2), strict=True):
            t.call("ran", "run", n, made[name]["item"])
        yield Target(
            t,
            h,
            m,
            folder / "peer0" / ".mapapi" / "store.sqlite",
            {k: v["chunk"] for k, v in made.items()},
            {k: v["item"] for k, v in made.items()},
            folder,
        )


def check_round_trip(target: Target) -> list[str]:
    """H commits to A through T; both must then read the same counter value."""
    item = target.items["A"]
    before = target.t.call("value", "value", item)["value"]
    target.h.call("ran", "run", 3, item, 60)
    at_t = target.t.call("value", "value", item)["value"]
    at_h = target.h.call("value", "value", item)["value"]
    if at_t != at_h or at_t != before + 3:
        return [f"after H's 3 increments T reads {at_t} and H {at_h}, expected {before + 3}"]
    return []


def run_fuzz(messages_n: int, seed: int, directory: str | None = None) -> dict[str, Any]:
    """Send `messages_n` hostile messages to a real peer; returns the report.

    Raises:
        FuzzFailed: the peer crashed, its store changed illegitimately, or a
            request was answered wrongly or not at all (after printing nothing:
            the report is in the exception's `report`).
    """
    with (
        tempfile.TemporaryDirectory(prefix="mapapi-fuzz-", dir=directory) as tmp,
        target_swarm(Path(tmp)) as target,
    ):
        return fuzz_target(target, messages_n, seed)


def fuzz_target(target: Target, messages_n: int, seed: int) -> dict[str, Any]:
    """The fuzz run of `run_fuzz` on a started target; returns the report."""
    rnd = random.Random(seed)
    pools = target.pools()
    before = store_check.snapshot(target.store)
    strangers = [os.urandom(16) for _ in range(8)]
    member = PeerId(target.m.id).to_bytes()
    generator = Generator(rnd, pools, strangers + [member] * len(strangers))
    fuzzer = Fuzzer(target.t.address, pools)
    started = time.perf_counter()
    chunk = ChunkId(target.chunks["C"]).to_bytes()
    try:
        while fuzzer.outcome.messages < messages_n:
            if fuzzer.outcome.messages % FLOW_EVERY == 0:
                commit_flow(generator, fuzzer, target, chunk, member)
            else:
                fuzzer.send(generator.shot())
                fuzzer.collect()
        fuzzer.drain()
        seconds = time.perf_counter() - started
        return finish(target, fuzzer, before, seconds, seed)
    finally:
        fuzzer.close()


def commit_flow(
    generator: Generator, fuzzer: Fuzzer, target: Target, chunk: bytes, member: bytes
) -> None:
    """One commit to `chunk` (C) as `member` (a holder), proposed to T (its leader)
    with a real proposal, or one a hostile or broken writer would make: in another
    peer's name, to an item of another chunk, of another table, a payload of
    another type, a removal with a payload. It reaches the checks a leader makes
    before an entry enters the log, which random bytes never pass the decoding to
    reach."""
    rnd, pools = generator.rnd, generator.pools
    item = ItemId(target.items["C"])
    data = Counter(name="c", value=rnd.randrange(100)).SerializeToString()
    change = Change(Op.UPDATE, "counters", item, ChunkId.from_bytes(chunk), data)
    how = rnd.choice(("valid", "valid", "author", "item", "table", "payload", "removal"))
    author = PeerId.from_bytes(member if how != "author" else rnd.choice(pools.peers))
    if how == "item":
        change = replace(change, item_id=ItemId(target.items["A"]))
    elif how == "table":
        change = replace(change, table="fuzz")
    elif how == "payload":
        change = replace(change, data=rnd.randbytes(rnd.randrange(1, 40)))
    elif how == "removal":
        change = replace(change, op=Op.REMOVE)
    proposal = Proposal(
        CommitId.new(), pools.lamport + 1, author, "fuzz", "", how, pools.lamport, "snapshot",
        (change,),
    )  # fmt: skip
    fuzzer.request(generator.propose(chunk, codec.encode_entry(proposal), member))


def finish(
    target: Target,
    fuzzer: Fuzzer,
    before: dict[str, list[tuple[Any, ...]]],
    seconds: float,
    seed: int,
) -> dict[str, Any]:
    """Check the target after a fuzz run (see the module docstring); the report."""
    out = fuzzer.outcome
    problems = list(out.problems)
    crashed = target.t.proc.poll() is not None
    peer_ok = not crashed and fuzzer.ping()
    if not peer_ok:
        problems.append("T does not answer a Ping after the run")
    store_problems = [] if crashed else _store_problems(target, before, out)
    if peer_ok:
        try:
            problems += check_round_trip(target)
        except MapError as exc:
            problems.append(f"the commit round trip through T failed: {exc}")
    if not crashed:
        store_problems += store_check.problems(target.store)  # after the round trip too
    crashed = crashed or target.t.proc.poll() is not None
    logged = target.logged_errors()
    problems += store_problems + logged[:20]
    return {
        "messages": out.messages,
        "error_replies": out.error_replies,
        "valid_replies": out.valid_replies,
        "notifications": out.notifications,
        "dropped": out.dropped,
        "missing_replies": out.missing_replies,
        "wrong_replies": out.wrong_replies,
        "internal_errors": out.internal_errors,
        "logged_errors": len(logged),
        "crashes": int(crashed),
        "peer_ok": peer_ok,
        "store_ok": not crashed and not store_problems,
        "seconds": round(seconds, 2),
        "messages_per_s": round(out.messages / seconds, 1) if seconds else 0.0,
        "seed": seed,
        "by_mode": dict(sorted(out.by_mode.items())),
        "by_body": {k: dict(sorted(v.items())) for k, v in sorted(out.by_body.items())},
        "problems": problems,
    }


def _store_problems(
    target: Target, before: dict[str, list[tuple[Any, ...]]], out: Outcome
) -> list[str]:
    """Differences between T's store now and `before` that no acknowledged
    message explains (only chunk C may change, and only if T acknowledged it;
    the holders of a chunk, if T acknowledged a join or leave of it)."""
    after = store_check.snapshot(target.store)
    may_change = {target.chunks["C"]} & {str(c) for c in out.changed}
    regrouped = {str(c) for c in out.regrouped}
    return store_check.unexplained(before, after, may_change, regrouped)


def check_fuzz(report: dict[str, Any]) -> None:
    """Raise unless the report shows a peer that survived with its store intact
    and answered every message as it should.

    Raises:
        FuzzFailed: naming the first problems.
    """
    problems = report["problems"]
    if report["crashes"] or not report["store_ok"] or not report["peer_ok"] or problems:
        shown = "; ".join(problems[:3]) or "see the report"
        raise FuzzFailed(
            f"the fuzzed peer {'crashed' if report['crashes'] else 'misbehaved'} "
            f"({len(problems)} problem(s)): {shown}; replay with --seed {report['seed']}"
        )
