"""Missions' places in shared frames, as rows of the `frames` table (issue 17 §1).

A mission's place in the `world` frame is one row (`Frame`) in the mission's
frames chunk, the chunk its mission row names under `frames` (made with the
mission at import; for a mission imported before, by its first alignment).
The row's item id is derived from the mission's and the frame's names
(`frame_item`), so every peer that aligns a mission writes the same item in the
same chunk: two alignments made at once conflict there, git-style, and one is
resolved with `mapctl resolve` like any conflict. The rows replicate and keep
their history like any other, and `mapctl log` shows who aligned what, when.
"""

from __future__ import annotations

import hashlib
import itertools
from collections.abc import Iterable, Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from mapapi.core.errors import UsageError
from mapapi.core.ids import ChunkId, ItemId
from mapapi.lookup.spatial import BBox
from mapapi.maps.alignment import matrix_pose, pose_matrix
from mapapi.maps.graph import MissionGraph
from mapapi.maps.schema import (
    FRAMES,
    MISSIONS,
    Frame,
    box_from_pb,
    box_to_pb,
    pose_from_pb,
    pose_to_pb,
)
from mapapi.maps.se3 import Pose
from mapapi.maps.stored import (
    GRAPH_READ,
    MissionInfo,
    MissionParts,
    graph_at,
    read_time,
    rows_of,
)
from mapapi.maps.world import WORLD, WorldFrame

if TYPE_CHECKING:
    from mapapi.core.transaction import Transaction
    from mapapi.service.peer import Peer

MISSION = "mission"
"""The frame a mission's poses are stored in, its own."""

FRAME_CHOICES = (MISSION, WORLD)
"""The frames reads may give poses in (`--frame`)."""


def frame_reads(frame: str) -> tuple[str, ...]:
    """The tables a read of a pose graph in `frame` needs.

    Raises:
        UsageError: an unknown frame.
    """
    if frame == MISSION:
        return GRAPH_READ
    if frame == WORLD:
        return (*GRAPH_READ, FRAMES)
    raise UsageError(f"no frame {frame!r}; expected one of {', '.join(FRAME_CHOICES)}")


def frame_at(peer: Peer, time: int, mission: str) -> WorldFrame | None:
    """The mission's place in the world frame as of `time` (None: never aligned)."""
    found = [r for r in rows_of(peer, time, FRAMES, mission) if r.frame == WORLD]
    return frame_from_pb(found[0]) if found else None


def place_in_world(peer: Peer, time: int, mission: str, hint: str) -> WorldFrame:
    """The mission's place in the world frame as of `time` (`frame_at`).

    Raises:
        UsageError: it was never placed there; the message ends with `hint`,
            what to do instead.
    """
    found = frame_at(peer, time, mission)
    if found is None:
        raise UsageError(f"mission {mission!r} has no place in the world frame yet; {hint}")
    return found


def graph_in(peer: Peer, time: int, mission: str, frame: str) -> MissionGraph:
    """`graph_at`, its poses in `frame` (in the world frame: moved by the mission's
    place there).

    Raises:
        UsageError: in the world frame, the mission was never aligned.
        MapImportError: no such mission.
    """
    graph = graph_at(peer, time, mission)
    if frame == MISSION:
        return graph
    hint = "run `mapctl align`, or read it in its own frame (--frame mission)"
    return in_frame(graph, place_in_world(peer, time, mission, hint).pose)


def frame_item(mission: str, frame: str = WORLD) -> ItemId:
    """The id of the row holding `mission`'s place in `frame`: the same on every peer."""
    return ItemId(hashlib.sha256(f"mapapi frame\0{mission}\0{frame}".encode()).hexdigest()[:32])


