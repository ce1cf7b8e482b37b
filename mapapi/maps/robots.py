"""Multi-robot sets: one mission per robot, each inter-robot edge kept once.

Shared by the readers of sets that list one robot's measurements per file, the
Kimera-Multi CSV (`mapapi.maps.kimera`) and the DGS per-robot g2o files
(`mapapi.maps.dgs`). In both, an edge between two robots appears in both robots'
files: it is kept once, the first read wins (its copies differ at most in a
weight), and it is owned by its source robot's mission, naming a vertex of the
other. An edge within one robot is odometry when it goes from `i` to `i + 1`,
else a loop. Vertices that edges name but no record places are chained from the
robot's odometry (`graph.chain_odometry`).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

from mapapi.maps.graph import EdgeKind, GraphEdge, MissionGraph, Origin, chain_odometry
from mapapi.maps.se3 import Pose

R = TypeVar("R", bound=Hashable)  # how the set names a robot: a number, a letter


class RobotMissions(Generic[R]):
    """The missions of a multi-robot set while its files are read.

    Args:
        naming: robot -> (mission name, robot name).
    """

    def __init__(self, naming: Callable[[R], tuple[str, str]]) -> None:
        self._naming = naming
        self._graphs: dict[R, MissionGraph] = {}
        self._wanted: dict[R, set[int]] = {}
        self._seen: set[Hashable] = set()

    def graph(self, robot: R) -> MissionGraph:
        """The mission of `robot`, made on first use."""
        graph = self._graphs.get(robot)
        if graph is None:
            name, robot_name = self._naming(robot)
            graph = self._graphs[robot] = MissionGraph(name, robot_name, f"{name}/odom")
            self._wanted[robot] = set()
        return graph

    def robots(self) -> list[R]:
        """Every robot met so far, in the order first met."""
        return list(self._graphs)

    def add_vertex(self, robot: R, index: int, pose: Pose, origin: Origin) -> bool:
        """Place a vertex; False (and nothing changes) when it is placed already."""
        graph = self.graph(robot)
        if index in graph.vertices:
            return False
        graph.vertices[index] = pose
        graph.origins[index] = origin
        return True

    def add_edge(
        self,
        key: Hashable,
        source: tuple[R, int],
        target: tuple[R, int],
        relative: Pose,
        information: tuple[float, ...],
        origin: Origin,
    ) -> bool:
        """Add the edge `source -> target` (robot, index) to its source robot's
        mission, unless an edge of the same `key` was added already (False)."""
        if key in self._seen:
            return False
        self._seen.add(key)
        (a, i), (b, j) = source, target
        if a == b:
            kind = EdgeKind.ODOMETRY if j == i + 1 else EdgeKind.LOOP
        else:
            kind = EdgeKind.INTER_ROBOT
        owner, other = self.graph(a), self.graph(b)
        self._wanted[a].add(i)
        self._wanted[b].add(j)
        owner.edges.append(
            GraphEdge((owner.name, i), (other.name, j), relative, information, kind, origin)
        )
        return True

    def graphs(self, robots: list[R] | None = None) -> list[MissionGraph]:
        """The missions of `robots` (default: all, by robot), their vertices by
        index, those no record placed chained from the odometry."""
        chosen = sorted(self._graphs) if robots is None else robots  # type: ignore[type-var]
        out = []
        for robot in chosen:
            graph = self._graphs[robot]
            chain_odometry(graph, self._wanted[robot])
            graph.vertices = dict(sorted(graph.vertices.items()))
            out.append(graph)
        return out
