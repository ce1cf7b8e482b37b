"""Spatial tiles (issue 14 §3): every vertex and edge in exactly one tile, tiles
bounded in size and extent, and a box's tiles hold every edge among its vertices."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mapapi.lookup.spatial import BBox
from mapapi.maps import read_g2o
from mapapi.maps.graph import EdgeKind, GraphEdge, MissionGraph
from mapapi.maps.se3 import IDENTITY
from mapapi.maps.tiles import Tile, tile_graph

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"

coordinate = st.floats(-200, 200, allow_nan=False, allow_infinity=False)


@st.composite
def graphs(draw: st.DrawFn) -> MissionGraph:
    """A mission of up to 300 vertices, some at one spot, with edges between
    random vertices and a few to another mission's vertices."""
    count = draw(st.integers(1, 300))
    spot = (draw(coordinate), draw(coordinate), 0.0)
    graph = MissionGraph("m", "r", "m/map")
    for index in range(count):
        here = spot if draw(st.booleans()) else (draw(coordinate), draw(coordinate), 0.0)
        graph.vertices[index * 3] = (*here, *IDENTITY[3:])
    keys = sorted(graph.vertices)
    pairs = st.tuples(st.sampled_from(keys), st.sampled_from(keys), st.booleans())
    for source, target, foreign in draw(st.lists(pairs, max_size=400)):
        start = ("other", source) if foreign else ("m", source)
        graph.edges.append(GraphEdge(start, ("m", target), IDENTITY, (0.0,) * 21, EdgeKind.LOOP))
    return graph


def where(tiles: list[Tile]) -> dict[int, Tile]:
    return {index: tile for tile in tiles for index in tile.vertices}


@settings(max_examples=150, deadline=None)
@given(
    graph=graphs(), most=st.integers(1, 64), extent=st.floats(0.5, 100), least=st.integers(0, 32)
)
def test_tiles_cover_the_graph_once_within_their_bounds(
    graph: MissionGraph, most: int, extent: float, least: int
) -> None:
    tiles = tile_graph(graph, most, extent, least)

    assert sorted(i for t in tiles for i in t.vertices) == sorted(graph.vertices)
    assert sorted(n for t in tiles for n in t.edges) == list(range(len(graph.edges)))
    for tile in tiles:
        assert 1 <= len(tile.vertices) <= most
        points = [graph.vertices[i][:3] for i in tile.vertices]
        assert tile.bbox == BBox.enclosing(BBox(*p, *p) for p in points)
        if len(tile.vertices) > least:
            assert max(tile.bbox.maxs[a] - tile.bbox.mins[a] for a in range(3)) <= extent
    tile_of = where(tiles)
    for tile in tiles:
        for n in tile.edges:  # the rule: the source's tile when it is ours, else the target's
            edge = graph.edges[n]
            end = edge.source if edge.source[0] == "m" else edge.target
            assert tile_of[end[1]] is tile
    assert tile_graph(graph, most, extent, least) == tiles  # the same graph, the same tiles


@settings(max_examples=100, deadline=None)
@given(graph=graphs(), corner=st.tuples(coordinate, coordinate), size=st.floats(0, 150))
def test_the_tiles_a_box_overlaps_hold_every_edge_among_its_vertices(
    graph: MissionGraph, corner: tuple[float, float], size: float
) -> None:
    tiles = tile_graph(graph, max_vertices=8, max_extent=20.0, min_vertices=2)
    box = BBox(corner[0], corner[1], -1.0, corner[0] + size, corner[1] + size, 1.0)
    loaded = [t for t in tiles if t.bbox.overlaps(box)]
    edges = {n for t in loaded for n in t.edges}
    vertices = {i for t in loaded for i in t.vertices}

    def inside(index: int) -> bool:
        x, y, z = graph.vertices[index][:3]
        return box.overlaps(BBox(x, y, z, x, y, z))

    assert {i for i in graph.vertices if inside(i)} <= vertices
    for n, edge in enumerate(graph.edges):
        ours = [end[1] for end in (edge.source, edge.target) if end[0] == "m"]
        if all(inside(i) for i in ours):
            assert n in edges


def test_a_dense_graph_is_cut_by_count_and_a_long_path_by_extent() -> None:
    intel = tile_graph(read_g2o(SAMPLES / "pose_graphs" / "intel.g2o"))  # 1,728 poses in 26 m
    assert [len(t.vertices) for t in intel] == [432] * 4  # by count: at most TILE_VERTICES
    dense = MissionGraph("dense", "r", "dense/map")
    for index in range(5_000):  # 5,000 poses in 20 m
        dense.vertices[index] = (index % 100 * 0.2, index // 100 * 0.4, 0.0, *IDENTITY[3:])
    assert [len(t.vertices) for t in tile_graph(dense)] == [625] * 8

    def path(poses: int, step: float) -> list[float]:
        graph = MissionGraph("path", "r", "path/map")
        for index in range(poses):
            graph.vertices[index] = (index * step, 0.0, 0.0, *IDENTITY[3:])
        return [t.bbox.xmax - t.bbox.xmin for t in tile_graph(graph)]

    assert path(2_000, 0.25) == [62.25] * 8  # by count, then by extent: 250 poses in 62 m
    assert path(600, 0.5) == [74.5] * 4  # 150 poses each: not cut below TILE_MIN_VERTICES
    assert path(150, 1.0) == [149.0]  # too few poses to cut for extent


def test_a_graph_without_vertices_has_no_tiles() -> None:
    assert tile_graph(MissionGraph("m", "r", "f")) == []


def test_bounds_that_cannot_hold_a_vertex_are_refused() -> None:
    with pytest.raises(ValueError, match="max_vertices"):
        tile_graph(MissionGraph("m", "r", "f"), max_vertices=0)
    with pytest.raises(ValueError, match="max_extent"):
        tile_graph(MissionGraph("m", "r", "f"), max_extent=0.0)
