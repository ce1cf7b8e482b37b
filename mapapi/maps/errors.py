"""The error the map importers raise (kept here, not in `mapapi.errors`: the core
knows nothing about missions, DESIGN §2)."""

from __future__ import annotations

from mapapi.errors import UsageError


class MapImportError(UsageError):
    """A map file is malformed, or a graph cannot be imported as it is.

    Attributes:
        source: the file (or other source name) being read, "" when unknown.
        line: the 1-based line number of the offending input, 0 when not about a line.
    """

    def __init__(self, message: str, *, source: str = "", line: int = 0) -> None:
        self.source, self.line = source, line
        where = f"{source or '<input>'}:{line}: " if line else (f"{source}: " if source else "")
        super().__init__(f"{where}{message}")
