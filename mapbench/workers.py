"""Peer processes for the swarm benchmarks: each a `python -m mapbench.worker`
child on loopback, driven over its acknowledged line protocol (see
`mapbench.worker`); every reply is awaited under a deadline and every child is
stopped (then killed) on the way out."""

from __future__ import annotations

import contextlib
import json
import queue
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from mapapi.core.errors import MapError
from mapapi.net.security import key_text, split_address

STARTUP_TIMEOUT = 30.0
CALL_TIMEOUT = 60.0


class WorkerFailed(MapError):
    """A worker process answered with an error, died, or did not answer in time."""


class SwarmCheckFailed(MapError):
    """The peers disagree after a benchmark (a lost or a diverging commit)."""


class WorkerProcess:
    """One `mapbench.worker` child and its acknowledged line protocol.

    Args:
        folder: the child's repository folder (created if missing).
        name: the peer's name.
        use_uvloop: run the child's event loop on uvloop.
        log: where the child's stderr goes (a file; None discards it).
        secure: a secure peer (its address carries its key; it trusts no one yet).
    """

    def __init__(
        self,
        folder: Path,
        name: str,
        *,
        use_uvloop: bool = False,
        log: IO[str] | None = None,
        secure: bool = False,
    ) -> None:
        self.name = name
        command = [sys.executable, "-m", "mapbench.worker", "--repo", str(folder)]
        command += ["--name", name]
        command += ["--uvloop"] if use_uvloop else []
        command += ["--secure"] if secure else []
        self.proc = subprocess.Popen(
            command,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=log if log is not None else subprocess.DEVNULL,
            text=True,
            bufsize=1,
        )
        self._lines: queue.Queue[str | None] = queue.Queue()
        self._reader = threading.Thread(target=self._read, name=f"{name} stdout", daemon=True)
        self._reader.start()
        self.id = ""
        self.address = ""

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self._lines.put(line)
        self._lines.put(None)  # end of output: the child exited

    def wait_ready(self, timeout: float = STARTUP_TIMEOUT) -> None:
        """Wait for the child's `ready` line; remember its id and address."""
        ready = self.reply("ready", timeout)
        self.id, self.address = ready["id"], ready["address"]

    def send(self, *words: object) -> None:
        """Write one command line."""
        assert self.proc.stdin is not None
        try:
            self.proc.stdin.write(" ".join(str(w) for w in words) + "\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, ValueError) as exc:
            raise WorkerFailed(f"worker {self.name} exited (its stdin is closed)") from exc

    def reply(self, word: str, timeout: float = CALL_TIMEOUT) -> dict[str, Any]:
        """The next reply line, which must be `word {json}`.

        Raises:
            WorkerFailed: an `error` reply, another word, no reply within
                `timeout` seconds, or the child exited.
        """
        try:
            line = self._lines.get(timeout=timeout)
        except queue.Empty:
            raise WorkerFailed(
                f"worker {self.name} did not answer {word!r} within {timeout:g} s"
            ) from None
        if line is None:
            raise WorkerFailed(f"worker {self.name} exited (code {self.proc.poll()})")
        got, _, body = line.partition(" ")
        data: dict[str, Any] = json.loads(body) if body.strip() else {}
        if got == "error":
            raise WorkerFailed(f"worker {self.name}: {data.get('error')}: {data.get('message')}")
        if got != word:
            raise WorkerFailed(f"worker {self.name} answered {got!r}, expected {word!r}")
        return data

    def call(self, word: str, *command: object, timeout: float = CALL_TIMEOUT) -> dict[str, Any]:
        """Send a command and wait for its acknowledgement `word`."""
        self.send(*command)
        return self.reply(word, timeout)

    def close(self, timeout: float = 10.0) -> None:
        """Ask the child to quit; kill it if it does not exit within `timeout` s."""
        try:
            if self.proc.poll() is None:
                with contextlib.suppress(WorkerFailed):
                    self.send("quit")
                with contextlib.suppress(subprocess.TimeoutExpired):
                    self.proc.wait(timeout)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait(timeout)
            for stream in (self.proc.stdin, self.proc.stdout):
                if stream is not None:
                    with contextlib.suppress(OSError):
                        stream.close()
            self._reader.join(timeout)


@contextlib.contextmanager
def spawn_workers(
    count: int,
    folder: Path,
    *,
    use_uvloop: bool = False,
    secure: bool = False,
) -> Iterator[list[WorkerProcess]]:
    """`count` started workers with repositories under `folder`; all stopped on exit.
    `secure` workers trust each other's keys (a secure swarm, DESIGN §10).

    Their stderr goes to `folder/worker-I.log`.
    """
    started: list[WorkerProcess] = []
    logs: list[IO[str]] = []
    try:
        for index in range(count):
            log = (folder / f"worker-{index}.log").open("w")
            logs.append(log)
            started.append(
                WorkerProcess(
                    folder / f"peer{index}",
                    f"peer{index}",
                    use_uvloop=use_uvloop,
                    log=log,
                    secure=secure,
                )
            )
        for worker in started:
            worker.wait_ready()
        if secure:
            keys = {w.name: split_address(w.address)[1] for w in started}
            for worker in started:
                others = [key_text(k) for n, k in keys.items() if n != worker.name and k]
                worker.call("trusted", "trust", *others)
        yield started
    finally:
        for worker in started:
            worker.close()
        for stream in logs:
            stream.close()
