"""Import, export and import again (mapapi.maps.operations, source): g2o round
trips through a peer, including a held-out synthetic graph, and the checks that
keep a set of missions from being half imported."""

from __future__ import annotations

import io
import math
import random
import subprocess
import sys
from pathlib import Path

import pytest

from mapapi import Peer
from mapapi.app import memory_peer, operations
from mapapi.core.errors import UsageError
from mapapi.maps import (
    EdgeKind,
    GraphEdge,
    MapImportError,
    MissionGraph,
    import_graph,
    import_missions,
    load_graph,
    read_g2o,
    read_kimera,
    write_g2o,
)
from mapapi.maps.operations import MapOperations
from mapapi.maps.se3 import Pose
from mapapi.maps.source import detect_format, read_source

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
INTEL = SAMPLES / "pose_graphs" / "intel.g2o"
GARAGE = SAMPLES / "pose_graphs" / "parking-garage.g2o"
TUNNELS = SAMPLES / "kimera_multi_tunnels_8robots"


def random_pose(rng: random.Random, scale: float = 50.0) -> Pose:
    q = [rng.gauss(0, 1) for _ in range(4)]
    norm = math.sqrt(sum(v * v for v in q))
    x, y, z, w = (v / norm for v in q)
    return (rng.uniform(-scale, scale), rng.uniform(-scale, scale), rng.uniform(-5, 5), x, y, z, w)


def synthetic_graph(seed: int, poses: int = 400, loops: int = 150) -> MissionGraph:
    """A 3D pose graph no file in the repository holds: random poses, odometry
    between neighbours, random loop closures, random information matrices."""
    rng = random.Random(seed)
    graph = MissionGraph("held-out", frame="held-out/map")
    graph.vertices = {i: random_pose(rng) for i in range(poses)}
    pairs = [(i, i + 1) for i in range(poses - 1)]
    while len(pairs) < poses - 1 + loops:
        i, j = rng.randrange(poses), rng.randrange(poses)
        if j != i + 1:  # a second edge i -> i+1 would be a second odometry edge
            pairs.append((i, j))
    for i, j in pairs:
        kind = EdgeKind.ODOMETRY if j == i + 1 else EdgeKind.LOOP
        information = tuple(rng.uniform(0, 100) for _ in range(21))
        relative = random_pose(rng, 2.0)
        graph.edges.append(GraphEdge(("held-out", i), ("held-out", j), relative, information, kind))
    return graph


def same_graph(a: MissionGraph, b: MissionGraph, tol: float = 0.0) -> None:
    assert a.vertices.keys() == b.vertices.keys()
    for index, pose in a.vertices.items():
        assert b.vertices[index] == pytest.approx(pose, abs=tol)
    assert [(e.source[1], e.target[1], e.kind) for e in a.edges] == [
        (e.source[1], e.target[1], e.kind) for e in b.edges
    ]
    for ours, theirs in zip(a.edges, b.edges, strict=True):
        assert ours.relative == pytest.approx(theirs.relative, abs=tol)
        assert ours.information == pytest.approx(theirs.information, abs=tol)


def by_index(graph: MissionGraph) -> MissionGraph:
    """The graph with its edges in (source, target) order, as a store returns no order."""
    graph.edges.sort(key=lambda e: (e.source[1], e.target[1], e.relative))
    return graph


@pytest.fixture
def ops() -> MapOperations:
    return MapOperations(memory_peer())


