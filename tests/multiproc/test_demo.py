"""`mapctl demo` (issue 5 §5): a swarm of peer processes builds the tunnels map;
the summary's invariants hold, the PNGs are images, and every process the demo
started is gone afterwards, also after Ctrl-C or SIGTERM.

The expected missions come from reading the tunnels set here, not from the summary.
"""

from __future__ import annotations

import json
import queue
import re
import signal
import subprocess
import threading
from pathlib import Path
from typing import Any

import pytest
from PIL import Image

from mapapi.lookup.spatial import BBox
from mapapi.maps import read_kimera
from mapapi.maps.tiles import tile_graph
from mapapi.testing import wait_until
from mapbench.demo import TUNNELS
from mapbench.demo.scenario import QUERY_BOX

from .conftest import MAPCTL

pytestmark = pytest.mark.slow

DEMO_TIMEOUT = 180.0


def _interruptible() -> None:
    """In the demo's child, before it runs: SIGINT as a terminal's Ctrl-C would
    find it. A shell that starts the suite in the background (`make test &`) hands
    every child SIGINT ignored, and Python then keeps it ignored: the demo would
    never see the interrupt this test sends, and run to its end."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def alive(pid: int) -> bool:
    """Whether process `pid` exists (a zombie of this test's children counts as gone)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(") ", 1)[1][0]
    except OSError:  # no such process
        return False
    return state != "Z"


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Any], Path]:
    """One `mapctl demo --json` run: its summary and its --out folder."""
    out = tmp_path_factory.mktemp("demo") / "out"
    done = subprocess.run(
        [MAPCTL, "demo", "--json", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=DEMO_TIMEOUT,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout), out


def test_three_or_four_peers_built_one_map(demo: tuple[dict[str, Any], Path]) -> None:
    summary, _ = demo
    peers = summary["peers"]
    assert 3 <= len(peers) <= 4
    assert len({p["pid"] for p in peers}) == len({p["id"] for p in peers}) == len(peers)
    expected = {g.name: g for g in read_kimera(TUNNELS, "tunnels-")}
    imported = {m["name"]: m for m in summary["missions"]}
    assert imported.keys() == expected.keys()
    for name, graph in expected.items():
        assert (imported[name]["vertices"], imported[name]["edges"]) == (
            len(graph.vertices),
            len(graph.edges),
        )
    assert all(p["imported"] for p in peers)  # every peer imported some robots
    by_peer = [name for p in peers for name in p["imported"]]
    assert sorted(by_peer) == sorted(expected)  # each mission once


def test_the_querying_peer_holds_what_lies_in_the_box_after_the_load(
    demo: tuple[dict[str, Any], Path],
) -> None:
    summary, _ = demo
    query = summary["query"]
    expected = {g.name: g for g in read_kimera(TUNNELS, "tunnels-")}
    assert query["peer"] == summary["peers"][-1]["name"]
    assert sorted(query["found"]) == sorted(expected)
    held = {m["name"]: m for m in query["missions"]}
    assert held.keys() == expected.keys()
    importer = {m["name"]: m["peer"] for m in summary["missions"]}
    box = BBox.from_tuple(QUERY_BOX)
    chunks = 0
    for name, graph in expected.items():
        tiles = tile_graph(graph)
        if importer[name] != query["peer"]:  # the tiles in the box, each its vertices and edges
            tiles = [t for t in tiles if t.bbox.overlaps(box)]
            chunks += 2 + sum(1 + bool(t.edges) for t in tiles)  # and its row's and frames' chunks
        assert (held[name]["vertices"], held[name]["edges"]) == (
            sum(len(t.vertices) for t in tiles),
            sum(len(t.edges) for t in tiles),
        )
        assert {query["peer"], importer[name]} == set(held[name]["holders"])
    assert query["complete"] is True
    assert query["loaded_chunks"] == chunks
    assert query["bytes_received"] > 0


def test_the_conflict_was_detected_and_both_editors_see_the_resolution(
    demo: tuple[dict[str, Any], Path],
) -> None:
    summary, _ = demo
    clash = summary["conflict"]
    first, second = clash["peers"]
    assert first != second
    assert clash["detected"] is True
    assert "conflicting" in clash["message"]
    assert clash["first"] != clash["second"] != clash["base"]
    mean = [(a + b) / 2 for a, b in zip(clash["first"], clash["second"], strict=True)]
    assert clash["resolved"] == pytest.approx(mean)
    assert clash["seen"] == {first: clash["resolved"], second: clash["resolved"]}
    assert clash["agree"] is True


def test_the_totals_add_up(demo: tuple[dict[str, Any], Path]) -> None:
    summary, _ = demo
    peers = summary["peers"]
    assert summary["bytes_moved"] == sum(p["sent"]["bytes"] for p in peers) > 0
    assert summary["chunks"] >= 3 * len(summary["missions"])
    assert summary["commits"] >= len(summary["missions"]) + 2  # imports and two edits
    steps = ["start", "import", "query", "conflict", "align", "plot", "stop", "total"]
    assert list(summary["timings"]) == steps
    assert summary["timings"]["total"] >= sum(summary["timings"][s] for s in steps[:-1])


def test_one_peer_aligned_every_mission_and_every_peers_watch_received_the_places(
    demo: tuple[dict[str, Any], Path],
) -> None:
    summary, _ = demo
    align = summary["align"]
    names = sorted(m["name"] for m in summary["missions"])
    assert align["peer"] == summary["peers"][-1]["name"]
    assert align["missions"] == names  # every robot joined to the anchor
    assert align["anchor"] in names
    assert 0 < align["inliers"] < align["edges"]  # the set's wrong matches weighed out
    assert align["rms_after"]["metres"] < align["rms_before"]["metres"]
    assert sorted(align["seen"]) == sorted(p["name"] for p in summary["peers"])


def test_the_pngs_are_images(demo: tuple[dict[str, Any], Path]) -> None:
    summary, out = demo
    assert summary["out"] == str(out.resolve())
    assert sorted(summary["pngs"]) == ["map", "query"]
    for path in map(Path, summary["pngs"].values()):
        assert path.parent == out.resolve()
        with Image.open(path) as image:
            assert image.format == "PNG"
            assert image.width > 100
            assert image.height > 100
            image.verify()


def test_every_process_is_gone_and_the_swarm_folder_removed(
    demo: tuple[dict[str, Any], Path],
) -> None:
    summary, _ = demo
    assert not Path(summary["swarm"]).exists()
    for peer in summary["peers"]:
        wait_until(lambda pid=peer["pid"]: not alive(pid), timeout=10.0)


def test_a_folder_that_is_a_file_is_refused_before_anything_starts(tmp_path: Path) -> None:
    taken = tmp_path / "taken"
    taken.write_text("")
    done = subprocess.run(
        [MAPCTL, "demo", "--out", str(taken)], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 2
    assert "is a file" in done.stderr
    assert "swarm runs in" not in done.stderr


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_demo_stops_every_peer_it_started(tmp_path: Path, signum: int) -> None:
    lines: queue.Queue[str | None] = queue.Queue()
    swarm, pids, rest = None, [], []
    with subprocess.Popen(
        [MAPCTL, "demo", "--out", str(tmp_path / "out")],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_interruptible,
    ) as demo:

        def read() -> None:
            assert demo.stderr is not None
            for line in demo.stderr:
                lines.put(line)
            lines.put(None)

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        try:
            while len(pids) < 2:  # interrupt once two peers serve, while the others start
                line = lines.get(timeout=DEMO_TIMEOUT)
                assert line is not None, "the demo ended before two peers served"
                if found := re.search(r"the swarm runs in (\S+)", line):
                    swarm = Path(found[1])
                if found := re.search(r"serves \S+ \(pid (\d+)\)", line):
                    pids.append(int(found[1]))
            demo.send_signal(signum)
            assert demo.wait(timeout=DEMO_TIMEOUT) == 130
        finally:
            if demo.poll() is None:
                demo.kill()
        reader.join(timeout=10)
    while (line := lines.get(timeout=10)) is not None:
        rest.append(line)
    pids += [int(p) for line in rest for p in re.findall(r"serves \S+ \(pid (\d+)\)", line)]
    assert swarm is not None
    assert any("stopped" in line for line in rest)
    for pid in pids:
        wait_until(lambda pid=pid: not alive(pid), timeout=10.0)
    # also a peer whose start the signal cut short, which never said its pid: the
    # demo saw it let go of its lock, and it may take a moment more to exit
    wait_until(lambda: running_in(swarm) == [], timeout=10.0)
    assert not swarm.exists()


def running_in(folder: Path) -> list[int]:
    """The live processes whose command line names `folder` (Linux /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue  # it ended meanwhile
        if str(folder) in command and alive(int(entry.name)):
            found.append(int(entry.name))
    return found
