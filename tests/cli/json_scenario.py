"""Runs every `mapctl` command that has `--json` once, on real repositories and
real peer daemons, and keeps what each printed (for tests/cli/test_json_shapes.py).

Commands run in-process (click's `CliRunner`, through the daemon's control
endpoint once one runs); the daemons are real `mapctl peer start --detach`
processes, and `watch` a real process, since it blocks until a change arrives.
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from click.testing import CliRunner

from mapctl.cli import cli
from tests.cli.conftest import run_main
from tests.multiproc.conftest import COMMAND_TIMEOUT, MAPCTL, Daemons

ROOT = Path(__file__).resolve().parents[2]
INTEL = ROOT / "sample_maps" / "pose_graphs" / "intel.g2o"
LASER_LOG = ROOT / "sample_maps" / "laser_logs" / "intel-head.clf.bz2"
STRUCT = "google.protobuf.Struct"
COUNTER = "mapapi.v1.Counter"

Command = tuple[str, ...]
"""A command's path in the click tree, e.g. ("chunk", "list")."""


@dataclass
class Outputs:
    """What each command printed with `--json`: its path -> every stdout, in order."""

    seen: dict[Command, list[str]] = field(default_factory=dict)
    runner: CliRunner = field(default_factory=CliRunner)

    def run(
        self, path: Command, *args: str, repo: Path | None = None, view: str | None = None
    ) -> Any:
        """Run `mapctl [-C repo] [--view view] PATH ARGS --json`, which must
        succeed; keep and return its parsed stdout."""
        where = [*(["-C", str(repo)] if repo else []), *(["--view", view] if view else [])]
        argv = [*where, *path, *args, "--json"]
        result = self.runner.invoke(cli, argv)
        assert result.exit_code == 0, (
            f"mapctl {' '.join(argv)} exited {result.exit_code}: {result.exception!r}\n"
            f"{result.output}"
        )
        return self.keep(path, result.stdout)

    def keep(self, path: Command, stdout: str) -> Any:
        """Record `stdout` of one run of `path`; its first JSON document."""
        self.seen.setdefault(path, []).append(stdout)
        return json.loads(stdout.splitlines()[0])


def run_offline(out: Outputs, root: Path) -> Path:
    """Every command that works on a repository with no running peer; returns
    the repository (tables pts and counters, a commit, an imported mission)."""
    repo = root / "a"
    out.run(("init",), str(repo), "--name", "robot-a")
    out.run(("table", "create"), "pts", "--type", STRUCT, repo=repo)
    out.run(("table", "create"), "counters", "--type", COUNTER, repo=repo)
    out.run(("chunk", "create"), "pts", repo=repo)
    out.run(("chunk", "create"), "counters", repo=repo)
    point = out.run(("set",), "pts", json.dumps({"bbox": [0, 0, 0, 1, 1, 1]}), repo=repo)
    counter = out.run(("set",), "counters", '{"name": "doors", "value": 2}', repo=repo)
    out.run(("status",), repo=repo)
    out.run(("diff",), repo=repo)
    record = out.run(("commit",), "-m", "a point and a counter", repo=repo)
    out.run(("get",), "counters", counter["id"], repo=repo)
    out.run(("ls",), "pts", repo=repo)
    out.run(("log",), repo=repo)
    out.run(("log",), "counters", counter["id"], repo=repo)
    out.run(("show",), record["commit"], repo=repo)
    out.run(("fsck",), repo=repo)
    out.run(("gc",), "--keep", "1", repo=repo)
    out.run(("table", "list"), repo=repo)
    out.run(("chunk", "list"), repo=repo)
    _conflict(out, repo, point["id"])
    _maps(out, repo, root)
    out.run(("query-bbox",), "-1", "-1", "-1", "2", "2", "2", repo=repo)
    out.run(("peer", "status"), repo=repo)  # {"running": false}
    out.run(("peer", "stop"), repo=repo)  # {"stopped": false, ...}
    return repo


