"""`mapctl peer ...`, `peers`, `join`, `chunk participate|leave` and the CLI path.

Without a daemon the swarm commands exit 5 with a hint; a stale pid file is
ignored. A daemon served in the test's own event loop (`mapapi.service.daemon.serve`)
shows that every command goes through its control endpoint while it runs, with
the same exit codes; the CLI runs in a worker thread meanwhile. The detached
start and a SIGKILLed daemon use real processes (marked slow).
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from mapapi import Repository
from mapapi.service import known_peers
from mapapi.service.daemon import advertised_address
from mapapi.service.daemon_process import stop_daemon
from mapapi.service.repo import PeerRecord
from mapapi.testing import wait_until
from tests.cli.conftest import STRUCT, InProcessDaemon, Mapctl

CHUNK = "0123456789abcdef0123456789abcdef"
TIMEOUT = 30.0


def _dead_pid() -> int:
    """The pid of a process that has exited (and been reaped)."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait(timeout=TIMEOUT)
    return child.pid


def _write_stale_record(repo: Path) -> PeerRecord:
    record = PeerRecord(
        _dead_pid(),
        "f" * 32,
        "ghost",
        "tcp://127.0.0.1:9",
        "tcp://127.0.0.1:9",
        "tcp://127.0.0.1:9",
        0,
    )
    (repo / ".mapapi" / "peer.pid").write_text(record.to_json(), encoding="utf-8")
    (repo / ".mapapi" / "peer.lock").touch()  # left behind, but nobody holds it
    return record


class TestWithoutADaemon:
    @pytest.mark.parametrize(
        "args",
        [
            ("peers",),
            ("peers", "--json"),
            ("join", "tcp://127.0.0.1:9"),
            ("chunk", "participate", CHUNK),
            ("chunk", "leave", CHUNK),
        ],
    )
    def test_swarm_commands_exit_5_with_a_hint(self, mapctl: Mapctl, args: tuple[str, ...]) -> None:
        outcome = mapctl.main(*args)
        assert outcome.code == 5, outcome
        assert len(outcome.err_lines) == 1
        assert outcome.err_lines[0].startswith("error: no peer runs on this repository")
        assert "mapctl peer start" in outcome.err
        assert outcome.out == ""

    def test_peer_status_and_stop_say_none_runs(self, mapctl: Mapctl) -> None:
        assert mapctl.json("peer", "status") == {"running": False}
        assert mapctl.json("peer", "stop") == {"stopped": False, "pid": None, "id": None}
        assert "no peer runs" in mapctl("peer", "stop")

    def test_a_bad_join_address_is_a_usage_error(self, mapctl: Mapctl) -> None:
        outcome = mapctl.main("peer", "start", "--join", "127.0.0.1:7000")
        assert outcome.code == 2
        assert "bad peer address '127.0.0.1:7000'" in outcome.err


class TestStalePidFile:
    def test_a_stale_pid_file_is_ignored(self, points: Mapctl) -> None:
        _write_stale_record(points.repo)
        repo = Repository.find(points.repo)
        assert repo.running_peer() is None
        assert repo.stale_peer_record() is not None
        # every command works on the repository alone, as if no file were there
        item = points.insert({"x": 1})
        points.commit("alone")
        assert points.json("ls", "pts")["items"] == [{"id": item, "data": {"x": 1.0}}]
        assert points.json("peer", "status") == {"running": False}
        assert points.main("peers").code == 5

    def test_peer_stop_removes_a_stale_pid_file(self, mapctl: Mapctl) -> None:
        record = _write_stale_record(mapctl.repo)
        out = mapctl("peer", "stop")
        assert f"removed the stale pid file of {record.pid}" in out
        assert not (mapctl.repo / ".mapapi" / "peer.pid").exists()

    def test_an_unreadable_pid_file_is_ignored(self, points: Mapctl) -> None:
        (points.repo / ".mapapi" / "peer.pid").write_text("{not json", encoding="utf-8")
        assert Repository.find(points.repo).read_peer_record() is None
        assert points.json("table", "list")["tables"][0]["name"] == "pts"


class TestAdvertisedAddress:
    def test_a_concrete_address_is_kept(self) -> None:
        assert advertised_address("tcp://127.0.0.1:7000") == "tcp://127.0.0.1:7000"
        assert advertised_address("tcp://10.1.2.3:7000", ["tcp://10.1.2.4:7000"]) == (
            "tcp://10.1.2.3:7000"
        )
        assert advertised_address("ipc:///tmp/peer") == "ipc:///tmp/peer"

    def test_a_wildcard_becomes_the_address_on_the_route_to_the_seed(self) -> None:
        seeds = ["tcp://127.0.0.1:7001"]
        assert advertised_address("tcp://0.0.0.0:7000", seeds) == "tcp://127.0.0.1:7000"
        assert advertised_address("tcp://*:7000", seeds) == "tcp://127.0.0.1:7000"

    def test_with_no_seed_a_wildcard_still_becomes_a_concrete_address(self) -> None:
        address = advertised_address("tcp://0.0.0.0:7000")
        assert address.startswith("tcp://")
        assert address.endswith(":7000")
        assert "0.0.0.0" not in address


