"""`align` in a swarm (issue 17 §1): the frames one peer commits reach every
holder of the missions, and two peers that align at once conflict on the same
rows, which `resolve` settles like any conflict.

Three real peers on SQLite repositories; a holds the synthetic missions of
`tests/unit/test_maps_world.py` (known frames), b and c load them by box.
"""

from __future__ import annotations

import numpy as np
import pytest

from mapapi import ConflictError, Peer
from mapapi.maps import FRAMES, import_graphs, list_missions
from mapapi.maps.align_ops import AlignOperations
from mapapi.maps.alignment import pose_matrix
from mapapi.maps.frames import frame_at, frame_item, world_box
from mapapi.maps.operations import MapOperations
from mapapi.maps.stored import GRAPH_READ, read_time
from mapapi.maps.world import WorldFrame
from mapapi.service.workspace import Workspace
from tests.unit.test_maps_world import TRUTH, _scene

from .conftest import MakePeer, lookup_swarm

pytest.importorskip("gtsam", reason="the registration extra (make test installs it)")
EVERYWHERE = [-1000.0, -1000.0, -1000.0, 1000.0, 1000.0, 1000.0]


async def _frames(peer: Peer, names: list[str]) -> dict[str, WorldFrame | None]:
    """Each mission's place in the world frame as `peer` reads it now (at a time
    its replicas read as every holder's will)."""
    async with read_time(peer, names, (*GRAPH_READ, FRAMES)) as at:
        return {name: frame_at(peer, at, name) for name in names}


async def _aligned_swarm(make_peer: MakePeer) -> list[Peer]:
    a, b, c = await lookup_swarm(make_peer, 3)
    await import_graphs(a, _scene())
    for peer in (b, c):
        await MapOperations(peer).load_bbox(EVERYWHERE)
    return [a, b, c]


async def test_frames_committed_on_one_peer_are_read_on_the_others(make_peer: MakePeer) -> None:
    a, b, c = await _aligned_swarm(make_peer)

    done = await AlignOperations(a, Workspace(a)).align("main", anchor="a")

    assert [f["mission"] for f in done["frames"]] == ["a", "b", "c"]
    assert done["unaligned"] == ["d"]
    for peer in (a, b, c):
        found = await _frames(peer, ["a", "b", "c", "d"])
        assert found["d"] is None
        for name in ("b", "c"):
            place = found[name]
            assert place is not None
            assert np.allclose(pose_matrix(place.pose), pose_matrix(TRUTH[name]), atol=1e-4)
    record = a.store.commit_record(done["commit"])
    assert record is not None
    assert record.message == done["message"]


async def test_two_peers_aligning_at_once_conflict_and_resolve(make_peer: MakePeer) -> None:
    _, b, c = await _aligned_swarm(make_peer)
    views_b, views_c = Workspace(b), Workspace(c)
    views_b.open("main")
    views_c.open("main")  # both begin before either aligns

    first = await AlignOperations(b, views_b).align("main", anchor="a", message="b's frames")
    with pytest.raises(ConflictError):
        await AlignOperations(c, views_c).align("main", anchor="b", message="c's frames")

    # A commit of several chunks stops at the first that refuses it: the user
    # resolves what is reported and commits again, as with any conflict.
    wanted = {frame_item(name) for name in ("a", "b", "c")}
    seen: set[str] = set()
    record = None
    for _ in wanted:
        view = views_c.get("main")
        assert view is not None
        conflicts = {conflict.item_id for conflict in view.conflicts}
        assert conflicts
        assert conflicts <= wanted - seen
        seen |= conflicts
        assert views_c.resolve("main", "ours")  # c keeps its own alignment, anchored at b
        try:
            record = await views_c.commit("main", "c's frames, after b's")
            break
        except ConflictError:
            continue
    assert record is not None

    for peer in (b, c):
        found = await _frames(peer, ["a", "b"])
        assert found["b"] is not None
        assert found["b"].anchor == "b"
        assert found["a"] is not None
        assert np.allclose(pose_matrix(found["b"].pose), np.eye(4), atol=1e-9)
    assert first["anchor"] == "a"


async def test_a_box_in_the_world_frame_finds_and_loads_the_missions_aligned_there(
    make_peer: MakePeer,
) -> None:
    a, _, c = await lookup_swarm(make_peer, 3)
    await import_graphs(a, _scene())
    await AlignOperations(a, Workspace(a)).align("main", anchor="a")
    ops = MapOperations(c)
    far = [-5.0, 45.0, -1.0, 40.0, 55.0, 1.0]  # where d lies in its own frame: no place

    assert (await ops.load_bbox(far, frame="world"))["results"] == []
    loaded = await ops.load_bbox([10.0, -2.0, -1.0, 12.0, 2.0, 1.0], frame="world")

    # the places of a, b and c lie there (each at its mission's box moved to the world)
    assert sorted(n for r in loaded["results"] for n in r["missions"]) == ["a", "b", "c"]
    assert {r["table"] for r in loaded["results"]} == {FRAMES}
    infos = {i.name: i for i in await list_missions(c)}
    assert sorted(infos) == ["a", "b", "c"]  # their rows and tiles came; nothing of d
    assert all(i.vertices == 16 for i in infos.values())
    found = await _frames(c, ["b"])
    assert found["b"] is not None
    assert found["b"].bbox == world_box(infos["b"].bbox, found["b"].pose)
    # in the missions' own frames the same far box finds d, and no place
    mission = await ops.load_bbox(far)
    assert {n for r in mission["results"] for n in r["missions"]} == {"d"}
    assert FRAMES not in {r["table"] for r in mission["results"]}
