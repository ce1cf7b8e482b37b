"""A chunk's replication factor (issue 13 §2), set per table or per chunk: its
group keeps at most that many voters (an odd number), every other holder is a
learner, and the factor travels with the chunk's state to every holder, so any
of them that comes to lead keeps it. Real peers on 127.0.0.1."""

from __future__ import annotations

import pytest

from mapapi import Peer
from mapapi.core.errors import UsageError
from mapapi.swarm.raft_wire import node_id
from tests.swarm.conftest import TABLE, Counter, MakeSwarm, net, share


def _roles(leader: Peer, peers: list[Peer], chunk: object) -> list[str]:
    """Each peer's role in the chunk's group, as its leader reports it, in peer order."""
    roles = leader.roles(chunk)  # type: ignore[arg-type]
    return [roles[p.id] for p in peers]


async def test_a_chunk_of_factor_one_has_one_voter_and_learners(swarm: MakeSwarm) -> None:
    peers = await swarm(3)
    founder = peers[0]
    await founder.create_table(TABLE, Counter)  # the default factor, 3
    chunk = await founder.create_chunk(TABLE, replication=1)

    await share(chunk, peers[1:])

    config = net(founder).groups.config(chunk)
    assert config.voters == {node_id(founder.id)}
    assert config.learners == {node_id(p.id) for p in peers[1:]}
    assert _roles(founder, peers, chunk) == ["leader", "learner", "learner"]
    assert [p.store.replication(chunk) for p in peers] == [1, 1, 1]  # came with the state


async def test_a_tables_factor_is_its_chunks_unless_one_has_its_own(swarm: MakeSwarm) -> None:
    peers = await swarm(5)
    founder = peers[0]
    await founder.create_table(TABLE, Counter, replication=5)
    wide = await founder.create_chunk(TABLE)
    narrow = await founder.create_chunk(TABLE, replication=3)

    await share(wide, peers[1:])
    await share(narrow, peers[1:])

    assert len(net(founder).groups.config(wide).voters) == 5
    assert len(net(founder).groups.config(narrow).voters) == 3
    assert sorted(_roles(founder, peers, narrow)) == [
        "leader",
        "learner",
        "learner",
        "voter",
        "voter",
    ]


async def test_a_negative_factor_is_refused(swarm: MakeSwarm) -> None:
    (peer,) = await swarm(1)
    with pytest.raises(UsageError, match="replication factor -1"):
        await peer.create_table(TABLE, Counter, replication=-1)
    await peer.create_table(TABLE, Counter)
    with pytest.raises(UsageError, match="replication factor -2"):
        await peer.create_chunk(TABLE, replication=-2)
    assert peer.chunks(TABLE) == []
