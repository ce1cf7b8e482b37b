"""`clone`: make a folder a new peer of a swarm (`mapctl clone`).

Init the repository (or take one `mapctl init` just made, still empty: that is
how a secure swarm is cloned, since the swarm must trust the new peer's key
first), start its peer daemon joined to the swarm, then have it participate in
the chunks chosen. The daemon keeps running afterwards: it is the new peer.
"""

from __future__ import annotations

import asyncio
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mapapi.core.errors import MapError, UsageError
from mapapi.net.security import split_address
from mapapi.service.control import RemoteOperations
from mapapi.service.daemon_process import daemon_command, spawn_detached
from mapapi.service.ops import call_polled, check_address
from mapapi.service.repo import PeerRecord, Repository

Json = Any
Progress = Callable[[str, int, int], None]
"""`progress(chunk, parts received, parts)`: (chunk, 0, 0) when a chunk begins."""


@dataclass(frozen=True, slots=True)
class Cloned:
    """A clone made: its repository, its running peer and the chunks it fetched
    (each as the `participate` operation answers)."""

    repo: Repository
    record: PeerRecord
    chunks: list[Json]

    def to_json(self) -> Json:
        """Path, id, address, join string and chunks."""
        record = self.record
        return {
            "path": str(self.repo.root),
            "id": record.id,
            "address": record.address,
            "join": record.join,
            "chunks": self.chunks,
        }


async def clone(
    address: str,
    directory: Path,
    *,
    chunks: Sequence[str] | None = None,
    listen: str = "tcp://127.0.0.1:0",
    name: str | None = None,
    verbose: bool = False,
    progress: Progress | None = None,
) -> Cloned:
    """Make `directory` a new peer of the swarm at `address` and participate in
    `chunks` (ids; None: every chunk the swarm holds).

    Raises:
        UsageError: a bad address, `directory` is a repository with data, or a
            secure swarm and no repository yet (its key must be trusted first).
        MapError: the peer did not start (nothing is left behind), or a chunk
            could not be fetched (the peer keeps running; a note says so).
    """
    repo, record = await asyncio.to_thread(_start, address, directory, listen, name, verbose)
    remote = RemoteOperations.of(repo, record, alive=repo.peer_locked)
    try:
        wanted = chunks
        if wanted is None:
            wanted = [c["id"] for c in (await remote.call("swarm_chunks", {}))["chunks"]]
        done = [await _participate(remote, chunk, progress) for chunk in wanted]
    except MapError as exc:
        exc.add_note(
            f"the peer of {repo.root} keeps running; retry with `mapctl -C {repo.root} chunk "
            "participate ID`, or stop it with `mapctl peer stop`"
        )
        raise
    finally:
        await remote.close()
    return Cloned(repo, record, done)


def _start(
    address: str, directory: Path, listen: str, name: str | None, verbose: bool
) -> tuple[Repository, PeerRecord]:
    """Make (or take) the repository and start its daemon, joined through
    `address` (blocking: files, and waiting for the daemon to serve)."""
    check_address(address)
    check_address(listen)
    existed = directory.exists()
    repo, made = _target(directory, address, name)
    try:
        argv = daemon_command(repo, listen, (address,), None, verbose)
        return repo, spawn_detached(repo, argv)
    except BaseException:
        # nothing but an empty repository was made: leave no half-made clone behind
        if made:
            shutil.rmtree(repo.root if not existed else repo.meta_dir, ignore_errors=True)
        raise


async def _participate(remote: RemoteOperations, chunk: str, progress: Progress | None) -> Json:
    def show(state: Json) -> None:
        if progress is not None:
            progress(chunk, state["received"], state["parts"])

    show({"received": 0, "parts": 0})
    args = {"chunk": chunk}
    return await call_polled(remote, "participate", args, ("participate_progress", args), show)


def _target(directory: Path, address: str, name: str | None) -> tuple[Repository, bool]:
    """The repository to clone into, and whether it was made now.

    Raises:
        UsageError: `directory` is a repository with data, or `address` is a secure
            swarm and `directory` is no repository yet (the swarm cannot trust a
            key made on the spot).
    """
    if (directory / ".mapapi" / "config.toml").is_file():
        repo = Repository.find(directory)
        if name or not repo.is_empty():
            raise UsageError(
                f"{repo.root} is a repository already; clone into a new folder, or into one "
                "that `mapctl init` just made (no --name then)"
            )
        return repo, False
    endpoint, key = split_address(address)
    if key is not None:
        raise UsageError(
            f"{endpoint} is a secure swarm: its peers must trust the new peer's key before "
            f"it joins. Run `mapctl init {directory} --secure`, have every peer of the swarm "
            f"`mapctl trust add` the key it prints, trust theirs (`mapctl -C {directory} "
            f"trust add KEY`), then run this clone again"
        )
    return Repository.init(directory, name), True
