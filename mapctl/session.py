"""`Session`: what every command shares (repo path, view, the operations)."""

from __future__ import annotations

from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

import click

if TYPE_CHECKING:
    import asyncio

    from mapapi.service.peer import Peer

T = TypeVar("T")

PROGRESS_POLL_S = 0.2
Progress = Callable[[Any], None]  # gets each answer of a progress operation


class Ops(Protocol):
    """`mapapi.service.ops.Operations`, or `mapapi.service.control.RemoteOperations` in a daemon."""

    async def call(self, op: str, args: dict[str, Any]) -> Any:
        """Run one operation; its JSON result."""


class Session:
    """Opens the repository lazily and closes it when the command ends.

    Commands call `call(op, **args)`: one JSON operation of `mapapi.service.ops`. While
    a peer daemon runs on the repository (`mapctl peer start`), every operation
    goes to it over its control endpoint; otherwise it runs on the repository's
    embedded peer in this process (DESIGN §9).
    """

    def __init__(self, path: Path, view: str, verbose: bool) -> None:
        self.path = path
        self.view = view
        self.verbose = verbose
        self._ops: Ops | None = None
        self._peer: Peer | None = None
        self._runner: asyncio.Runner | None = None

    @property
    def ops(self) -> Ops:
        """The operations: the running daemon's, else the embedded peer's (on first use)."""
        if self._ops is None:
            from mapapi.service.repo import Repository

            repo = Repository.find(self.path)
            record = repo.running_peer()
            if record is not None:
                from mapapi.service.control import RemoteOperations

                self._ops = RemoteOperations.of(repo, record, alive=repo.peer_locked)
            else:
                from mapapi.service.ops import Operations
                from mapapi.service.peer import Peer

                self._peer = Peer.of(repo)
                self._ops = Operations(self._peer)
        return self._ops

    @property
    def remote(self) -> bool:
        """True when the operations go to a running peer daemon."""
        self.ops  # noqa: B018  (opens it: decides where the operations go)
        return self._peer is None

    def run(self, coro: Coroutine[Any, Any, T]) -> T:
        """Run a coroutine on the session's event loop (one loop per command)."""
        if self._runner is None:
            import asyncio  # here, not at the top: `mapctl --help` never needs it

            self._runner = asyncio.Runner()
        return self._runner.run(coro)

    def call(self, op: str, **args: Any) -> Any:
        """Run one operation to completion and return its JSON result."""
        return self.run(self.ops.call(op, args))

    def call_with_progress(
        self, op: str, args: dict[str, Any], poll: tuple[str, dict[str, Any]], show: Progress
    ) -> Any:
        """Run operation `op` while asking operation `poll` (name, arguments)
        how far it got, every 0.2 s; `show` gets each answer."""
        return self.run(self._polled(op, args, poll, show))

    async def _polled(
        self, op: str, args: dict[str, Any], poll: tuple[str, dict[str, Any]], show: Progress
    ) -> Any:
        import asyncio

        call = asyncio.ensure_future(self.ops.call(op, args))
        try:
            while True:
                done, _ = await asyncio.wait({call}, timeout=PROGRESS_POLL_S)
                if done:
                    return call.result()
                show(await self.ops.call(*poll))
        finally:
            if not call.done():
                call.cancel()

    def close(self) -> None:
        """Release the repository, or the connection to its daemon."""
        ops, self._ops = self._ops, None
        close = getattr(ops, "close", None)
        if close is not None and self._runner is not None:
            self._runner.run(close())
        if self._runner is not None:
            self._runner.close()
            self._runner = None
        if self._peer is not None:
            self._peer.store.close()
            self._peer = None


pass_session = click.make_pass_decorator(Session)

json_option = click.option("--json", "as_json", is_flag=True, help="Print JSON for scripts.")
