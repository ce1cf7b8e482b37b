"""Hostile messages never crash a peer or corrupt its store (DESIGN §11, issue 7 §5).

A real peer process (with a holder and a member, `mapbench.fuzz.target_swarm`)
receives messages of every body type from a real zmq socket, as strangers and
as a member: valid, with hostile fields (wrong id lengths, huge counts and
numbers, NaN, unknown enum values, random bytes) or broken as bytes (bit
flips, truncations), plus commits through the target's log (real
proposals, or ones a hostile writer would make). Hypothesis draws each
example's body type, mode and the seed of the generator
(`mapbench.hostile`) that fills the fields; the target's answers steer
later messages (its clock), so the fields are not drawn by hypothesis
itself, whose replays must not depend on outside state. Each example's answers are checked as
they arrive (an "internal error" reply or a wrong reply fails it); after all
examples the peer must answer a Ping and a commit through it, and its store
must pass `PRAGMA integrity_check` and hold exactly the data it held, but for
acknowledged commits of the member's chunk. `mapctl bench fuzz` runs the same
harness with more messages (docs/benchmarks.md).
"""

from __future__ import annotations

import os
import random
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mapapi.core.ids import ChunkId, PeerId
from mapbench import store_check
from mapbench.fuzz import Target, commit_flow, finish, target_swarm
from mapbench.fuzz_client import Fuzzer
from mapbench.hostile import BODIES, MODES, Generator

EXAMPLES = 600
PER_EXAMPLE = 6  # messages per example: the drawn body first, then any
ANSWER_WAIT = 0.5  # seconds an example waits for its answers (slow ones are checked at the end)


@pytest.fixture(scope="module")
def target(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Target]:
    """The three peer processes of `mapctl bench fuzz`, for the whole module."""
    with target_swarm(Path(tmp_path_factory.mktemp("fuzz"))) as started:
        yield started


def test_hostile_messages_never_hurt_the_peer(
    target: Target, record_property: Callable[[str, object], None]
) -> None:
    pools = target.pools()
    before = store_check.snapshot(target.store)
    member = PeerId(target.m.id).to_bytes()
    senders = [os.urandom(16) for _ in range(4)] + [member] * 4
    chunk = ChunkId(target.chunks["C"]).to_bytes()
    fuzzer = Fuzzer(target.t.address, pools)
    started = time.perf_counter()

    @settings(
        max_examples=EXAMPLES,
        deadline=None,
        suppress_health_check=[HealthCheck.too_slow],
    )
    @given(
        body=st.sampled_from(BODIES),
        mode=st.sampled_from(MODES),
        flow=st.booleans(),
        seed=st.integers(0, 2**32),
    )
    def one_batch(body: str, mode: str, flow: bool, seed: int) -> None:
        out = fuzzer.outcome
        bad = out.internal_errors + out.wrong_replies
        waiting = fuzzer.in_flight  # slow ones of earlier examples (a proposal, a join)
        generator = Generator(random.Random(seed), pools, senders)
        fuzzer.send(generator.shot(body, mode))
        for _ in range(PER_EXAMPLE - 1):
            fuzzer.send(generator.shot())
        if flow:
            commit_flow(generator, fuzzer, target, chunk, member)
        end = time.monotonic() + ANSWER_WAIT
        while fuzzer.in_flight > waiting and time.monotonic() < end:
            fuzzer.collect(0.05)
        assert out.internal_errors + out.wrong_replies == bad, out.problems[-3:]

    try:
        one_batch()
        fuzzer.drain()
        report = finish(target, fuzzer, before, time.perf_counter() - started, seed=0)
    finally:
        fuzzer.close()
    for key in ("messages", "error_replies", "valid_replies", "dropped"):
        record_property(f"fuzz_{key}", report[key])
    assert report["problems"] == []
    assert report["crashes"] == 0
    assert report["peer_ok"]
    assert report["store_ok"]
    assert report["missing_replies"] == report["internal_errors"] == 0
    assert report["messages"] == (
        report["error_replies"]
        + report["valid_replies"]
        + report["notifications"]
        + report["dropped"]
    )
    assert set(report["by_body"]) == set(BODIES)  # every body type was tried