def _conflict(out: Outputs, repo: Path, item: str) -> None:
    """Two views race on one item: the loser's commit (exit 3) and `resolve`."""
    out.run(("view", "open"), repo=repo, view="w")  # a view of its own: main reads the newest
    for view, x in (("x", 2), ("y", 3)):
        argv = ["-C", str(repo), "--view", view, "set", "pts", item, json.dumps({"x": x})]
        assert out.runner.invoke(cli, argv).exit_code == 0
    out.run(("view", "list"), repo=repo)
    assert out.runner.invoke(cli, ["-C", str(repo), "--view", "x", "commit"]).exit_code == 0
    lost = run_main(["-C", str(repo), "--view", "y", "commit", "--json"])  # the exit code too
    assert lost.code == 3, lost
    out.keep(("commit",), lost.out)
    resolve = ["-C", str(repo), "--view", "y", "resolve", "--theirs", "--json"]
    resolved = out.runner.invoke(cli, resolve)
    assert resolved.exit_code == 0, resolved.output
    out.keep(("resolve",), resolved.stdout)


def _maps(out: Outputs, repo: Path, root: Path) -> None:
    out.run(("import",), str(INTEL), "--mission", "intel", repo=repo)
    out.run(("missions",), repo=repo)
    out.run(("ls",), "vertices", repo=repo)  # vertex 0 has index 0: present, an int
    out.run(("export",), "intel", "-o", str(root / "intel.g2o"), repo=repo)
    out.run(("plot",), "-o", str(root / "map.png"), repo=repo)
    out.run(("align",), repo=repo)  # one mission: the world is its frame
    out.run(("missions",), "--frame", "world", repo=repo)
    laser = root / "laser"  # a repository of its own: the others' boxes stay as they are
    out.run(("init",), str(laser), "--name", "robot-l")
    out.run(("import",), str(LASER_LOG), repo=laser)
    out.run(("grid",), "-o", str(root / "head.yaml"), "--resolution", "0.1", repo=laser)
    out.run(("grid",), "-o", str(root / "big.yaml"), "--tile", "64", repo=laser)
    out.run(("export",), "intel-head", "-o", str(root / "head-export.yaml"), repo=laser)


def run_secure(out: Outputs, root: Path) -> None:
    """`init --secure`, `key show` and `trust add|list|remove` on two secure repositories."""
    one, two = root / "s1", root / "s2"
    out.run(("init",), str(one), "--secure")
    out.run(("init",), str(two), "--secure")
    key = out.run(("key", "show"), repo=two)["public_key"]
    out.run(("trust", "add"), key, repo=one)
    out.run(("trust", "list"), repo=one)
    out.run(("trust", "remove"), key, repo=one)


def start(out: Outputs, daemons: Daemons, repo: Path) -> dict[str, Any]:
    """`mapctl -C repo peer start --detach --json`, a real daemon process."""
    daemons.adopt(repo)
    done = subprocess.run(
        [MAPCTL, "-C", str(repo), "peer", "start", "--detach", "--json"],
        capture_output=True,
        text=True,
        timeout=COMMAND_TIMEOUT,
        check=True,
    )
    info: dict[str, Any] = out.keep(("peer", "start"), done.stdout)
    return info


