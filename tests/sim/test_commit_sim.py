"""The commit path in the simulator (`mapbench.sim_store`, `mapbench.sim_clients`): the
checkers are not vacuous, and the seeds exercise what they claim."""

from __future__ import annotations

import pytest

from mapapi.core import codec
from mapapi.core.proposal import Proposal
from mapapi.store.base import ReplicaStore
from mapapi.swarm import apply
from mapapi.swarm.apply import Outcome
from mapapi.swarm.raft_types import Config, Entry, EntryKind, Ready, Snapshot
from mapbench import sim_clients, sim_store
from mapbench.sim import SHAPES, Sim, Violation, run_seeds
from mapbench.sim_clients import CommitWorkload
from mapbench.sim_store import CHUNK, ChunkReplica
from mapbench.sim_world import A0
from tests.sim.test_raft_sim import CALM, run_seed


def replica(sim: Sim, nid: int) -> ChunkReplica:
    """Node `nid`'s store replica."""
    found = sim.nodes[nid].replica
    assert isinstance(found, ChunkReplica)
    return found


def test_calm_world_acknowledges_or_conflicts_every_proposal() -> None:
    """Without faults every proposal commits or conflicts (and is retried); the counter is
    a0 plus the acknowledged increments exactly; every store holds the same commits."""
    sim = run_seed(1, faults=CALM, commits=True, nodes=5, voters=3)
    workload = sim.workload
    assert isinstance(workload, CommitWorkload)
    assert sim.acked
    assert not sim.failed
    assert not sim.unknown
    assert sim.acked | workload.conflicted == sim.proposed
    incs = sum(workload.attempts[c][0].by for c in sim.acked)
    counters = {replica(sim, n).values()[0] for n in sim.nodes if n <= 3}
    assert counters == {A0 + incs}
    commits = {tuple(replica(sim, n).commits) for n in sim.nodes if n <= 3}
    assert commits == {tuple(workload.history.ids)}


def test_same_seed_same_commits() -> None:
    """A seed determines the whole commit run, ids included."""
    first, second = run_seed(5, commits=True), run_seed(5, commits=True)
    assert first.checker.history == second.checker.history
    assert first.counts() == second.counts()


def test_the_commit_seeds_exercise_conflicts_stale_reads_and_snapshots() -> None:
    """Stale begins conflict and are retried; compaction sends stores snapshots."""
    sims = [run_seed(s, compact_after=4, commits=True, nodes=5, voters=3) for s in range(8)]
    counts = [s.counts() for s in sims]
    assert all(c["conflicts"] for c in counts)
    assert all(c["stale_reads"] for c in counts)
    assert any(s.unknown for s in sims)
    assert any(replica(s, n).installed for s in sims for n in s.nodes)


def test_the_commit_seeds_draw_their_group_shape() -> None:
    """Commit-path seeds run groups of three, five, three of five and one voter."""
    shapes = {Sim(seed, commits=True).shape for seed in range(40)}
    assert shapes == set(SHAPES)


def test_a_lost_update_is_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    """The counter and bank checkers are not vacuous: holders that skip validation
    (every begin time moved past the chunk's clock) lose updates, and the run fails."""

    def blind(store: ReplicaStore, chunk: object, p: Proposal, rules: object = ()) -> Outcome:
        since = {i: 10**9 for i in p.since}
        blinded = Proposal(**{**_fields(p), "begin_time": 10**9, "since": since})
        return apply.apply_proposal(store, CHUNK, blinded)

    monkeypatch.setattr(sim_store, "apply_proposal", blind)
    with pytest.raises(Violation, match=r"lost update|bank accounts"):
        Sim(1, commits=True, faults=CALM).run()


def _fields(p: Proposal) -> dict[str, object]:
    return {name: getattr(p, name) for name in Proposal.__slots__}


def test_an_entry_applied_twice_is_caught() -> None:
    """A store that applied an entry refuses it again, by index and by commit id (a
    restart that resumed before its store's applied index)."""
    sim = run_seed(2, faults=CALM, commits=True)
    node = replica(sim, 1)
    last = sim.checker.history[node.applied - 1]
    with pytest.raises(Violation, match="applied twice"), node.batch():
        node.apply(last)
    committed = next(
        e
        for e in reversed(sim.checker.history[: node.applied])
        if e.kind.name == "NORMAL" and codec.decode_entry(e.data).commit_id in node.commits
    )
    node.applied = committed.index - 1
    with pytest.raises(Violation, match="applied twice"):
        node.apply(committed)


def test_bench_sim_runs_seeds_in_every_mode_and_reports_counts() -> None:
    """`mapctl bench sim`'s runner: the three modes, summed counts, no violation."""
    result = run_seeds(3, 2)
    assert result["runs"] == 6
    assert result["violations"] == []
    assert result["core"]["acked"] > 0
    assert result["commits"]["commits"] > 0
    assert result["commits"]["acked"] <= result["commits"]["commits"]
    assert result["tx"]["transactions"] >= result["tx"]["acked"] > 0


def test_a_snapshot_from_a_leader_replaces_the_whole_stored_log(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Seed 81 of seven nodes (five voters), under the open client load it ran with (no
    cap on proposals in flight): node 1 held entries 76.. of term 2, a branch that lost;
    it restored the leader's snapshot (76, term 3), and its store kept 77..99 of term 2
    after it. Restarted, it read back a log that breaks Log Matching (and a last term of
    2, so it would grant votes to candidates that lack the committed (76, 3))."""
    monkeypatch.setattr(sim_clients, "IN_FLIGHT", 10**9)
    run_seed(81, nodes=7, voters=5, fault_ticks=300, commits=True)


def test_the_store_drops_a_lost_branch_with_a_leaders_snapshot() -> None:
    """The same, at the store: a restored snapshot leaves no entry after it."""
    store = sim_store.new_store(None)
    branch = [Entry(2, i, EntryKind.NORMAL, b"lost") for i in range(1, 6)]
    disk = sim_store.StoreDisk(store)
    disk.save(Ready(entries=tuple(branch)))
    disk.save(Ready(snapshot=Snapshot(3, 3, Config(frozenset({1})), b"")))
    assert disk.state().entries == ()
