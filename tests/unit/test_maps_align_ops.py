"""`align` on one peer: a mission imported before missions had a frames chunk
gets one at its first alignment, named in its row; aligning again updates the
same rows (history), and a mission alone is its own world."""

from __future__ import annotations

import pytest

from mapapi.app import memory_peer
from mapapi.maps import FRAMES, MISSIONS, import_graphs
from mapapi.maps.align_ops import AlignOperations
from mapapi.maps.frames import frame_item
from mapapi.service.workspace import Workspace
from tests.unit.test_maps_world import _scene

pytest.importorskip("gtsam", reason="the registration extra (make test installs it)")


async def test_a_mission_without_a_frames_chunk_gets_one_and_aligning_again_updates() -> None:
    peer = memory_peer()
    try:
        await import_graphs(peer, _scene())
        tx = peer.begin()  # as missions were written before they had a frames chunk
        for item, row in (await tx.items(MISSIONS)).items():
            if row.name == "b":
                del row.chunks[FRAMES]
                tx.update(MISSIONS, item, row)
        await tx.commit("forget b's frames chunk")
        old_chunks = set(peer.store.chunk_ids(FRAMES))
        ops = AlignOperations(peer, Workspace(peer))

        first = await ops.align("main", anchor="a")
        second = await ops.align("main", anchor="a", message="again")

        rows = {r.name: r for r in (await peer.begin().items(MISSIONS)).values()}
        made = set(peer.store.chunk_ids(FRAMES)) - old_chunks
        assert made == {rows["b"].chunks[FRAMES]}  # one new chunk, named in b's row
        assert [f["mission"] for f in first["frames"]] == ["a", "b", "c"]
        history = peer.store.history(frame_item("b"))
        assert [r.commit_id for r in history] == [first["commit"], second["commit"]]
        assert history[1].kind == "updated"
    finally:
        await peer.close()
