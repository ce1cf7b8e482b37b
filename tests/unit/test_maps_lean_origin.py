"""A g2o line's number formatting in place of its text (mapapi.maps.g2o_records.lean_origin).

A row keeps a record's decimals instead of its text only where they write the
row's values back as exactly that text; whatever the file's formatting (fixed
decimals, shortest repr, exponents, odd spacing, leading zeros), the export of
the lean graph is the file, byte for byte.
"""

from __future__ import annotations

import io
import random

from hypothesis import given, settings
from hypothesis import strategies as st

from mapapi.maps import parse_g2o, write_g2o
from mapapi.maps.g2o_records import lean_edge, lean_vertex
from mapapi.maps.graph import NO_ORIGIN

STYLES = ("fixed", "fixed", "fixed", "repr", "g", "e", "zeros")


def _number(rnd: random.Random, value: float, style: str, decimals: int) -> str:
    if style == "fixed":
        return f"{value:.{decimals}f}"
    if style == "g":
        return f"{value:g}"
    if style == "e":
        return f"{value:e}"
    if style == "zeros":
        return f"{value:0{decimals + 8}.{decimals}f}"
    return repr(value)


def _line(rnd: random.Random, tag: str, ids: list[int], values: list[float]) -> str:
    style = rnd.choice(STYLES)
    words = [tag, *(str(i) for i in ids)]
    words += [_number(rnd, v, style, rnd.randrange(0, 9)) for v in values]
    gap = "  " if rnd.random() < 0.1 else " "
    return gap.join(words) + (" " if rnd.random() < 0.1 else "")


def _graph_text(seed: int, poses: int) -> str:
    rnd = random.Random(seed)
    lines = []
    for i in range(poses):
        x, y, theta = (rnd.uniform(-1e3, 1e3) for _ in range(3))
        lines.append(_line(rnd, "VERTEX_SE2", [i], [x, y, theta % 3.0]))
    for i in range(poses - 1):
        rel = [rnd.uniform(-2, 2), rnd.uniform(-2, 2), rnd.uniform(-1, 1)]
        info = [rnd.choice((0.0, rnd.uniform(1, 1e4))) for _ in range(6)]
        info[0] = info[3] = info[5] = rnd.uniform(1, 1e4)  # a positive diagonal
        lines.append(_line(rnd, "EDGE_SE2", [i, i + 1], rel + info))
    return "\n".join(lines) + "\n"


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32), poses=st.integers(1, 30))
def test_the_lean_graph_exports_as_the_file(seed: int, poses: int) -> None:
    text = _graph_text(seed, poses)
    graph = parse_g2o(io.StringIO(text), "m")
    for index, pose in graph.vertices.items():
        graph.origins[index] = lean_vertex(
            index, pose, graph.origins.get(index, NO_ORIGIN), graph.planar
        )
    graph.edges = [lean_edge(e, graph.planar) for e in graph.edges]

    out = io.StringIO()
    write_g2o(graph, out)
    assert out.getvalue() == text  # each line, as it was
    for origin in [*graph.origins.values(), *(e.origin for e in graph.edges)]:
        assert bool(origin.text) != bool(origin.digits)  # one or the other


def test_a_fixed_point_line_keeps_a_byte_a_number() -> None:
    graph = parse_g2o(io.StringIO("VERTEX_SE2 7 1.500 -0.25 0.000001\n"), "m")
    origin = lean_vertex(7, graph.vertices[7], graph.origins[7], graph.planar)
    assert (origin.line, origin.text, origin.digits) == (1, "", bytes([0, 3, 2, 6]))