class TestG2oRoundTrip:
    async def test_intel_exports_as_2d_and_reads_back_equal_to_rounding(
        self, ops: MapOperations, tmp_path: Path
    ) -> None:
        await ops.imports.import_map(str(INTEL))
        out = tmp_path / "intel.g2o"

        info = await ops.export_map("intel", str(out))

        assert info == {
            "frame": "mission",
            "mission": "intel",
            "path": str(out),
            "format": "g2o",
            "vertices": 1_728,
            "landmarks": 0,
            "edges": 2_512,
            "left_out": 0,
        }
        assert out.read_text().startswith("VERTEX_SE2 0 ")
        same_graph(by_index(read_g2o(INTEL)), by_index(read_g2o(out)), tol=1e-12)

    async def test_a_3d_graph_comes_back_bit_for_bit(
        self, ops: MapOperations, tmp_path: Path
    ) -> None:
        await ops.imports.import_map(str(GARAGE))
        await ops.export_map("parking-garage", str(tmp_path / "garage.g2o"))
        await ops.imports.import_map(str(tmp_path / "garage.g2o"), mission="again")

        first = await load_graph(ops.peer, "parking-garage")
        again = await load_graph(ops.peer, "again")
        same_graph(by_index(read_g2o(GARAGE)), by_index(first))
        assert again.vertices == first.vertices
        assert sorted(
            (e.source[1], e.target[1], e.relative, e.information) for e in again.edges
        ) == (sorted((e.source[1], e.target[1], e.relative, e.information) for e in first.edges))

    async def test_a_held_out_synthetic_graph_survives_import_export_import(
        self, ops: MapOperations, tmp_path: Path
    ) -> None:
        graph = synthetic_graph(seed=20_240_611)
        source = tmp_path / "held-out.g2o"
        with source.open("w") as out:
            write_g2o(graph, out)

        await ops.imports.import_map(str(source))
        await ops.export_map("held-out", str(tmp_path / "exported.g2o"))
        result = await ops.imports.import_map(str(tmp_path / "exported.g2o"), mission="reimported")

        assert result["missions"][0]["vertices"] == 400
        assert result["missions"][0]["edges"] == 549
        back = await load_graph(ops.peer, "reimported")
        same_graph(by_index(graph), by_index(back))

    async def test_inter_robot_edges_are_left_out_of_a_one_mission_file(
        self, ops: MapOperations, tmp_path: Path
    ) -> None:
        await ops.imports.import_map(str(TUNNELS))
        robot2 = next(g for g in read_kimera(TUNNELS) if g.name == "robot2")
        inter = robot2.count(EdgeKind.INTER_ROBOT)

        info = await ops.export_map("robot2", str(tmp_path / "robot2.g2o"))

        assert inter > 0
        assert (info["edges"], info["left_out"]) == (len(robot2.edges) - inter, inter)
        assert len(read_g2o(tmp_path / "robot2.g2o").edges) == info["edges"]

    async def test_export_errors_say_what_to_do(self, ops: MapOperations, tmp_path: Path) -> None:
        await ops.imports.import_map(str(INTEL))
        with pytest.raises(MapImportError, match=r"no mission 'nope'.*mapctl missions"):
            await ops.export_map("nope", str(tmp_path / "x.g2o"))
        with pytest.raises(UsageError, match="no point cloud"):
            await ops.export_map("intel", str(tmp_path / "x.ply"))
        with pytest.raises(
            UsageError, match=r"pass --format \(g2o\|tum\|kitti\|ply\|pcd\|bag\|grid\)"
        ):
            await ops.export_map("intel", str(tmp_path / "x.csv"))


class TestNothingOfASetHalfImported:
    async def test_a_name_taken_already_stops_the_whole_set(self) -> None:
        peer = Peer.in_memory()
        await import_graph(peer, read_g2o(INTEL, mission="robot5"))
        with pytest.raises(MapImportError, match="'robot5' exists already"):
            await import_missions(peer, read_kimera(TUNNELS))
        assert len(peer.log()) == 1

    async def test_a_bad_last_mission_stops_the_whole_set(self) -> None:
        peer = Peer.in_memory()
        bad = MissionGraph("bad", vertices={0: (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)})
        bad.edges.append(
            GraphEdge(("bad", 0), ("bad", 9), bad.vertices[0], (0.0,) * 21, EdgeKind.LOOP)
        )
        with pytest.raises(MapImportError, match="missing vertex 9"):
            await import_missions(peer, [*read_kimera(TUNNELS), bad])
        assert peer.log() == []
        assert peer.chunks() == []

    async def test_a_name_twice_in_one_set_stops_it(self) -> None:
        peer = Peer.in_memory()
        with pytest.raises(MapImportError, match="'intel' exists already"):
            await import_missions(peer, [read_g2o(INTEL), read_g2o(INTEL)])
        assert peer.log() == []

    async def test_a_malformed_file_commits_nothing(
        self, ops: MapOperations, tmp_path: Path
    ) -> None:
        lines = INTEL.read_text().splitlines(keepends=True)
        lines[3000] = "EDGE_SE2 1 2 3\n"
        broken = tmp_path / "broken.g2o"
        broken.write_text("".join(lines))
        with pytest.raises(MapImportError, match=r"broken\.g2o:3001: EDGE_SE2 needs 11"):
            await ops.imports.import_map(str(broken))
        assert ops.peer.log() == []
        assert ops.peer.chunks() == []


