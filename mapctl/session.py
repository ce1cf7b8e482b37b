"""`Session`: what every command shares (repo path, view, the opened peer)."""

from __future__ import annotations

from collections.abc import Coroutine
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

if TYPE_CHECKING:
    from mapapi import Peer
    from mapapi.store.base import IdKind
    from mapapi.workspace import Workspace

T = TypeVar("T")


class Session:
    """Opens the repository lazily and closes it when the command ends."""

    def __init__(self, path: Path, view: str, verbose: bool) -> None:
        self.path = path
        self.view = view
        self.verbose = verbose
        self._peer: Peer | None = None

    @property
    def peer(self) -> Peer:
        """The repository's peer (opened on first use)."""
        if self._peer is None:
            from mapapi import Peer

            self._peer = Peer.open(self.path)
        return self._peer

    @property
    def workspace(self) -> Workspace:
        """The repository's named views."""
        from mapapi.workspace import Workspace

        return Workspace(self.peer)

    def run(self, coro: Coroutine[Any, Any, T]) -> T:
        """Run one library coroutine to completion."""
        import asyncio  # here, not at the top: `mapctl --help` never needs it

        return asyncio.run(coro)

    def resolve_id(self, kind: IdKind, text: str) -> str:
        """A full id from a full id or a unique prefix (like a short git hash)."""
        from mapapi.errors import UsageError

        text = text.lower()
        if not 4 <= len(text) <= 32 or any(c not in "0123456789abcdef" for c in text):
            raise UsageError(f"bad {kind} id {text!r}: give 32 hex digits or a prefix of 4 or more")
        if len(text) == 32:
            return text
        found = self.peer.store.resolve_prefix(kind, text)
        if not found:
            raise UsageError(f"no {kind} id starts with {text!r}")
        if len(found) > 1:
            raise UsageError(f"{kind} id prefix {text!r} is ambiguous; give more digits")
        return found[0]

    def close(self) -> None:
        """Release the repository."""
        if self._peer is not None:
            self._peer.store.close()
            self._peer = None


pass_session = click.make_pass_decorator(Session)

json_option = click.option("--json", "as_json", is_flag=True, help="Print JSON for scripts.")
