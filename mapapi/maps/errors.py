"""The error the map importers raise (kept here, not in `mapapi.core.errors`: the core
knows nothing about missions, DESIGN §2)."""

from __future__ import annotations

from mapapi.core.errors import UsageError


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


class MissionRuleError(UsageError):
    """A commit would break a mission's rules (`mapapi.maps.rules`): a vertex
    index taken twice in one mission, or an edge whose end does not exist.
    Nothing of the commit is written; exit status 2 in `mapctl`.

    Attributes:
        mission: the mission whose rule the commit breaks.
        index: the vertex index concerned.
        items: the items in question, the one already there first.
    """

    def __init__(self, message: str, *, mission: str, index: int, items: tuple[str, ...]) -> None:
        self.mission, self.index, self.items = mission, index, items
        super().__init__(message)
