"""Seeded simulations of a Raft group under faults (DESIGN §13); see `mapbench.sim`.

Two runs per seed: the pure core (`test_seed`) and the commit path, real stores and
`apply_proposal` (`test_commit_seed`). A failing seed names the command that replays it alone:
`SIM_SEED=<n> .venv/bin/python -m pytest tests/sim -k seed -s`; `mapctl bench sim --seeds N`
runs more.
"""

from __future__ import annotations

import os

import pytest

from mapapi.swarm.raft_types import Entry, Role
from mapbench.sim import TICK, Faults, Sim, SimNode, Violation, replay_command

SEEDS = 300  # the pure core: about 7 s on one core; `SIM_SEEDS=5000 pytest tests/sim -k seed`
COMMIT_SEEDS = 200  # the commit path (about 0.07 s a seed): about 15 s on one core
CALM = Faults(drop=0.0, duplicate=0.0, max_delay=5, defer_ready=0.0, fault_every=10**9)


def run_seed(seed: int, **kwargs: object) -> Sim:
    """Run one seed; on a violation, fail with the seed's summary and its replay command."""
    sim = Sim(seed, **kwargs)  # type: ignore[arg-type]
    try:
        sim.run()
    except Violation as err:
        trace = "\n".join(sim.trace[-15:])
        pytest.fail(
            f"{err}\n{sim.summary()}\nlast faults:\n{trace}\nreplay: {replay_command(seed)}",
            pytrace=False,
        )
    return sim


def _seeds(default: int) -> list[int]:
    """The seeds to run: SIM_SEED alone (a replay), else the first SIM_SEEDS (or `default`)."""
    if "SIM_SEED" in os.environ:
        return [int(os.environ["SIM_SEED"])]
    return list(range(int(os.environ.get("SIM_SEEDS", default))))


@pytest.mark.parametrize("seed", _seeds(SEEDS))
def test_seed(seed: int) -> None:
    """Every invariant holds through this seed's faults, and the group recovers after them."""
    print(run_seed(seed).summary())  # shown with -s, e.g. when replaying one seed


@pytest.mark.parametrize("seed", _seeds(COMMIT_SEEDS))
def test_commit_seed(seed: int) -> None:
    """The same, through the commit path: one history of commits on every store, every
    acknowledged commit present, the counter and the bank add up."""
    print(run_seed(seed, commits=True).summary())


def test_same_seed_same_run() -> None:
    """A seed determines the whole run: two runs of it produce the same history."""
    first, second = run_seed(7), run_seed(7)
    assert first.checker.history == second.checker.history
    assert first.trace == second.trace


def test_calm_world_commits_every_proposal() -> None:
    """Without faults every proposal is acknowledged and no outcome is unknown."""
    sim = run_seed(1, faults=CALM)
    assert sim.acked
    assert not sim.failed
    assert not sim.unknown
    assert len(sim.acked) == len(sim.proposed)


def test_faults_are_exercised() -> None:
    """The seeds really inject what they claim: snapshots, failed and unknown proposals."""
    sims = [run_seed(seed, compact_after=4) for seed in range(20)]
    assert any(s.failed for s in sims)
    assert any(s.unknown for s in sims)
    assert any("REMOVE_NODE" in line for s in sims for line in s.trace)
    assert sum(len(s.checker.leaders) for s in sims) > 2 * len(sims)  # leaders changed


def test_checker_catches_a_divergent_apply() -> None:
    """The state-machine-safety checker is not vacuous: a forged apply is reported."""
    sim = run_seed(3, faults=CALM)
    node = sim.nodes[1]
    forged = sim.checker.history[-1]
    with pytest.raises(Violation, match="applied"):
        sim.checker.applied(node, type(forged)(forged.term + 1, forged.index, forged.kind))


def test_a_violation_names_the_command_that_replays_its_seed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def violate(self: Sim) -> None:
        raise Violation("forged")

    monkeypatch.setattr(Sim, "run", violate)
    with pytest.raises(pytest.fail.Exception) as failed:
        run_seed(5)
    assert "forged" in str(failed.value)
    assert "replay: SIM_SEED=5 .venv/bin/python -m pytest tests/sim -k seed -s" in str(failed.value)


def _led(sim: Sim) -> SimNode:
    """The node that leads at the end of a calm run."""
    (leader,) = [n for n in sim.nodes.values() if n.alive and n.raft.role is Role.LEADER]
    return leader


def test_checker_catches_two_leaders_in_one_term() -> None:
    """Election Safety is checked: a second leader of a term is reported."""
    sim = run_seed(3, faults=CALM)
    leader = _led(sim)
    sim.checker.leaders[leader.raft.term] = leader.id + 1  # as if another led this term
    with pytest.raises(Violation, match="two leaders in term"):
        sim.checker.leader(leader)


def test_checker_catches_two_entries_at_one_index_and_term() -> None:
    """Log Matching is checked: another entry persisted at a known (index, term) is reported."""
    sim = run_seed(3, faults=CALM)
    known = sim.checker.history[-1]
    forged = Entry(known.term, known.index, known.kind, known.data + b"forged")
    with pytest.raises(Violation, match="two different entries"):
        sim.checker.persisted(next(iter(sim.nodes.values())), (forged,))


def test_checker_catches_a_leader_without_a_committed_entry() -> None:
    """Leader Completeness is checked: a leader elected later whose log lacks an entry
    applied at an earlier term is reported."""
    sim = run_seed(3, faults=CALM)
    leader = _led(sim)
    index = sim.checker.history[-1].index
    sim.checker.history[-1] = Entry(leader.raft.term + 5, index)  # applied as another entry
    sim.checker.bounds[-1] = 0  # ... in a term before this leader's
    sim.checker.leaders.pop(leader.raft.term)  # so its election is checked again
    with pytest.raises(Violation, match="lacks applied"):
        sim.checker.leader(leader)


# -- regressions: seeds that found bugs, kept as named tests -----------------------------


def test_removed_leader_with_longer_log_does_not_block_election() -> None:
    """Seed 9: a leader removed itself and stepped down with a longer log than the last
    voter, who had not learnt the commit and still counted it; with configs applied on
    commit nobody could win. Configs now apply when appended (thesis §4.1)."""
    run_seed(9)


def test_removed_leader_that_lost_its_quorum_may_campaign_again() -> None:
    """Seed 82: a leader that removed itself lost its quorum (CheckQuorum) before the removal
    committed; the one remaining voter lacked the removal and needed its vote, which it
    refused (longer log), and it could not campaign. A server removed by an uncommitted change
    may now campaign without counting its own vote (thesis §4.2.2)."""
    run_seed(82)


def test_leader_of_an_old_term_elected_late_is_not_a_completeness_violation() -> None:
    """Seeds 708 and 2118 (checker bug): delayed votes made a node leader of term 2 after a
    term-3 entry was applied; Leader Completeness only binds leaders of later terms."""
    run_seed(708)
    run_seed(2118)


def test_slow_world_recovers_within_the_liveness_bound() -> None:
    """Seed 21: delays of 4 ticks and deferred Readys; heals within 100 ticks."""
    sim = run_seed(21)
    assert sim.now <= sim.fault_end + 100 * TICK
