"""`Session`: what every command shares (repo path, view, the operations)."""

from __future__ import annotations

from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

if TYPE_CHECKING:
    import asyncio

    from mapapi import Operations, RemoteOperations

T = TypeVar("T")

Progress = Callable[[Any], None]  # gets each answer of a progress operation


class Session:
    """Opens the repository lazily and closes it when the command ends.

    Commands call `call(op, **args)`: one JSON operation of `mapapi.Operations`. While
    a peer daemon runs on the repository (`mapctl peer start`), every operation
    goes to it over its control endpoint; otherwise it runs on the repository's
    embedded peer in this process (DESIGN §9).
    """

    def __init__(self, path: Path, view: str, verbose: bool) -> None:
        self.path = path
        self.view = view
        self.verbose = verbose
        self._ops: Operations | RemoteOperations | None = None
        self._runner: asyncio.Runner | None = None

    @property
    def ops(self) -> Operations | RemoteOperations:
        """The operations: the running daemon's, else the embedded peer's (on first use)."""
        if self._ops is None:
            from mapapi import attach

            self._ops = attach(self.path)
        return self._ops

    @property
    def remote(self) -> bool:
        """True when the operations go to a running peer daemon."""
        from mapapi import RemoteOperations

        return isinstance(self.ops, RemoteOperations)

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
        from mapapi import call_polled

        return self.run(call_polled(self.ops, op, args, poll, show))

    def close(self) -> None:
        """Release the repository, or the connection to its daemon."""
        ops, self._ops = self._ops, None
        if ops is not None:
            from mapapi import RemoteOperations

            if not isinstance(ops, RemoteOperations):
                ops.peer.store.close()  # the embedded peer: never on the network
            elif self._runner is not None:
                self._runner.run(ops.close())
        if self._runner is not None:
            self._runner.close()
            self._runner = None


pass_session = click.make_pass_decorator(Session)

json_option = click.option("--json", "as_json", is_flag=True, help="Print JSON for scripts.")
