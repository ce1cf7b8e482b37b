"""What `.mapapi/config.toml` holds (DESIGN §9): the peer's name and id, the
spatial index's geometry, whether the peer is secure; read and written as TOML."""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mapapi.core.errors import CorruptRepoError, MapError
from mapapi.core.ids import PeerId
from mapapi.lookup.spatial import SpatialGrid

_SECURE_TOML = (
    "\n# A secure peer (CurveZMQ): its keypair and trust list are in .mapapi/curve/.\n"
    "[security]\nsecure = true\n"
)
FIX_CONFIG = (
    "fix it in an editor (`mapctl init` in an empty folder writes a valid one to compare) "
    "or restore it from a backup"
)


def _toml_str(text: str) -> str:
    """`text` as a TOML basic string: JSON quoting without the surrogate-pair
    escapes TOML refuses (non-ASCII stays UTF-8), and DEL escaped (JSON leaves it raw)."""
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


@dataclass(frozen=True)
class RepoConfig:
    """What `config.toml` holds: the peer's name and id, the geometry of the
    spatial index (which every peer of a swarm must share, DESIGN §7), and
    whether the peer is secure (DESIGN §10; its keys are in `.mapapi/curve/`)."""

    name: str
    peer_id: PeerId
    spatial: SpatialGrid = field(default_factory=SpatialGrid)
    secure: bool = False
    retention: int | None = None  # [history] retention: `gc` keeps each item's newest N

    def to_toml(self) -> str:
        """The config as TOML text (strings quoted as JSON, valid TOML; floats
        written with repr, which round-trips exactly)."""
        grid = self.spatial.to_config()
        bounds = ", ".join(repr(float(v)) for v in grid["bounds"])
        cells = ", ".join(str(int(n)) for n in grid["cells"])
        return (
            (
                f"name = {_toml_str(self.name)}\npeer_id = {_toml_str(str(self.peer_id))}\n\n"
                f"# The spatial index: fixed bounds (xmin, ymin, zmin, xmax, ymax, zmax, metres)\n"
                f"# split into cells (nx, ny, nz). Every peer of a swarm must use the same.\n"
                f"[spatial]\nbounds = [{bounds}]\ncells = [{cells}]\n"
            )
            + (_SECURE_TOML if self.secure else "")
            + _history_toml(self.retention)
        )

    @classmethod
    def from_toml(cls, text: str, source: Path) -> RepoConfig:
        """Parse config text; raises CorruptRepoError naming `source` (a config
        without a ``[spatial]`` table gets the default index geometry)."""
        try:
            data: dict[str, Any] = tomllib.loads(text)
            spatial = data.get("spatial", {})
            security = data.get("security", {})
            history = data.get("history", {})
            if not all(isinstance(t, dict) for t in (spatial, security, history)):
                raise ValueError("[spatial], [security] and [history] must be tables")
            secure = security.get("secure", False)
            if not isinstance(secure, bool):
                raise ValueError("[security] secure must be true or false")
            return cls(
                name=str(data["name"]),
                peer_id=PeerId(data["peer_id"]),
                spatial=SpatialGrid.from_config(spatial),
                secure=secure,
                retention=_retention(history.get("retention")),
            )
        except (tomllib.TOMLDecodeError, KeyError, ValueError, MapError) as exc:
            raise CorruptRepoError(f"{source} is damaged: {exc}; {FIX_CONFIG}") from exc


def _history_toml(retention: int | None) -> str:
    if retention is None:
        return ""
    note = f"# `mapctl gc` keeps each item's newest {retention} revisions."
    return f"\n{note}\n[history]\nretention = {retention}\n"


def _retention(value: object) -> int | None:
    """`[history] retention`: how many revisions of each item `gc` keeps (None: unset)."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(
            f"[history] retention must be a whole number of revisions >= 1, not {value!r}"
        )
    return value
