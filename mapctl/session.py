"""`Session`: what every command shares (repo path, view, the operations)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

if TYPE_CHECKING:
    from mapapi.ops import Operations


class Session:
    """Opens the repository lazily and closes it when the command ends.

    Commands call `call(op, **args)`: one JSON operation of `mapapi.ops`,
    run on the repository's embedded peer.
    """

    def __init__(self, path: Path, view: str, verbose: bool) -> None:
        self.path = path
        self.view = view
        self.verbose = verbose
        self._ops: Operations | None = None

    @property
    def ops(self) -> Operations:
        """The operations over the repository's peer (opened on first use)."""
        if self._ops is None:
            from mapapi import Peer
            from mapapi.ops import Operations

            self._ops = Operations(Peer.open(self.path))
        return self._ops

    def call(self, op: str, **args: Any) -> Any:
        """Run one operation to completion and return its JSON result."""
        import asyncio  # here, not at the top: `mapctl --help` never needs it

        return asyncio.run(self.ops.call(op, args))

    def close(self) -> None:
        """Release the repository."""
        if self._ops is not None:
            self._ops.peer.store.close()
            self._ops = None


pass_session = click.make_pass_decorator(Session)

json_option = click.option("--json", "as_json", is_flag=True, help="Print JSON for scripts.")
