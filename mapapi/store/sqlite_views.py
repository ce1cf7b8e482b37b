"""The saved-views part of `SqliteStore`: each open view's state
as one blob under its name.

A base class of `SqliteStore`, as `SqliteChains` is: these are methods of the
`Store` protocol, on the store's connections.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Callable
from contextlib import AbstractContextManager


class SqliteViews:
    """The views kept in the store (see the module docstring)."""

    _con: Callable[[], sqlite3.Connection]
    _write: Callable[[sqlite3.Connection], AbstractContextManager[None]]

    def load_view(self, name: str) -> bytes | None:
        """A view."""
        row = self._con().execute("SELECT body FROM views WHERE name = ?", (name,)).fetchone()
        return None if row is None else bytes(row[0])

    def save_view(self, name: str, blob: bytes) -> None:
        """Store a view."""
        con = self._con()
        with self._write(con):
            con.execute("INSERT OR REPLACE INTO views VALUES (?, ?)", (name, blob))

    def delete_view(self, name: str) -> None:
        """Drop a view."""
        con = self._con()
        with self._write(con):
            con.execute("DELETE FROM views WHERE name = ?", (name,))

    def views(self) -> dict[str, bytes]:
        """All views."""
        return {n: bytes(b) for n, b in self._con().execute("SELECT name, body FROM views")}