def run_swarm(out: Outputs, daemons: Daemons, repo: Path, root: Path) -> None:
    """The commands that need running peers: `repo` (from `run_offline`) and a
    second peer `b` that joins it, participates, watches and leaves."""
    a = start(out, daemons, repo)
    other = root / "b"
    out.run(("init",), str(other), "--name", "robot-b")
    start(out, daemons, other)
    out.run(("join",), a["join"], repo=other)
    out.run(("peers",), repo=other)
    out.run(("peer", "status"), repo=other)
    chunk = out.run(("chunk", "list"), "--table", "pts", repo=repo)["chunks"][0]["id"]
    out.run(("chunk", "list"), "--peer", a["address"], repo=other)
    out.run(("chunk", "participate"), chunk, repo=other)
    out.run(("chunk", "leave"), chunk, repo=other)
    out.run(("query-bbox",), "-1", "-1", "-1", "2", "2", "2", "--load", repo=other)
    out.run(("missions",), "--swarm", repo=other)
    _watch(out, other, lambda: out.run(("set",), "pts", '{"bbox": [0, 0, 0, 1, 1, 1]}', repo=repo))
    out.run(("clone",), a["join"], str(root / "c"), "--chunks", "none")
    daemons.adopt(root / "c")
    for each in (root / "c", other, repo):
        out.run(("peer", "stop"), repo=each)


def _watch(out: Outputs, repo: Path, change: Callable[[], Any]) -> None:
    """`watch --count 1 --json` in its own process; `change` commits once the
    watch says (on stderr) that its subscription is active."""
    argv = [MAPCTL, "-C", str(repo), "watch", "--count", "1", "--timeout", "30", "--json"]
    with subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as proc:
        assert proc.stderr is not None
        assert "watching" in proc.stderr.readline()  # subscribed: a commit now reaches it
        change()
        out.runner.invoke(cli, ["-C", str(repo.parent / "a"), "commit", "-m", "watched"])
        stdout, _ = proc.communicate(timeout=COMMAND_TIMEOUT)
    assert proc.returncode == 0
    out.keep(("watch",), stdout)


BENCHMARKS: dict[Command, tuple[str, ...]] = {
    ("bench", "local"): ("-n", "5"),
    ("bench", "commit"): ("-n", "5", "--holders", "2"),
    ("bench", "viewtest"): ("--peers", "2", "-n", "5"),
    ("bench", "lookup"): ("--peers", "4", "--lookups", "10"),
    ("bench", "spatial"): ("-d", "parking-garage", "-c", "1", "-l", "0", "-p", "2", "-n", "2"),
    ("bench", "registration"): ("--quick",),
    ("bench", "import"): ("-d", "intel", "-n", "1", "--store", "memory"),
    ("bench", "scale"): ("--missions", "1,2", "--runs", "1"),
    ("bench", "triggers"): (
        *("-f", "0.5", "-m", "idle", "-w", "1", "-s", "1"),
        *("-p", "2", "--items", "5", "-n", "2"),
    ),
    ("bench", "fuzz"): ("--messages", "50"),
    ("bench", "soak"): ("--minutes", "0.1", "--peers", "3"),
    ("bench", "flood"): ("--senders", "2", "--megabytes", "3", "--mode", "frame"),
    ("bench", "sim"): ("--seeds", "2"),
    ("bench", "mapping"): ("--robots", "2", "--holders", "2", "--seconds", "1"),
    ("demo",): ("--peers", "3"),
}
"""The smallest run of each benchmark (and the demo), with its arguments."""

_SCRATCH = {
    ("bench", n) for n in ("local", "commit", "viewtest", "fuzz", "soak", "scale", "mapping")
}


def run_benchmark(out: Outputs, path: Command, root: Path) -> None:
    """One small run of a benchmark (or the demo) in its own process, as a user
    runs it: they start peer processes and change the working directory's files."""
    args = list(BENCHMARKS[path])
    if path in _SCRATCH:
        args += ["--dir", str(root)]
    if path == ("demo",):
        args += ["--out", str(root / "demo")]
    done = subprocess.run(
        [MAPCTL, *path, *args, "--json"],
        capture_output=True,
        text=True,
        timeout=BENCH_TIMEOUT,
        check=False,
        cwd=root,
    )
    assert done.returncode == 0, f"mapctl {' '.join(path)} exited {done.returncode}: {done.stderr}"
    out.keep(path, done.stdout)


BENCH_TIMEOUT = 120.0
