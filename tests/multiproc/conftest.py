"""Helpers for tests that drive real `mapctl` processes."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from mapapi import Repository
from mapapi.service.daemon_process import stop_daemon

COMMAND_TIMEOUT = 30.0


def _mapctl_path() -> str:
    found = shutil.which("mapctl", path=str(Path(sys.executable).parent)) or shutil.which("mapctl")
    assert found, "mapctl is not installed next to the test interpreter"
    return found


MAPCTL = _mapctl_path()


def run_mapctl(
    repo: Path, *args: str, view: str = "main", ok: tuple[int, ...] = (0,)
) -> subprocess.CompletedProcess[str]:
    """Run one `mapctl -C repo --view VIEW ARGS` process; check its exit code against `ok`."""
    done = subprocess.run(
        [MAPCTL, "-C", str(repo), "--view", view, *args],
        capture_output=True,
        text=True,
        timeout=COMMAND_TIMEOUT,
        check=False,
    )
    assert done.returncode in ok, (
        f"mapctl -C {repo.name} {' '.join(args)} exited {done.returncode}: {done.stderr}"
    )
    return done


def mapctl(repo: Path, *args: str, view: str = "main", ok: tuple[int, ...] = (0,)) -> str:
    """Run `mapctl -C repo ARGS`; check its exit code; return its stdout."""
    return run_mapctl(repo, *args, view=view, ok=ok).stdout


def mapctl_json(repo: Path, *args: str, view: str = "main") -> Any:
    return json.loads(mapctl(repo, *args, "--json", view=view))


def holders_of(repo: Path, chunk: str) -> list[str]:
    """The holders of `chunk` as the peer of `repo` records them (`chunk list`)."""
    rows = mapctl_json(repo, "chunk", "list")["chunks"]
    return next(r["holders"] for r in rows if r["id"] == chunk)


@dataclass
class Daemon:
    """One started peer: its repository and what `peer start --json` printed."""

    repo: Path
    id: str
    address: str
    join: str


class Daemons:
    """Starts peers in fresh repositories; `cleanup()` stops them all, no matter what."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.repos: list[Path] = []

    def start(
        self, name: str, join: str | None = None, env: dict[str, str] | None = None
    ) -> Daemon:
        """`init` a repository `name` and start its daemon (joined through `join`;
        `env` adds to the daemon's environment, e.g. MAPAPI_FAULTS)."""
        repo = self.root / name
        subprocess.run(
            [MAPCTL, "init", str(repo), "--name", name],
            check=True,
            capture_output=True,
            timeout=COMMAND_TIMEOUT,
        )
        self.repos.append(repo)
        return self.restart(repo, join, env)

    def restart(
        self, repo: Path, join: str | None = None, env: dict[str, str] | None = None
    ) -> Daemon:
        """Start the daemon of an existing repository (without `join`, it rejoins
        through the members it remembers)."""
        args = ["peer", "start", "--detach", "--json", *(["--join", join] if join else [])]
        done = subprocess.run(
            [MAPCTL, "-C", str(repo), *args],
            capture_output=True,
            text=True,
            timeout=COMMAND_TIMEOUT,
            check=False,
            env={**os.environ, **(env or {})},
        )
        assert done.returncode == 0, (
            f"peer start in {repo.name} exited {done.returncode}: {done.stderr}"
        )
        info = json.loads(done.stdout)
        assert set(info) == {"id", "address", "join"}
        return Daemon(repo, info["id"], info["address"], info["join"])

    def adopt(self, repo: Path) -> None:
        """Also clean up the daemon of `repo` (say a clone's)."""
        self.repos.append(repo)

    def cleanup(self) -> None:
        for path in self.repos:
            if not (path / ".mapapi").is_dir():
                continue
            repo = Repository.find(path)
            record = repo.running_peer()
            if record is None:
                continue
            try:
                stop_daemon(repo, timeout=10.0)
            except Exception:
                os.kill(record.pid, signal.SIGKILL)


@pytest.fixture
def daemons(tmp_path: Path) -> Iterator[Daemons]:
    started = Daemons(tmp_path)
    try:
        yield started
    finally:
        started.cleanup()
