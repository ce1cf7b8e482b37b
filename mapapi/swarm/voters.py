"""Who votes in a chunk's Raft group (DESIGN §13): pure policy, no I/O.

Every holder of a chunk is a member of its group, but only an odd number of them
vote, at most the chunk's replication factor; the others are learners, which
receive the log and never block a commit. So a robot that only reads another's
mission never slows it down, and two holders are one voter and one learner, never
a two-voter group that stops when either is away.

`next_change` answers one question: given the group's configuration now and the
holders it should have, which single-server change comes next (the core applies
one at a time, thesis §4.1)? The leader asks again after each change applies,
until the answer is None.

Order, so that a group keeps as many working voters as it can:
1. remove members that should no longer hold the chunk (learners first, as
   they cost nothing; a dead voter is removed before anything is added);
2. add new holders as learners (they catch up without counting in quorums);
3. promote learners until the voters reach the target (lowest id first, so
   every leader picks the same), only those caught up with the log: a member
   that never answers never votes; and from an odd number of voters only when
   two are ready, so the voters never stay even waiting for a laggard;
4. retire surplus voters (a voter cannot be demoted in place: it is removed,
   and step 2 adds it back as a learner).
"""

from __future__ import annotations

from collections.abc import Collection

from mapapi.swarm.raft_types import ConfChange, ConfChangeKind, Config

DEFAULT_REPLICATION = 3
"""Voters a chunk's group aims for when it has that many holders."""


def voter_target(holders: int, factor: int = DEFAULT_REPLICATION) -> int:
    """The number of voters for `holders` holders: the largest odd number at most
    `factor` and `holders` (at least 1).

    Raises:
        ValueError: `factor` is below 1.
    """
    if factor < 1:
        raise ValueError(f"a replication factor is at least 1, not {factor}")
    limit = max(1, min(factor, holders))
    return limit if limit % 2 else limit - 1


def next_change(
    config: Config,
    holders: Collection[int],
    factor: int = DEFAULT_REPLICATION,
    leader: int | None = None,
    promotable: Collection[int] | None = None,
) -> ConfChange | None:
    """The next single-server change that brings `config` to `holders` with the
    right number of voters, or None when it is there, or waits for a learner to
    catch up (see the module docstring).

    Args:
        holders: the node ids that should hold the chunk.
        leader: the proposing leader, which retires itself last (it would step
            down, and a new leader would have to finish the work).
        promotable: the learners caught up with the log (None: every learner).
    """
    wanted = set(holders)
    for node in sorted(config.learners - wanted) + sorted(config.voters - wanted):
        if len(config.voters) > 1 or node not in config.voters:
            return ConfChange(ConfChangeKind.REMOVE_NODE, node)
    for node in sorted(wanted - config.members):
        return ConfChange(ConfChangeKind.ADD_LEARNER, node)
    target = voter_target(len(wanted & config.members), factor)
    if len(config.voters) < target:
        ready = config.learners if promotable is None else config.learners & set(promotable)
        needed = 2 if len(config.voters) % 2 else 1  # the next odd count, or nothing
        return ConfChange(ConfChangeKind.ADD_VOTER, min(ready)) if len(ready) >= needed else None
    if len(config.voters) > target:
        surplus = sorted(config.voters - {leader}, reverse=True)
        return ConfChange(ConfChangeKind.REMOVE_NODE, surplus[0])
    return None
