"""Line-oriented map text files (g2o, GTSAM landmark text): what their readers
share, opening a file to stream it and checking a record's tag and arity."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Protocol, TypeVar

from mapapi.maps.errors import MapImportError

T_co = TypeVar("T_co", covariant=True)
Progress = Callable[[int, int], None]  # (lines read, 0 while the total is unknown)


class LineParser(Protocol[T_co]):
    """A parser of a text's lines into one mission (`parse_g2o` and the like)."""

    def __call__(
        self,
        lines: Iterable[str],
        mission: str,
        robot: str = "",
        *,
        source: str = "",
        progress: Progress | None = None,
    ) -> T_co:
        """Parse `lines` as mission `mission`."""


def read_text(
    parse: LineParser[T_co],
    path: str | Path,
    mission: str | None = None,
    robot: str = "",
    progress: Progress | None = None,
) -> T_co:
    """`parse` the file at `path`, streamed, as one mission named after the
    file unless `mission`; errors name the file.

    Raises:
        MapImportError: a line is malformed (the message names it).
    """
    path = Path(path)
    with path.open(encoding="utf-8") as lines:
        return parse(lines, mission or path.stem, robot, source=str(path), progress=progress)


def check_arity(parts: list[str], arity: Mapping[str, int], source: str, line: int) -> str:
    """The tag of a record split in `parts`, once it is known and has as many
    values as `arity` says.

    Raises:
        MapImportError: an unknown tag or a wrong number of values.
    """
    tag = parts[0]
    wanted = arity.get(tag)
    if wanted is None:
        raise MapImportError(
            f"unsupported record {tag!r}; expected one of {', '.join(arity)}",
            source=source,
            line=line,
        )
    if len(parts) != wanted + 1:
        raise MapImportError(
            f"{tag} needs {wanted} values, found {len(parts) - 1}", source=source, line=line
        )
    return tag
