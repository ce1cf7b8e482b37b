"""The control endpoint is its owner's only (issue: hardening, part 1).

A daemon serves `mapctl` on an ipc socket that only its owner can reach, even
when the repository path is too long for a socket inside it (then a private
runtime folder holds it; never a tcp port, which every local user can reach),
and every call must carry the owner's token. The last test plays another local
user (`nobody`, through `runuser`), which needs root.
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import stat
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from mapapi import Repository
from mapapi.core.errors import NotOwner, RepoError
from mapapi.service.control import TOKEN_FILE, RemoteOperations, endpoint, private_runtime_dir
from tests.cli.conftest import InProcessDaemon

DEEP = "d" * 120  # a folder name that makes `.mapapi/control.sock` too long for ipc


@pytest.fixture
def public_root() -> Iterator[Path]:
    """A folder every local user may enter (as a robot's home often is), removed after."""
    root = Path(tempfile.mkdtemp(prefix="mapapi-owner-"))
    root.chmod(0o755)
    yield root
    shutil.rmtree(root)


class TestEndpoint:
    def test_a_short_repository_serves_inside_it(self, tmp_path: Path) -> None:
        repo = Repository.init(tmp_path / "r")
        assert endpoint(repo) == f"ipc://{repo.meta_dir / 'control.sock'}"

    def test_a_deep_repository_serves_in_a_private_runtime_folder(self, tmp_path: Path) -> None:
        repo = Repository.init(tmp_path / DEEP)
        address = endpoint(repo)
        assert address.startswith("ipc://")
        folder = Path(address.removeprefix("ipc://")).parent
        info = folder.stat()
        assert (info.st_uid, stat.S_IMODE(info.st_mode)) == (os.geteuid(), 0o700)

    def test_two_deep_repositories_get_two_sockets(self, tmp_path: Path) -> None:
        first = Repository.init(tmp_path / DEEP / "a")
        second = Repository.init(tmp_path / DEEP / "b")
        assert endpoint(first) != endpoint(second)

    def test_a_runtime_folder_others_may_enter_is_refused(
        self, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
        (tmp_path / "mapapi").mkdir(mode=0o755)
        (tmp_path / "mapapi").chmod(0o755)  # whatever the umask left
        with pytest.raises(RepoError, match="not private"):
            private_runtime_dir()


class TestOwnersToken:
    async def test_a_call_without_the_token_is_refused_and_the_daemon_goes_on(
        self, tmp_path: Path
    ) -> None:
        root = tmp_path / DEEP
        Repository.init(root, name="owner")
        daemon = InProcessDaemon(root)
        record = await daemon.start()
        repo = Repository.find(root)
        stranger = RemoteOperations(record.control, "0" * 64, "the peer")
        owner = RemoteOperations.of(repo, record)
        try:
            with pytest.raises(NotOwner, match="owner's token"):
                await stranger.call("shutdown", {})
            assert (await owner.call("peer_status", {}))["name"] == "owner"
        finally:
            await stranger.close()
            await owner.close()
            await daemon.close()

    async def test_the_socket_and_the_token_are_the_owners_only(self, repo: Path) -> None:
        daemon = InProcessDaemon(repo)
        record = await daemon.start()
        try:
            token = os.stat(repo / ".mapapi" / TOKEN_FILE)
            socket = os.stat(record.control.removeprefix("ipc://"))
            assert stat.S_IMODE(token.st_mode) == stat.S_IMODE(socket.st_mode) == 0o600
        finally:
            await daemon.close()


# Run as `nobody`: try to connect to the control endpoint (ipc or tcp) and to read
# the token; print what happened. Plain sockets, so no zmq is needed.
_INTRUDER = r"""
import json, socket, sys
address, token = sys.argv[1], sys.argv[2]
seen = {}
try:
    if address.startswith("ipc://"):
        s = socket.socket(socket.AF_UNIX)
        s.connect(address[len("ipc://"):])
    else:
        host, port = address[len("tcp://"):].rsplit(":", 1)
        s = socket.create_connection((host, int(port)), timeout=5)
    seen["connect"] = "connected"
except OSError as exc:
    seen["connect"] = type(exc).__name__
try:
    open(token).read()
    seen["token"] = "read"
except OSError as exc:
    seen["token"] = type(exc).__name__
print(json.dumps(seen))
"""


def _as_nobody(*argv: str) -> dict[str, str]:
    result = subprocess.run(
        ["runuser", "-u", "nobody", "--", "/usr/bin/python3", "-c", _INTRUDER, *argv],
        capture_output=True,
        text=True,
        timeout=30,
        check=True,
    )
    seen: dict[str, str] = json.loads(result.stdout)
    return seen


@pytest.mark.skipif(os.geteuid() != 0, reason="playing another local user needs root (runuser)")
@pytest.mark.skipif(
    not (shutil.which("runuser") and Path("/usr/bin/python3").exists()),
    reason="needs runuser and /usr/bin/python3 to run as nobody",
)
async def test_another_local_user_cannot_reach_a_deep_repositorys_daemon(
    public_root: Path,
) -> None:
    root = public_root / DEEP
    root.mkdir(mode=0o755)
    Repository.init(root)
    daemon = InProcessDaemon(root)
    record = await daemon.start()
    try:
        token = str(root / ".mapapi" / TOKEN_FILE)
        seen = await asyncio.to_thread(_as_nobody, record.control, token)
        assert seen == {"connect": "PermissionError", "token": "PermissionError"}
        owner = RemoteOperations.of(Repository.find(root), record)
        try:
            assert (await owner.call("peer_status", {}))["id"] == record.id
        finally:
            await owner.close()
    finally:
        await daemon.close()
