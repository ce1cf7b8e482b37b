"""An edge row comes back as the edge it was made from, in fewer bytes (issue 14 §4).

`edge_to_pb` leaves out the mission of an end in the edge's own mission and keeps
only the non-zero entries of a sparse information matrix; `edge_from_pb` and the
mission rules' `edge_keys` read both that and the full form older rows have.
"""

from __future__ import annotations

import math

from hypothesis import given
from hypothesis import strategies as st

from mapapi.maps.graph import EdgeKind, GraphEdge, Origin
from mapapi.maps.rules import edge_keys
from mapapi.maps.schema import Edge, edge_from_pb, edge_to_pb
from mapapi.maps.se3 import lift_information

OWN = "robot-a"

value_st = st.floats(allow_nan=False) | st.sampled_from((0.0, -0.0, 0.0, 0.0))
end_st = st.tuples(st.sampled_from((OWN, OWN, "robot-b")), st.integers(0, 2**63))
edge_st = st.builds(
    GraphEdge,
    source=end_st,
    target=end_st,
    relative=st.tuples(*[st.floats(-1e3, 1e3)] * 3, *[st.floats(-1, 1)] * 4),
    information=st.lists(value_st, min_size=21, max_size=21).map(tuple),
    kind=st.sampled_from(list(EdgeKind)),
    origin=st.builds(Origin, st.integers(0, 2**32 - 1), st.text(max_size=20)),
)


def _same(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    """Equal, with the sign of every zero."""
    return a == b and all(
        math.copysign(1, x) == math.copysign(1, y) for x, y in zip(a, b, strict=True)
    )


@given(edge=edge_st)
def test_an_edge_row_reads_back_as_its_edge(edge: GraphEdge) -> None:
    data = edge_to_pb(OWN, edge).SerializeToString()
    again = edge_from_pb(Edge.FromString(data))
    assert again.source == edge.source
    assert again.target == edge.target
    assert again.kind == edge.kind
    assert again.origin == edge.origin
    assert _same(again.information, edge.information)
    ends = (edge.source,) if edge.kind is EdgeKind.LANDMARK else (edge.source, edge.target)
    assert edge_keys(data) == ends  # a landmark observation's target is no vertex


def test_a_lifted_2d_edge_keeps_three_values_and_names_no_mission() -> None:
    information = lift_information((400.0, 0.0, 0.0, 400.0, 0.0, 3283.0))
    edge = GraphEdge(
        (OWN, 4264), (OWN, 4265), (0.07, 0.0, 0.0, 0, 0, 0, 1), information, EdgeKind.ODOMETRY
    )
    row = edge_to_pb(OWN, edge)

    assert list(row.information) == [400.0, 400.0, 3283.0]
    assert len(row.information_at) == 3
    assert row.from_vertex.mission == row.to_vertex.mission == ""
    full = Edge(mission=OWN, kind=row.kind)  # as rows were written before
    full.from_vertex.mission, full.from_vertex.index = edge.source
    full.to_vertex.mission, full.to_vertex.index = edge.target
    full.information.extend(information)
    assert len(row.SerializeToString()) < len(full.SerializeToString()) - 120
    assert edge_from_pb(full).information == edge_from_pb(row).information == information
    assert edge_keys(full.SerializeToString()) == edge_keys(row.SerializeToString())


def test_an_edge_to_another_mission_names_it() -> None:
    edge = GraphEdge(
        (OWN, 1), ("robot-b", 7), (0, 0, 0, 0, 0, 0, 1), (1.0,) * 21, EdgeKind.INTER_ROBOT
    )
    row = edge_to_pb(OWN, edge)
    assert (row.from_vertex.mission, row.to_vertex.mission) == ("", "robot-b")
    assert len(row.information) == 21  # dense: no entry is zero
    assert not row.information_at
