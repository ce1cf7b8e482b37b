"""The mission rules checked at commit (issue 15): a vertex index is unique in
its mission and an edge's ends exist, whoever commits (a script through the
library here; `mapctl set` in tests/cli/test_maps_commands.py; an import)."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from pathlib import Path

import pytest

from mapapi import ItemId, Peer
from mapapi.maps import EDGES, VERTICES, import_graph, list_missions, read_g2o
from mapapi.maps.errors import MissionRuleError
from mapapi.maps.schema import Edge, Vertex, pose_to_pb
from mapapi.maps.se3 import IDENTITY

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
INTEL = SAMPLES / "pose_graphs" / "intel.g2o"

MakePeer = Callable[..., Awaitable[Peer]]


@pytest.fixture
async def intel(make_peer: MakePeer) -> Peer:
    """A peer on a real repository holding the Intel graph (1,728 vertices)."""
    peer = await make_peer()
    await import_graph(peer, read_g2o(INTEL))
    return peer


def vertex(index: int, mission: str = "intel") -> Vertex:
    return Vertex(mission=mission, index=index, pose=pose_to_pb(IDENTITY))


def edge(i: int, j: int, mission: str = "intel") -> Edge:
    message = Edge(mission=mission, relative=pose_to_pb(IDENTITY), kind=Edge.Kind.LOOP)
    message.from_vertex.mission, message.from_vertex.index = mission, i
    message.to_vertex.mission, message.to_vertex.index = mission, j
    message.information.extend([1.0] * 21)
    return message


async def vertex_id(peer: Peer, index: int) -> ItemId:
    tx = peer.begin()
    (found,) = await tx.find(VERTICES, "index", index)
    tx.abort()
    return found


async def counts(peer: Peer) -> tuple[int, int]:
    (info,) = await list_missions(peer)
    return info.vertices, info.edges


class TestVertexIndices:
    async def test_a_second_vertex_100_is_refused_naming_both_items(self, intel: Peer) -> None:
        existing = await vertex_id(intel, 100)
        tx = intel.begin()
        chunk = intel.chunks(VERTICES)[-1].id  # any tile: the rule sees them all
        second = tx.insert(VERTICES, vertex(100), chunk)

        with pytest.raises(MissionRuleError) as caught:
            await tx.commit("a bogus pose")

        message = str(caught.value)
        assert "mission 'intel'" in message
        assert "vertex 100" in message
        assert str(existing) in message
        assert str(second) in message
        assert (caught.value.mission, caught.value.index) == ("intel", 100)
        assert caught.value.items == (existing, second)
        assert caught.value.exit_code == 2
        assert await counts(intel) == (1_728, 2_512)  # nothing was written

    async def test_moving_a_vertex_onto_a_taken_index_is_refused(self, intel: Peer) -> None:
        moved = await vertex_id(intel, 5)
        tx = intel.begin()
        tx.update(VERTICES, moved, vertex(6))
        with pytest.raises(MissionRuleError, match="vertex 6"):
            await tx.commit()

    async def test_two_new_vertices_of_one_index_in_one_commit_are_refused(
        self, intel: Peer
    ) -> None:
        chunk = intel.chunks(VERTICES)[-1].id  # any tile: the rule sees them all
        tx = intel.begin()
        tx.insert(VERTICES, vertex(5_000), chunk)
        tx.insert(VERTICES, vertex(5_000), chunk)
        with pytest.raises(MissionRuleError, match="vertex 5000"):
            await tx.commit()

    async def test_a_new_index_an_edge_to_it_and_a_swap_are_accepted(self, intel: Peer) -> None:
        chunk = intel.chunks(VERTICES)[-1].id  # any tile: the rule sees them all
        edges = intel.chunks(EDGES)[-1].id
        tx = intel.begin()
        tx.insert(VERTICES, vertex(5_000), chunk)
        tx.insert(EDGES, edge(1_727, 5_000), edges)
        # the same index again in another mission is no duplicate
        tx.insert(VERTICES, vertex(100, mission="other"), chunk)
        await tx.commit()
        # two vertices swap their indices in one commit: unique before and after
        a, b = await vertex_id(intel, 7), await vertex_id(intel, 8)
        tx = intel.begin()
        tx.update(VERTICES, a, vertex(8))
        tx.update(VERTICES, b, vertex(7))
        await tx.commit()
        assert await vertex_id(intel, 7) == b

    async def test_a_removed_index_may_be_taken_again(self, intel: Peer) -> None:
        chunk = intel.chunks(VERTICES)[-1].id  # any tile: the rule sees them all
        tx = intel.begin()
        tx.insert(VERTICES, vertex(6_000), chunk)
        await tx.commit()
        tx = intel.begin()
        tx.remove(VERTICES, await vertex_id(intel, 6_000))
        await tx.commit()
        tx = intel.begin()
        tx.insert(VERTICES, vertex(6_000), chunk)
        await tx.commit()


class TestEdgeEnds:
    async def test_an_edge_to_a_missing_vertex_is_refused(self, intel: Peer) -> None:
        edges = intel.chunks(EDGES)[-1].id
        tx = intel.begin()
        added = tx.insert(EDGES, edge(3, 9_999), edges)
        with pytest.raises(MissionRuleError, match="vertex 9999") as caught:
            await tx.commit()
        assert str(added) in str(caught.value)

    async def test_removing_a_vertex_an_edge_ends_at_is_refused(self, intel: Peer) -> None:
        tx = intel.begin()
        tx.remove(VERTICES, await vertex_id(intel, 100))
        with pytest.raises(MissionRuleError, match=r"vertex 100 .*edge"):
            await tx.commit()

    async def test_an_edge_to_a_mission_not_held_here_is_not_judged(self, intel: Peer) -> None:
        edges = intel.chunks(EDGES)[-1].id
        message = edge(3, 4)
        message.to_vertex.mission = "robot7"  # another robot's mission, not held here
        tx = intel.begin()
        tx.insert(EDGES, message, edges)
        await tx.commit()


async def test_an_import_is_checked_too(make_peer: MakePeer) -> None:
    """An import commits through the same rule (the importer checks first, so
    here a second mission's rows are staged by hand into the first's chunk)."""
    peer = await make_peer()
    await import_graph(peer, read_g2o(INTEL))
    chunk = peer.chunks(VERTICES)[-1].id
    tx = peer.begin()
    tx.insert_many(VERTICES, [vertex(i) for i in (0, 1)], chunk)
    with pytest.raises(MissionRuleError, match="vertex 0"):
        await tx.commit()