class TestThroughTheDaemon:
    async def test_pid_file_says_how_to_reach_the_peer(self, daemon: InProcessDaemon) -> None:
        record = daemon.record
        assert record is not None
        on_disk = Repository.find(daemon.repo).read_peer_record()
        assert on_disk == record
        assert record.pid == os.getpid()
        assert record.join == record.address
        assert record.address.startswith("tcp://127.0.0.1:")
        assert not record.address.endswith(":0")
        status = await daemon.json("peer", "status")
        assert set(status.pop("loop_lag_ms")) == {"p50", "p99", "max"}
        assert status == {
            "running": True,
            "id": record.id,
            "name": "bench",
            "address": record.address,
            "join": record.address,
            "pid": record.pid,
            "members": [{"id": record.id, "address": record.address, "name": "bench"}],
            "chunks": 0,
            "diverged": [],
            "rollback": [],
            "control": record.control,
        }
        assert await daemon.json("peers") == {"peers": []}

    async def test_commands_go_through_the_daemon_with_the_same_exit_codes(
        self, daemon: InProcessDaemon
    ) -> None:
        assert (await daemon("table", "create", "pts", "--type", STRUCT)).code == 0
        assert (await daemon("chunk", "create", "pts")).code == 0
        created = await daemon.json("set", "pts", '{"x": 1}')
        item = created["id"]
        assert (await daemon("commit", "-m", "one")).code == 0
        for view in ("alice", "bob"):
            assert (await daemon("view", "open", view=view)).code == 0
        for view, x in (("alice", 2), ("bob", 3)):
            assert (await daemon("set", "pts", item, json.dumps({"x": x}), view=view)).code == 0
        assert (await daemon("commit", "-m", "alice", view="alice")).code == 0
        conflicted = await daemon("commit", "-m", "bob", view="bob")
        assert conflicted.code == 3
        assert conflicted.err_lines == [
            "error: 1 conflicting item(s); run `mapctl --view bob diff` and "
            "`mapctl --view bob resolve`, then commit again"
        ]
        assert (await daemon("resolve", "--ours", view="bob")).code == 0
        assert (await daemon("commit", "-m", "bob wins", view="bob")).code == 0
        listed = await daemon.json("ls", "pts")
        assert listed == {"items": [{"id": item, "data": {"x": 3.0}}]}
        missing = await daemon("get", "pts", "ffff")
        assert missing.code == 2
        assert "no item id starts with 'ffff'" in missing.err
        log = await daemon.json("log")
        assert [c["message"] for c in log] == ["bob wins", "alice", "one"]
        # the swarm commands answer now; the last holder may not leave without --force
        assert await daemon.json("peers") == {"peers": []}
        chunk = (await daemon.json("chunk", "list"))["chunks"][0]["id"]
        refused = await daemon("chunk", "leave", chunk)
        assert refused.code == 2
        assert "--force" in refused.err
        left = await daemon.json("chunk", "leave", chunk, "--force")
        assert left == {"chunk": chunk, "left": True}

    async def test_a_second_start_is_refused(self, daemon: InProcessDaemon) -> None:
        outcome = await daemon("peer", "start")
        assert outcome.code == 2
        assert "a peer already runs on" in outcome.err
        assert "mapctl peer stop" in outcome.err

    async def test_join_needs_a_live_peer(self, daemon: InProcessDaemon, tmp_path: Path) -> None:
        other = InProcessDaemon(Repository.init(tmp_path / "other", "other").root)
        record = await other.start()
        try:
            joined = await daemon.json("join", record.join)
            members = {m["name"] for m in joined["members"]}
            assert members == {"bench", "other"}
            peers = await daemon.json("peers")
            assert [p["name"] for p in peers["peers"]] == ["other"]
        finally:
            await other.close()

    async def test_a_restart_rejoins_through_the_member_that_answers(
        self, daemon: InProcessDaemon, tmp_path: Path, caplog: pytest.LogCaptureFixture
    ) -> None:
        assert daemon.record is not None
        # Nothing listens on port 1, and its address sorts before the live one: tried
        # in turn, it would cost a join's whole timeout before the live member.
        gone = "tcp://127.0.0.1:1"
        other_repo = Repository.init(tmp_path / "other", "other")
        known_peers.remember(other_repo, [daemon.record.join, gone])
        assert known_peers.recall(other_repo) == [gone, daemon.record.join]
        other = InProcessDaemon(other_repo.root)
        await other.start()
        try:
            peers = await other.json("peers")
            assert [p["name"] for p in peers["peers"]] == ["bench"]
            assert not [r for r in caplog.records if gone in r.getMessage()]
        finally:
            await other.close()

    async def test_peer_stop_ends_the_daemon(self, daemon: InProcessDaemon) -> None:
        stopped = await daemon.json("peer", "stop")
        assert daemon.record is not None
        assert stopped == {"stopped": True, "pid": daemon.record.pid, "id": daemon.record.id}
        assert daemon.task is not None
        async with asyncio.timeout(TIMEOUT):
            await daemon.task
        repo = Repository.find(daemon.repo)
        assert repo.read_peer_record() is None
        assert repo.running_peer() is None
        assert not repo.control_path.exists()
        # and the repository works alone again
        assert (await daemon("table", "list")).code == 0
        assert (await daemon("peers")).code == 5