def frame_to_pb(found: WorldFrame, info: MissionInfo | None = None) -> Any:
    """The row of one mission's place in the world frame; with the mission's
    `info`, its box moved there and the chunk of its row."""
    row = Frame(
        mission=found.mission,
        frame=WORLD,
        transform=pose_to_pb(found.pose),
        covariance=found.covariance,
        anchor=found.anchor,
        linked=found.linked,
        edges=found.edges,
        duplicate_of=found.duplicate_of,
        content=found.content,
    )
    if info is not None:
        row.mission_chunk = info.chunks.get(MISSIONS, "")
        if info.bbox is not None:
            row.bbox.CopyFrom(box_to_pb(world_box(info.bbox, found.pose)))
    return row


def frame_from_pb(row: Any) -> WorldFrame:
    """A `frame_to_pb` row read back."""
    return WorldFrame(
        row.mission,
        pose_from_pb(row.transform),
        tuple(row.covariance),
        row.anchor,
        tuple(row.linked),
        row.edges,
        row.duplicate_of,
        row.content,
        box_from_pb(row.bbox) if row.HasField("bbox") else None,
        row.mission_chunk,
    )


def stage_frames(
    tx: Transaction,
    frames: Iterable[WorldFrame],
    held: Mapping[str, MissionInfo],
    chunks: Mapping[str, ChunkId],
    existing: Iterable[str],
) -> None:
    """Buffer each mission's place in `tx` (with what `held` says of the mission):
    an update of its row where `existing` names the mission (its row is there at
    the transaction's begin), else an insert in its frames chunk (`chunks`)."""
    there = set(existing)
    for found in frames:
        row = frame_to_pb(found, held.get(found.mission))
        item = frame_item(found.mission)
        if found.mission in there:
            tx.update(FRAMES, item, row)
        else:
            tx.insert(FRAMES, row, chunks[found.mission], item)


async def world_places(peer: Peer, names: list[str]) -> dict[str, WorldFrame | None]:
    """Each mission's place in the world frame as `peer` reads it now (None: never
    aligned), read in a worker thread."""
    async with read_time(peer, names, (MISSIONS, FRAMES)) as at:
        return await peer.off_loop(lambda: {name: frame_at(peer, at, name) for name in names})


def needed(
    parts: Mapping[str, MissionParts],
    places: Mapping[str, WorldFrame | None],
    box: BBox,
    found: set[ChunkId],
) -> set[ChunkId]:
    """The chunks a load of `box` needs of the missions of `parts`: for one with a
    place (a load in the world frame), its untiled chunks and the tiles whose box,
    moved to the world, overlaps `box`; else `MissionParts.in_box`."""
    wanted: set[ChunkId] = set()
    for name, part in parts.items():
        place = places.get(name)
        if place is None:
            wanted |= part.in_box(box, found)
            continue
        wanted |= set(part.chunks.values())
        for tile in part.tiles:
            if world_box(tile.bbox, place.pose).overlaps(box):
                wanted |= set(tile.chunks())
    return wanted


def row_chunks(places: Mapping[str, WorldFrame | None]) -> set[ChunkId]:
    """The chunks of the mission rows that `places` name."""
    return {ChunkId(p.mission_chunk) for p in places.values() if p and p.mission_chunk}


def world_box(box: BBox, pose: Pose) -> BBox:
    """The box, in a mission's frame, that holds `box` moved by `pose` (its corners'
    box: larger than the points' when the motion turns)."""
    pairs = zip(box.mins, box.maxs, strict=True)
    corners = np.array([[*corner, 1.0] for corner in itertools.product(*pairs)])
    moved = (pose_matrix(pose) @ corners.T).T[:, :3]
    return BBox(*moved.min(axis=0), *moved.max(axis=0))


def in_frame(graph: MissionGraph, pose: Pose) -> MissionGraph:
    """The graph with its vertices moved by `pose` (its origin's place in another
    frame); its edges, relative measurements, stay as they are."""
    move = pose_matrix(pose)
    vertices = {i: matrix_pose(move @ pose_matrix(p)) for i, p in graph.vertices.items()}
    return replace(graph, vertices=vertices, frame=WORLD)