class TestSources:
    @pytest.mark.parametrize(
        ("path", "fmt"),
        [
            (INTEL, "g2o"),
            (TUNNELS, "kimera-csv"),
            (TUNNELS / "robot0" / "measurements.csv", "kimera-csv"),
        ],
    )
    def test_the_format_follows_from_the_extension(self, path: Path, fmt: str) -> None:
        assert detect_format(path) == fmt

    def test_an_unknown_extension_asks_for_the_format(self, tmp_path: Path) -> None:
        with pytest.raises(UsageError, match="pass --format"):
            detect_format(tmp_path / "map.txt")

    def test_one_robots_csv_is_that_robots_mission_only(self) -> None:
        (graph,) = read_source(TUNNELS / "robot3" / "measurements.csv", mission="t-")
        assert (graph.name, graph.robot) == ("t-robot3", "robot3")
        whole = next(g for g in read_kimera(TUNNELS, "t-") if g.name == "t-robot3")
        assert graph.vertices == whole.vertices

    def test_options_that_do_not_fit_the_format_are_refused(self) -> None:
        with pytest.raises(UsageError, match="--voxel applies to point clouds"):
            read_source(INTEL, voxel=0.1)
        with pytest.raises(UsageError, match="holds 8 robots' missions; drop --robot"):
            read_source(TUNNELS, robot="jackal")
        with pytest.raises(UsageError, match="no file or folder"):
            read_source(SAMPLES / "missing.g2o")

    def test_a_file_read_as_another_format_names_its_first_line(self) -> None:
        with pytest.raises(MapImportError, match=r"intel\.g2o:1: expected the header"):
            read_source(INTEL, "kimera-csv")

    async def test_reading_and_staging_report_progress(self, ops: MapOperations) -> None:
        read: list[tuple[int, int]] = []
        staged: list[tuple[int, int]] = []
        graphs = read_source(GARAGE, progress=lambda d, t: read.append((d, t)))
        await import_missions(ops.peer, graphs, lambda d, t: staged.append((d, t)))

        lines = len(GARAGE.read_text().splitlines())
        assert read[-1] == (lines, lines)  # every 10,000 lines (total unknown), then the end
        rows = 1 + 1_661 + 6_275
        # one step per chunk staged: the mission row, then each tile's vertices and edges
        assert staged[0] == (1, rows)
        assert staged[-1] == (rows, rows)
        assert [d for d, _ in staged] == sorted({d for d, _ in staged})
        assert await ops.imports.import_progress("/no/import") == {
            "path": "/no/import",
            "done": 0,
            "total": 0,
        }

    def test_every_map_operation_is_an_operation(self) -> None:
        assert {"import_map", "import_progress", "export_map", "missions", "plot_map"} <= set(
            operations(memory_peer()).table
        )

    def test_commands_load_the_operations_without_numpy(self) -> None:
        # every mapctl command imports mapapi (the operations with it); numpy would add ~40 ms
        code = "import sys, mapapi; print({'numpy', 'open3d'} & set(sys.modules))"
        ran = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True
        )
        assert ran.stdout.strip() == "set()"

    def test_write_g2o_of_a_2d_graph_stays_2d(self) -> None:
        out = io.StringIO()
        write_g2o(read_g2o(INTEL), out)
        assert out.getvalue().startswith("VERTEX_SE2")
