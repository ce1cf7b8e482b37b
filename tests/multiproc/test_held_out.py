"""Issue 5, "done when": a real g2o graph the project never saw (MIT Killian Court,
`tests/data/held_out/`, not in `sample_maps/`) imports on one peer process, and
another that never saw it finds it with `query-bbox --load`: a small box loads the
mission's row and the one spatial tile around it (issue 14 §3), and the mission's
whole box then the rest, after which it holds the same graph: the same counts,
and an export equal to the importer's and to the file.

Every step is a real `mapctl` process talking to real peer daemons on 127.0.0.1.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from mapapi.maps import read_g2o
from tests.unit.test_maps_export import by_index, same_graph

from .conftest import Daemons, mapctl, mapctl_json

pytestmark = pytest.mark.slow

HELD_OUT = Path(__file__).resolve().parents[1] / "data" / "held_out" / "mit_killian_court.g2o"


def vertex_position(path: Path, index: int) -> tuple[float, float]:
    """x, y of `VERTEX_SE2 index` as the file writes it (read without mapapi)."""
    for line in path.read_text().splitlines():
        words = line.split()
        if words[:2] == ["VERTEX_SE2", str(index)]:
            return float(words[2]), float(words[3])
    raise AssertionError(f"no vertex {index} in {path}")


def counts(path: Path) -> tuple[int, int]:
    """Vertices and edges of a g2o file, by its lines (read without mapapi)."""
    kinds = [line.split(maxsplit=1)[0] for line in path.read_text().splitlines() if line]
    return kinds.count("VERTEX_SE2"), kinds.count("EDGE_SE2")


def test_a_held_out_graph_imported_on_one_peer_is_found_and_loaded_whole_by_another(
    daemons: Daemons, tmp_path: Path
) -> None:
    a = daemons.start("a")
    b = daemons.start("b", join=a.join)
    vertices, edges = counts(HELD_OUT)
    assert (vertices, edges) == (808, 827)  # shared/datasets/README.md §4

    imported = mapctl_json(a.repo, "import", str(HELD_OUT), "--mission", "killian")
    assert [(m["name"], m["vertices"], m["edges"]) for m in imported["missions"]] == [
        ("killian", vertices, edges)
    ]
    assert mapctl_json(b.repo, "missions")["missions"] == []  # b has never seen it

    # a 4 m box around a vertex far from the origin (the graph spans ~260 x 335 m)
    x, y = vertex_position(HELD_OUT, 600)
    assert abs(x) + abs(y) > 50
    box = [x - 2, y - 2, -1, x + 2, y + 2, 1]
    found = mapctl_json(b.repo, "query-bbox", *map(str, box), "--load")

    assert {n for r in found["results"] for n in r["missions"]} == {"killian"}
    assert all(r["held"] for r in found["results"])
    tables = ["edges", "frames", "missions", "vertices"]  # frames: empty until `align`
    assert sorted(c["table"] for c in found["loaded"]) == tables
    (mission,) = imported["missions"]
    (tile,) = [
        t for t in mission["tiles"] if t["vertices"] in {c["chunk"] for c in found["loaded"]}
    ]
    assert found["items"] == 1 + tile["vertex_count"] + tile["edge_count"] < 1 + vertices + edges
    (part,) = mapctl_json(b.repo, "missions")["missions"]
    assert (part["vertices"], part["edges"]) == (tile["vertex_count"], tile["edge_count"])

    rest = mapctl_json(b.repo, "query-bbox", *map(str, mission["bbox"]), "--load")
    assert found["items"] + rest["items"] == 1 + vertices + edges
    on_a = mapctl_json(a.repo, "missions")["missions"]
    on_b = mapctl_json(b.repo, "missions")["missions"]
    assert len(on_a) == len(on_b) == 1
    for key in ("name", "vertices", "edges", "bbox", "chunks", "tiles"):
        assert on_b[0][key] == on_a[0][key], key
    assert sorted(h["name"] for h in on_b[0]["holders"]) == ["a", "b"]

    mapctl(a.repo, "export", "killian", "-o", str(tmp_path / "from_a.g2o"))
    mapctl(b.repo, "export", "killian", "-o", str(tmp_path / "from_b.g2o"))
    assert (tmp_path / "from_b.g2o").read_bytes() == (tmp_path / "from_a.g2o").read_bytes()
    # 2D poses go through a quaternion and back: equal to within 1e-12
    same_graph(by_index(read_g2o(HELD_OUT)), by_index(read_g2o(tmp_path / "from_b.g2o")), 1e-12)