# -- real processes -------------------------------------------------------------------------
def _mapctl(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mapctl", *args],
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        check=False,
    )


@pytest.fixture
def detached(repo: Path) -> Iterator[Path]:
    """The repository; whatever daemon runs on it is stopped (or killed) afterwards."""
    yield repo
    stopper = Repository.find(repo)
    record = stopper.running_peer()
    if record is not None:
        try:
            stop_daemon(stopper, timeout=10.0)
        except Exception:
            os.kill(record.pid, signal.SIGKILL)


@pytest.mark.slow
class TestDetached:
    def test_start_json_shape_stop_and_restart_after_sigkill(self, detached: Path) -> None:
        started = _mapctl("-C", str(detached), "peer", "start", "--detach", "--json")
        assert started.returncode == 0, started.stderr
        info = json.loads(started.stdout)
        assert set(info) == {"id", "address", "join"}
        assert info["join"] == info["address"]
        host, port = info["address"].removeprefix("tcp://").rsplit(":", 1)
        assert host == "127.0.0.1"
        assert int(port) > 0
        repo = Repository.find(detached)
        record = repo.running_peer()
        assert record is not None
        assert record.address == info["address"]
        assert record.id == info["id"] == str(repo.config.peer_id)

        again = _mapctl("-C", str(detached), "peer", "start", "--detach")
        assert again.returncode == 2
        assert "a peer already runs" in again.stderr

        os.kill(record.pid, signal.SIGKILL)  # no goodbye: the pid file stays behind
        wait_until(lambda: repo.running_peer() is None, timeout=TIMEOUT)
        assert repo.stale_peer_record() == record
        listed = _mapctl("-C", str(detached), "table", "list", "--json")
        assert listed.returncode == 0, listed.stderr  # on the repository alone
        assert _mapctl("-C", str(detached), "peers").returncode == 5

        restarted = _mapctl("-C", str(detached), "peer", "start", "--detach")
        assert restarted.returncode == 0, restarted.stderr
        new = repo.running_peer()
        assert new is not None
        assert new.pid != record.pid
        assert restarted.stdout.strip() == new.address
        assert f"runs in the background (pid {new.pid})" in restarted.stderr

        os.kill(new.pid, signal.SIGTERM)  # a graceful stop: the daemon removes its files
        wait_until(lambda: repo.running_peer() is None, timeout=TIMEOUT)
        assert repo.read_peer_record() is None
        assert not repo.control_path.exists()
        assert "stopping" in repo.log_path.read_text(encoding="utf-8")

    def test_peer_stop(self, detached: Path) -> None:
        started = _mapctl("-C", str(detached), "peer", "start", "--detach")
        assert started.returncode == 0, started.stderr
        record = Repository.find(detached).running_peer()
        assert record is not None
        stopped = _mapctl("-C", str(detached), "peer", "stop")
        assert stopped.returncode == 0, stopped.stderr
        assert stopped.stdout.strip() == f"stopped peer bench (pid {record.pid})"
        assert Repository.find(detached).read_peer_record() is None

    def test_a_restarted_peer_listens_where_it_did_when_that_port_is_free(
        self, detached: Path
    ) -> None:
        """So the others' remembered address of it stays right through a restart of
        the whole swarm; a taken port falls back to a new one."""
        first = _mapctl("-C", str(detached), "peer", "start", "--detach")
        assert first.returncode == 0, first.stderr
        assert _mapctl("-C", str(detached), "peer", "stop").returncode == 0
        second = _mapctl("-C", str(detached), "peer", "start", "--detach")
        assert second.returncode == 0, second.stderr
        assert second.stdout.strip() == first.stdout.strip()
        assert _mapctl("-C", str(detached), "peer", "stop").returncode == 0
        port = int(first.stdout.strip().rsplit(":", 1)[1])
        with socket.socket() as squatter:
            squatter.bind(("127.0.0.1", port))
            squatter.listen()
            third = _mapctl("-C", str(detached), "peer", "start", "--detach")
            assert third.returncode == 0, third.stderr
            assert third.stdout.strip() != first.stdout.strip()

    def test_a_failed_start_reports_the_cause(self, detached: Path) -> None:
        done = _mapctl(
            "-C", str(detached), "peer", "start", "--detach", "--listen", "tcp://192.0.2.1:1"
        )
        assert done.returncode == 5
        assert "the peer exited (status 5) before it served" in done.stderr
        assert "cannot listen on tcp://192.0.2.1:1" in done.stderr
        assert Repository.find(detached).running_peer() is None
