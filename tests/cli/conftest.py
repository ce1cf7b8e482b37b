"""Fixtures for the `mapctl` tests: a real repository in tmp_path and a CLI driver.

`Mapctl` runs the click group in-process with `CliRunner` (fast). `Mapctl.main`
runs `mapctl.cli.main`, the console script's error boundary, in-process too, so
exit codes and the one-line error messages are the real ones. `daemon` serves
the repository's peer daemon in the test's own event loop, so commands go
through its control endpoint.
"""

from __future__ import annotations

import asyncio
import json
import sys
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner, Result

from mapapi import Repository
from mapapi.app import operations, peer_of
from mapapi.service.daemon import serve
from mapapi.service.repo import PeerRecord
from mapctl.cli import cli, main

STRUCT = "google.protobuf.Struct"


@dataclass(frozen=True)
class Outcome:
    """What `mapctl.cli.main` did: exit code, stdout and stderr."""

    code: int
    out: str
    err: str

    @property
    def err_lines(self) -> list[str]:
        """The non-empty lines written to stderr."""
        return [line for line in self.err.splitlines() if line.strip()]


class Mapctl:
    """Drives `mapctl` on one repository, optionally in a named view."""

    def __init__(self, repo: Path) -> None:
        self.repo = repo
        self.runner = CliRunner()

    def _argv(self, args: tuple[str, ...], view: str | None) -> list[str]:
        return ["-C", str(self.repo), *(["--view", view] if view else []), *args]

    def invoke(self, *args: str, view: str | None = None, input: str | None = None) -> Result:
        """Run a command; return the result whatever happened."""
        return self.runner.invoke(cli, self._argv(args, view), input=input)

    def __call__(self, *args: str, view: str | None = None, input: str | None = None) -> str:
        """Run a command that must succeed; return its stdout."""
        result = self.invoke(*args, view=view, input=input)
        assert result.exit_code == 0, (
            f"mapctl {' '.join(args)} failed ({result.exit_code}): {result.exception!r}\n"
            f"{result.output}"
        )
        return result.stdout

    def json(self, *args: str, view: str | None = None, input: str | None = None) -> Any:
        """Run a command with `--json` that must succeed; return the parsed document."""
        return json.loads(self(*args, "--json", view=view, input=input))

    def insert(self, data: Any, *, table: str = "pts", view: str | None = None) -> str:
        """Stage an insert of `data` (a JSON value); return the new id."""
        return str(self.json("set", table, json.dumps(data), view=view)["id"])

    def commit(self, message: str = "", *, view: str | None = None) -> dict[str, Any]:
        """Commit a view that must not conflict; return the commit record."""
        record: dict[str, Any] = self.json("commit", "-m", message, view=view)
        return record

    def main(self, *args: str, view: str | None = None, input: str | None = None) -> Outcome:
        """Run `mapctl.cli.main` the way the console script does."""
        return run_main(self._argv(args, view), input=input)


def run_main(argv: list[str], input: str | None = None) -> Outcome:
    """Run the console script's `main()` in-process on `argv`."""
    runner = CliRunner()
    saved = sys.argv
    code: int | str | None = 0
    with runner.isolation(input=input) as (out, err, _):
        sys.argv = ["mapctl", *argv]
        try:
            main()
        except SystemExit as exc:
            code = exc.code
        finally:
            sys.argv = saved
            sys.stdout.flush()
            sys.stderr.flush()
        stdout, stderr = out.getvalue().decode(), err.getvalue().decode()
    assert isinstance(code, int) or code is None, f"exit with {code!r}"
    return Outcome(code or 0, stdout, stderr)


@pytest.fixture
def repo(tmp_path: Path) -> Path:
    """An empty, initialised repository."""
    path = tmp_path / "repo"
    result = CliRunner().invoke(cli, ["init", str(path), "--name", "bench"])
    assert result.exit_code == 0, result.output
    return path


@pytest.fixture
def mapctl(repo: Path) -> Mapctl:
    """The CLI driver on an empty repository."""
    return Mapctl(repo)


@pytest.fixture
def points(mapctl: Mapctl) -> Mapctl:
    """The CLI driver on a repository with table `pts` (Struct) and one chunk."""
    mapctl("table", "create", "pts", "--type", STRUCT)
    mapctl("chunk", "create", "pts")
    return mapctl


DAEMON_TIMEOUT = 30.0  # seconds a served daemon may take to stop


class InProcessDaemon:
    """A daemon served by the test's event loop; the CLI runs in worker threads."""

    def __init__(self, repo: Path) -> None:
        self.repo = repo
        self.mapctl = Mapctl(repo)
        self.stop = asyncio.Event()
        self.record: PeerRecord | None = None
        self.task: asyncio.Task[None] | None = None

    async def start(self) -> PeerRecord:
        ready: asyncio.Future[PeerRecord] = asyncio.get_running_loop().create_future()
        self.task = asyncio.create_task(
            serve(
                Repository.find(self.repo),
                open_peer=peer_of,
                operations=operations,
                stop=self.stop,
                ready=ready.set_result,
            )
        )
        waiting: list[asyncio.Future[Any]] = [ready, self.task]
        done, _ = await asyncio.wait(waiting, return_when=asyncio.FIRST_COMPLETED)
        if self.task in done:
            self.task.result()  # raises what failed
        self.record = ready.result()
        return self.record

    async def __call__(self, *args: str, view: str | None = None) -> Outcome:
        """`mapctl ARGS` through the console script's error boundary, in a thread."""
        return await asyncio.to_thread(self.mapctl.main, *args, view=view)

    async def json(self, *args: str, view: str | None = None) -> Any:
        """`mapctl ARGS --json`, which must succeed; the parsed document."""
        outcome = await self(*args, "--json", view=view)
        assert outcome.code == 0, outcome
        return json.loads(outcome.out)

    async def close(self) -> None:
        self.stop.set()
        if self.task is not None:
            async with asyncio.timeout(DAEMON_TIMEOUT):
                await self.task


@pytest.fixture
async def daemon(repo: Path) -> AsyncIterator[InProcessDaemon]:
    """The repository's peer daemon, served in the test's event loop; stopped after it."""
    served = InProcessDaemon(repo)
    await served.start()
    yield served
    await served.close()
