"""`mapctl init --secure`, `key show`, `trust add|list|remove`, and the secure
join string through the CLI (issue 7 §6, DESIGN §10)."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Awaitable, Callable
from pathlib import Path

import pytest
from zmq.utils import z85

from mapapi import Peer
from mapapi.net.security import split_address
from tests.cli.conftest import STRUCT, InProcessDaemon, Mapctl, run_main

EXIT_USAGE, EXIT_OTHER, EXIT_NETWORK = 2, 1, 5


@pytest.fixture
def secure_repo(tmp_path: Path) -> Path:
    path = tmp_path / "robot"
    outcome = run_main(["init", str(path), "--secure"])
    assert outcome.code == 0, outcome
    return path


@pytest.fixture
def secure(secure_repo: Path) -> Mapctl:
    return Mapctl(secure_repo)


def other_key(tmp_path: Path, name: str) -> str:
    """The public key of another fresh secure repository."""
    path = tmp_path / name
    info = json.loads(run_main(["init", str(path), "--secure", "--json"]).out)
    return str(info["public_key"])


class TestInit:
    def test_init_secure_makes_a_private_keypair_and_an_empty_trust_list(
        self, tmp_path: Path
    ) -> None:
        path = tmp_path / "robot"
        info = json.loads(run_main(["init", str(path), "--secure", "--json"]).out)
        assert info["secure"] is True
        assert len(info["public_key"]) == 64
        meta = path / ".mapapi"
        assert meta.stat().st_mode & 0o777 == 0o700
        assert (meta / "curve" / "peer.key_secret").stat().st_mode & 0o777 == 0o600
        assert "secure = true" in (meta / "config.toml").read_text(encoding="utf-8")
        mapctl = Mapctl(path)
        assert mapctl.json("key", "show") == {"public_key": info["public_key"]}
        assert mapctl.json("trust", "list") == {"trusted": []}

    def test_an_open_repository_has_no_key(self, mapctl: Mapctl) -> None:
        info = json.loads(run_main(["init", str(mapctl.repo.parent / "x"), "--json"]).out)
        assert info["secure"] is False
        assert "public_key" not in info
        outcome = mapctl.main("key", "show")
        assert outcome.code == EXIT_USAGE
        assert "open repository" in outcome.err
        assert "mapctl init --secure" in outcome.err
        assert mapctl.main("trust", "list").code == EXIT_USAGE

    def test_init_secure_in_an_open_repository_keeps_its_data(self, points: Mapctl) -> None:
        item = points.insert({"x": 1})
        points.commit("before")
        outcome = run_main(["init", str(points.repo), "--secure"])
        assert outcome.code == 0, outcome
        assert "secure" in outcome.out
        assert len(points.json("key", "show")["public_key"]) == 64
        assert points.json("get", "pts", item) == {"x": 1}

    def test_init_secure_twice_is_refused(self, secure: Mapctl) -> None:
        key = secure.json("key", "show")
        outcome = run_main(["init", str(secure.repo), "--secure"])
        assert outcome.code == EXIT_USAGE
        assert "secure repository already" in outcome.err
        assert secure.json("key", "show") == key  # the keypair is kept


class TestTrust:
    def test_add_list_remove(self, secure: Mapctl, tmp_path: Path) -> None:
        k1, k2 = other_key(tmp_path, "r1"), other_key(tmp_path, "r2")
        added = secure.json("trust", "add", k1, k2)
        assert added == {"keys": [{"key": k1, "added": True}, {"key": k2, "added": True}]}
        assert secure.json("trust", "add", k1) == {"keys": [{"key": k1, "added": False}]}
        assert secure.json("trust", "list") == {"trusted": sorted([k1, k2])}
        assert k1 in secure("trust", "list")
        assert secure.json("trust", "remove", k1) == {"key": k1, "removed": True}
        assert secure.json("trust", "remove", k1) == {"key": k1, "removed": False}
        assert secure.json("trust", "list") == {"trusted": [k2]}

    def test_a_z85_key_is_accepted_and_shown_as_hex(self, secure: Mapctl, tmp_path: Path) -> None:
        key = other_key(tmp_path, "r1")
        as_z85 = z85.encode(bytes.fromhex(key)).decode()
        assert secure.json("trust", "add", as_z85) == {"keys": [{"key": key, "added": True}]}

    def test_a_bad_key_writes_nothing(self, secure: Mapctl, tmp_path: Path) -> None:
        good = other_key(tmp_path, "r1")
        outcome = secure.main("trust", "add", good, "not-a-key")
        assert outcome.code == EXIT_USAGE
        assert "not a public key: 'not-a-key'" in outcome.err
        assert secure.json("trust", "list") == {"trusted": []}
        assert secure.main("trust", "remove", "abc").code == EXIT_USAGE

    def test_an_exposed_secret_key_is_refused(self, secure: Mapctl) -> None:
        (secure.repo / ".mapapi" / "curve" / "peer.key_secret").chmod(0o644)
        outcome = secure.main("key", "show")
        assert outcome.code == EXIT_OTHER
        assert "chmod 600" in outcome.err


class TestSecureDaemon:
    async def test_the_join_string_carries_the_key(self, secure: Mapctl) -> None:
        served = InProcessDaemon(secure.repo)
        record = await served.start()
        try:
            status = await served.json("peer", "status")
            key = secure.json("key", "show")["public_key"]
            assert record.join == status["join"] == status["address"]
            assert split_address(status["join"])[1] == bytes.fromhex(key)
        finally:
            await served.close()

    async def test_a_running_peer_is_not_made_secure_under_its_feet(
        self, daemon: InProcessDaemon
    ) -> None:
        outcome = await asyncio.to_thread(run_main, ["init", str(daemon.repo), "--secure"])
        assert outcome.code == EXIT_USAGE
        assert "mapctl peer stop" in outcome.err
        assert not (daemon.repo / ".mapapi" / "curve").exists()

    async def test_an_open_daemon_cannot_join_a_secure_peer(
        self, daemon: InProcessDaemon, make_peer: Callable[..., Awaitable[Peer]]
    ) -> None:
        secure_peer = await make_peer(secure=True)
        await secure_peer.start()
        outcome = await daemon("join", secure_peer.address)
        assert outcome.code == EXIT_NETWORK
        assert "is a secure swarm and this peer is open" in outcome.err
        assert (await daemon.json("peers"))["peers"] == []


class TestClone:
    def test_cloning_a_secure_swarm_into_a_new_folder_explains_the_steps(
        self, tmp_path: Path
    ) -> None:
        address = f"tcp://127.0.0.1:9#curve={'ab' * 32}"
        target = tmp_path / "new"
        outcome = run_main(["clone", address, str(target)])
        assert outcome.code == EXIT_USAGE
        assert "is a secure swarm" in outcome.err
        assert f"mapctl init {target} --secure" in outcome.err
        assert not target.exists()

    def test_cloning_into_a_repository_with_data_is_refused(self, points: Mapctl) -> None:
        outcome = run_main(["clone", "tcp://127.0.0.1:9", str(points.repo)])
        assert outcome.code == EXIT_USAGE
        assert "is a repository already" in outcome.err
        assert points.json("table", "list")["tables"][0]["name"] == "pts"
        assert STRUCT in points("table", "list")
