"""The map tables' labels (`mapapi.store.labels`): every row of a mission carries
the mission's name, so the store indexes a mission's rows and keeps its summary.

- a mission row is labelled with its name, placed at its box;
- vertices and landmarks with their mission, placed at their position;
- edges with their mission (they have no place);
- point-cloud blocks with their mission, weighing their points, placed at their box;
- frames (`mapctl align`) with their mission, placed at its box in the world frame;
- occupancy grid tiles with their mission, weighing their cells, placed at their box.

`mapapi.app` gives these to the store of every peer it builds on a repository,
as it gives the mission rules; reads of a mission ask for them (`MAP_LABELS`)
and are answered from the store's index, or by filtering whole tables when the
store keeps none (a memory store, a bare `Peer`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from google.protobuf.message import DecodeError

from mapapi.maps.schema import Edge, Frame, GridTile, Landmark, Mission, PointCloudBlock, Vertex
from mapapi.store.labels import Box, LabelFn, Labels, RowLabel

VERSION = "3"
"""Bumped when a function below changes what it answers (stores then relabel)."""


def _box3(box: Any) -> Box:
    return (box.xmin, box.ymin, box.zmin, box.xmax, box.ymax, box.zmax)


def _point(p: Any) -> Box:
    return (p.x, p.y, p.z, p.x, p.y, p.z)


def _reader(cls: Any, label: Callable[[Any], RowLabel]) -> LabelFn:
    """The label function of rows of `cls`; a row that does not decode has none."""

    def read(data: bytes) -> RowLabel | None:
        try:
            message = cls.FromString(data)
        except DecodeError:
            return None
        return label(message)

    return read


def _mission(m: Any) -> RowLabel:
    return RowLabel(m.name, 1, _box3(m.bbox) if m.HasField("bbox") else None)


def _block(m: Any) -> RowLabel:
    return RowLabel(m.mission, m.count, _box3(m.bbox) if m.HasField("bbox") else None)


def _frame(m: Any) -> RowLabel:
    return RowLabel(m.mission, 1, _box3(m.bbox) if m.HasField("bbox") else None)


def _grid_tile(m: Any) -> RowLabel:
    return RowLabel(m.mission, m.width * m.height, _box3(m.bbox) if m.HasField("bbox") else None)


def map_labels() -> Labels:
    """The labels of the map tables' rows, by their protobuf type."""
    by_type = {
        Mission.DESCRIPTOR.full_name: _reader(Mission, _mission),
        Vertex.DESCRIPTOR.full_name: _reader(
            Vertex, lambda m: RowLabel(m.mission, 1, _point(m.pose))
        ),
        Edge.DESCRIPTOR.full_name: _reader(Edge, lambda m: RowLabel(m.mission)),
        Landmark.DESCRIPTOR.full_name: _reader(
            Landmark, lambda m: RowLabel(m.mission, 1, _point(m.position))
        ),
        PointCloudBlock.DESCRIPTOR.full_name: _reader(PointCloudBlock, _block),
        # a place has the mission's box in the world frame: the spatial index
        # places its frames chunk there, for queries in the world frame
        Frame.DESCRIPTOR.full_name: _reader(Frame, _frame),
        GridTile.DESCRIPTOR.full_name: _reader(GridTile, _grid_tile),
    }
    return Labels(by_type, VERSION)


MAP_LABELS = map_labels()
"""The labels every read of a mission asks for (`mapapi.maps.stored`)."""
