"""Seeded simulations of transactions over two chunks (two-phase commit, DESIGN §13);
see `mapbench.sim_tx`. A failing seed names the command that replays it alone:
`SIM_SEED=<n> .venv/bin/python -m pytest tests/sim -k tx_seed -s`; `mapctl bench sim --mode tx`
runs more.
"""

from __future__ import annotations

import os
import re

import pytest

from mapapi.core.proposal import TxDecision
from mapapi.store.memory import MemoryStore
from mapapi.swarm import apply_tx
from mapbench import sim_tx_world
from mapbench.sim import replay_command
from mapbench.sim_tx import TxSim
from mapbench.sim_world import Violation

TX_SEEDS = 300  # about 0.04 s a seed


def _seeds(default: int) -> list[int]:
    if "SIM_SEED" in os.environ:
        return [int(os.environ["SIM_SEED"])]
    return list(range(int(os.environ.get("SIM_SEEDS", default))))


@pytest.mark.parametrize("seed", _seeds(TX_SEEDS))
def test_tx_seed(seed: int) -> None:
    """No half-applied transaction is ever read, acknowledged ones are everywhere,
    aborted ones nowhere, and every prepare is decided once the faults stop."""
    sim = TxSim(seed)
    try:
        sim.run()
    except Violation as err:
        pytest.fail(
            f"{err}\n{sim.summary()}\nreplay: {replay_command(seed, 'tx_seed')}",
            pytrace=False,
        )
    print(sim.summary())


def test_the_seeds_commit_across_chunks_and_recover_abandoned_ones() -> None:
    """The runs are not vacuous: two-chunk transactions commit, and leaders settle
    prepares their crashed coordinators left."""
    totals: dict[str, int] = {}
    for seed in range(40):
        sim = TxSim(seed)
        sim.run()
        for name, n in sim.counts().items():
            totals[name] = totals.get(name, 0) + n
    assert totals["acked"] > 0.15 * totals["transactions"]
    assert totals["settled_by_recovery"] > 0
    assert totals["busy_retries"] > 0


def test_a_decision_lost_on_one_chunk_is_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    """A holder that aborts what it was told to commit on the second chunk leaves
    transactions half applied: the checker fails the run."""
    real = apply_tx.apply_decision

    def forgetful(store: MemoryStore, chunk: object, decision: TxDecision) -> object:
        if chunk == sim_tx_world.B:
            decision = TxDecision(decision.commit_id, False)
        return real(store, chunk, decision)  # type: ignore[arg-type]

    monkeypatch.setattr(apply_tx, "apply_decision", forgetful)
    found = violations(range(20))
    assert any(re.search(r"partly applied|bank total|missing", v) for v in found), found


def test_a_chunk_that_does_not_wait_for_the_decision_is_caught(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Without the hold a prepare puts on its chunk, other commits slip in between
    the prepare and the decision, and the bank total breaks."""
    monkeypatch.setattr(MemoryStore, "raft_tx_prepared", lambda self, chunk: [])
    assert violations(range(40))


def violations(seeds: range) -> list[str]:
    """What the checker found in each of these seeds' runs."""
    found = []
    for seed in seeds:
        try:
            TxSim(seed).run()
        except Violation as err:
            found.append(str(err))
    return found


def test_same_seed_same_run() -> None:
    first, second = TxSim(11), TxSim(11)
    first.run()
    second.run()
    assert first.logs == second.logs
    assert first.counts() == second.counts()
