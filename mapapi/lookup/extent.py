"""Where an item lies: its bounding box and, for missions, its name, by the
item's protobuf type (DESIGN §7: tables whose items have a box register their
chunk's box in the spatial index at commit).

The built-in extents:

- ``google.protobuf.Struct``: a ``"bbox"`` field holding six numbers
  ``[xmin, ymin, zmin, xmax, ymax, zmax]``, so schemaless items made with
  ``mapctl set`` can be placed in space;
- ``mapapi.v1.Mission`` (its ``bbox``, labelled with its name),
  ``mapapi.v1.Vertex`` (its position), ``mapapi.v1.Landmark`` (its position)
  ``mapapi.v1.PointCloudBlock`` (its ``bbox``), ``mapapi.v1.Frame`` (its
  ``bbox``, the mission's in the world frame) and ``mapapi.v1.GridTile`` (its
  ``bbox``: an occupancy grid's tile), each labelled with the name of
  the mission it belongs to.

Other types can be added with `register_extent`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from google.protobuf.message import Message

from mapapi.core.errors import InvalidBBox
from mapapi.lookup.spatial import BBox

BoxFn = Callable[[Any], BBox | None]
LabelFn = Callable[[Any], str]


@dataclass(frozen=True, slots=True)
class Extent:
    """How to place an item of one type: its box, and optionally a label naming
    what it stands for (a mission's name)."""

    box: BoxFn
    label: LabelFn | None = None


def _box3(box: Any) -> BBox:
    return BBox(box.xmin, box.ymin, box.zmin, box.xmax, box.ymax, box.zmax)


def _point(p: Any) -> BBox:
    return BBox.around((p.x, p.y, p.z))


def _struct_box(message: Any) -> BBox | None:
    value = message.fields.get("bbox")
    if value is None or value.WhichOneof("kind") != "list_value":
        return None
    numbers = [
        v.number_value for v in value.list_value.values if v.WhichOneof("kind") == "number_value"
    ]
    if len(numbers) != 6 or len(value.list_value.values) != 6:
        return None
    try:
        return BBox.from_tuple(numbers)
    except InvalidBBox:
        return None  # not a box: the item is simply not placed in space


def _mission_of(message: Any) -> str:
    return str(message.mission)


def _optional_box3(message: Any) -> BBox | None:
    return _box3(message.bbox) if message.HasField("bbox") else None


_EXTENTS: dict[str, Extent] = {
    "google.protobuf.Struct": Extent(_struct_box),
    "mapapi.v1.Mission": Extent(_optional_box3, label=lambda m: str(m.name)),
    # A mission's vertices, landmarks and clouds are labelled with its name too,
    # so a query that finds only them still says which missions they belong to.
    "mapapi.v1.Vertex": Extent(lambda m: _point(m.pose), label=_mission_of),
    "mapapi.v1.Landmark": Extent(lambda m: _point(m.position), label=_mission_of),
    "mapapi.v1.PointCloudBlock": Extent(_optional_box3, label=_mission_of),
    # A mission's place in the world frame lies at its box there (`mapctl align`).
    "mapapi.v1.Frame": Extent(_optional_box3, label=_mission_of),
    # An occupancy grid's tiles lie at their boxes, so a box query finds the grid.
    "mapapi.v1.GridTile": Extent(_optional_box3, label=_mission_of),
}


def register_extent(type_name: str, extent: Extent) -> None:
    """Place the items of protobuf type `type_name` with `extent` (replacing any)."""
    _EXTENTS[type_name] = extent


def extent_of(type_name: str) -> Extent | None:
    """How items of `type_name` are placed, or None when they have no place."""
    return _EXTENTS.get(type_name)


def item_box(message: Message) -> BBox | None:
    """The box of one item, or None when its type (or the item) has none."""
    extent = extent_of(message.DESCRIPTOR.full_name)
    return None if extent is None else extent.box(message)
