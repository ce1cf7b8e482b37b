"""Who votes in a chunk's group (swarm/voters.py): an odd number, at most the factor."""

from __future__ import annotations

from collections.abc import Iterable

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mapapi.swarm.raft_types import ConfChange, ConfChangeKind, Config
from mapapi.swarm.voters import next_change, voter_target

ADD_LEARNER, ADD_VOTER, REMOVE = (
    ConfChangeKind.ADD_LEARNER,
    ConfChangeKind.ADD_VOTER,
    ConfChangeKind.REMOVE_NODE,
)


def config(voters: set[int], learners: Iterable[int] = ()) -> Config:
    return Config(frozenset(voters), frozenset(learners))


@pytest.mark.parametrize(
    ("holders", "factor", "voters"),
    [(1, 3, 1), (2, 3, 1), (3, 3, 3), (4, 3, 3), (9, 3, 3), (4, 5, 3), (6, 5, 5), (5, 4, 3)],
)
def test_voters_are_odd_and_at_most_the_factor(holders: int, factor: int, voters: int) -> None:
    assert voter_target(holders, factor) == voters


def test_a_second_holder_joins_as_a_learner_and_stays_one() -> None:
    assert next_change(config({1}), {1, 2}) == ConfChange(ADD_LEARNER, 2)
    assert next_change(config({1}, {2}), {1, 2}) is None  # never a two-voter group


def test_a_third_holder_makes_three_voters() -> None:
    assert next_change(config({1}, {2}), {1, 2, 3}) == ConfChange(ADD_LEARNER, 3)
    assert next_change(config({1}, {2, 3}), {1, 2, 3}) == ConfChange(ADD_VOTER, 2)
    assert next_change(config({1, 2}, {3}), {1, 2, 3}) == ConfChange(ADD_VOTER, 3)
    assert next_change(config({1, 2, 3}), {1, 2, 3}) is None


def test_a_dead_voter_is_removed_and_a_learner_promoted() -> None:
    start = config({1, 2, 3}, {4})
    assert next_change(start, {1, 2, 4}) == ConfChange(REMOVE, 3)
    assert next_change(config({1, 2}, {4}), {1, 2, 4}) == ConfChange(ADD_VOTER, 4)


def test_the_leader_retires_last_when_voters_shrink() -> None:
    assert next_change(config({1, 2, 3}), {1, 2, 3}, factor=1, leader=3) == ConfChange(REMOVE, 2)


def test_the_last_voter_is_never_removed() -> None:
    assert next_change(config({1}), set()) is None


@given(
    st.sets(st.integers(1, 9), min_size=1, max_size=6),
    st.sets(st.integers(1, 9), min_size=1, max_size=6),
    st.integers(1, 5),
)
def test_changes_converge_to_the_holders_with_odd_voters(
    start: set[int], holders: set[int], factor: int
) -> None:
    """Applying next_change until None reaches every holder, nobody else (but a
    last voter), and an odd number of voters at most the factor."""
    voters = sorted(start)[:1]
    current = config(set(voters), start - set(voters))
    for _ in range(40):
        change = next_change(current, holders, factor)
        if change is None:
            break
        current = current.apply(change)
    else:
        pytest.fail("next_change did not converge")
    if current.members != holders:  # only when the last voter must stay
        assert len(current.voters) == 1
        assert not current.voters & holders
    else:
        assert len(current.voters) == voter_target(len(holders), factor)


def test_a_learner_is_promoted_only_once_it_caught_up() -> None:
    config = Config(frozenset({1}), frozenset({2, 3}))
    assert next_change(config, {1, 2, 3}, promotable=set()) is None  # wait for them
    assert next_change(config, {1, 2, 3}, promotable={3}) is None  # 2 voters, stuck: no
    assert next_change(config, {1, 2, 3}, promotable={2, 3}) == ConfChange(
        ConfChangeKind.ADD_VOTER, 2
    )
    halfway = Config(frozenset({1, 2}), frozenset({3}))
    assert next_change(halfway, {1, 2, 3}, promotable={3}) == ConfChange(
        ConfChangeKind.ADD_VOTER, 3
    )
