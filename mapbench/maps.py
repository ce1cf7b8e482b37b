"""`mapctl bench import`: how fast real maps import (issue 5: >= 50k graph
elements per second), phase by phase.

Each run reads a sample map (parse), then imports it into a fresh repository:
build the rows and stage them, then commit (one commit per mission). The
figures are graph elements (vertices + edges) per second for the parse alone,
for parse + stage (everything before the store writes) and end to end. A run
on the in-memory store leaves SQLite out. Nothing here asserts a speed; the
figures go to docs/benchmarks.md.
"""

from __future__ import annotations

import asyncio
import statistics
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from mapapi.app import memory_peer, peer_of
from mapapi.core.errors import UsageError
from mapapi.maps.importer import MapSource, import_missions
from mapapi.maps.source import read_source
from mapapi.service.peer import Peer
from mapapi.service.repo import Repository
from mapbench.lookup import environment

SAMPLES = Path(__file__).resolve().parents[1] / "sample_maps"
"""The source tree's sample maps (`sample_maps/README.md`)."""

DATASETS = {
    "intel": "pose_graphs/intel.g2o",
    "parking-garage": "pose_graphs/parking-garage.g2o",
    "tunnels": "kimera_multi_tunnels_8robots",
    "victoria-park": "landmarks/victoria_park.txt",
    "dgs-blocks": "dgs_blocks_world_4robots_SIMULATED",
}
"""The graph data sets `measure_import` knows: name -> path under `SAMPLES`."""

STORES = ("sqlite", "memory")


def measure_import(
    dataset: str,
    *,
    runs: int = 3,
    store: str = "sqlite",
    samples: Path = SAMPLES,
    directory: str | Path | None = None,
    path: Path | None = None,
) -> dict[str, Any]:
    """Import `dataset` (or the map file `path`, named `dataset`) `runs` times,
    each into a fresh repository; the median of each phase.

    Returns:
        JSON-ready figures: dataset, store, missions, elements, points (of clouds
        and laser scans), runs, the median seconds of `parse_s`, `stage_s` (rows
        built and staged) and `commit_s`, and the rates `parse_per_s`,
        `parse_stage_per_s` and `end_to_end_per_s` (elements per second), plus
        the machine.

    Raises:
        UsageError: an unknown data set or store, or no runs.
    """
    if path is None and dataset not in DATASETS:
        raise UsageError(f"unknown data set {dataset!r}; choose from {', '.join(DATASETS)}")
    if store not in STORES:
        raise UsageError(f"unknown store {store!r}; choose from {', '.join(STORES)}")
    if runs < 1:
        raise UsageError(f"runs must be at least 1, not {runs}")
    machine = environment()
    source = path or samples / DATASETS[dataset]
    phases = [_one_run(source, store, directory) for _ in range(runs)]
    parse, stage, commit = (statistics.median(p[k] for p in phases) for k in range(3))
    elements = int(phases[0][3])
    return {
        "dataset": dataset,
        "store": store,
        "missions": int(phases[0][4]),
        "elements": elements,
        "points": int(phases[0][5]),
        "runs": runs,
        "parse_s": round(parse, 4),
        "stage_s": round(stage, 4),
        "commit_s": round(commit, 4),
        "parse_per_s": round(elements / parse),
        "parse_stage_per_s": round(elements / (parse + stage)),
        "end_to_end_per_s": round(elements / (parse + stage + commit)),
        **machine,
    }


def _one_run(
    path: Path, store: str, directory: str | Path | None
) -> tuple[float, float, float, int, int, int]:
    """(parse s, stage s, commit s, elements, missions, points) of one import."""
    start = time.perf_counter()
    sources = read_source(path)
    parse = time.perf_counter() - start
    if store == "memory":
        return (parse, *asyncio.run(_import(memory_peer(), sources)))
    with tempfile.TemporaryDirectory(prefix="mapapi-bench-", dir=directory) as tmp:
        repo = Repository.init(Path(tmp) / "repo", "bench")
        return (parse, *asyncio.run(_import(peer_of(repo), sources)))


async def _import(peer: Peer, sources: Sequence[MapSource]) -> tuple[float, float, int, int, int]:
    """(seconds before the commits, seconds in them, elements, missions, points)
    of importing `sources`."""
    try:
        start = time.perf_counter()
        results = await import_missions(peer, sources)
        total = time.perf_counter() - start
    finally:
        await peer.close()
    commit = sum(r.commit_seconds for r in results)
    elements, points = sum(r.elements() for r in results), sum(r.points for r in results)
    return total - commit, commit, elements, len(results), points
