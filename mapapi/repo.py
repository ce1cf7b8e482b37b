"""The repository on disk: `<repo>/.mapapi/` with config, identity and store (DESIGN §9)."""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mapapi.errors import AlreadyInitialisedError, CorruptRepoError, NotARepoError
from mapapi.ids import PeerId
from mapapi.store.sqlite import SqliteStore

REPO_DIR = ".mapapi"
CONFIG = "config.toml"
STORE = "store.sqlite"


def _toml_str(text: str) -> str:
    """`text` as a TOML basic string: JSON quoting without the surrogate-pair
    escapes TOML refuses (non-ASCII stays UTF-8), and DEL escaped (JSON leaves it raw)."""
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


@dataclass(frozen=True)
class RepoConfig:
    """What `config.toml` holds."""

    name: str
    peer_id: PeerId

    def to_toml(self) -> str:
        """The config as TOML text (flat keys; strings quoted as JSON, valid TOML)."""
        return f"name = {_toml_str(self.name)}\npeer_id = {_toml_str(str(self.peer_id))}\n"

    @classmethod
    def from_toml(cls, text: str, source: Path) -> RepoConfig:
        """Parse config text; raises CorruptRepoError naming `source`."""
        try:
            data: dict[str, Any] = tomllib.loads(text)
            return cls(name=str(data["name"]), peer_id=PeerId(data["peer_id"]))
        except (tomllib.TOMLDecodeError, KeyError, ValueError) as exc:
            raise CorruptRepoError(f"{source} is damaged: {exc}") from exc


class Repository:
    """A map repository folder."""

    def __init__(self, root: Path, config: RepoConfig) -> None:
        self.root = root
        self.config = config

    @property
    def meta_dir(self) -> Path:
        """The `.mapapi` folder."""
        return self.root / REPO_DIR

    @property
    def store_path(self) -> Path:
        """The SQLite store file."""
        return self.meta_dir / STORE

    @classmethod
    def init(cls, path: str | Path, name: str | None = None) -> Repository:
        """Create a repository in `path` (created if missing).

        Raises:
            AlreadyInitialisedError: `path` already holds one.
        """
        root = Path(path).resolve()
        meta = root / REPO_DIR
        if (meta / CONFIG).exists():
            raise AlreadyInitialisedError(
                f"{root} is already a map repository; use it as is, or init another folder"
            )
        meta.mkdir(parents=True, exist_ok=True)
        config = RepoConfig(name=name or root.name, peer_id=PeerId.new())
        SqliteStore(meta / STORE, create=True).close()
        tmp = meta / (CONFIG + ".tmp")
        tmp.write_text(config.to_toml(), encoding="utf-8")
        tmp.replace(meta / CONFIG)  # the config appears last: its presence means "initialised"
        return cls(root, config)

    @classmethod
    def find(cls, start: str | Path = ".") -> Repository:
        """The repository containing `start` (walking up like git).

        Raises:
            NotARepoError: none found.
        """
        here = Path(start).resolve()
        for folder in (here, *here.parents):
            config = folder / REPO_DIR / CONFIG
            if config.is_file():
                try:
                    text = config.read_text(encoding="utf-8")
                except UnicodeDecodeError as exc:
                    raise CorruptRepoError(f"{config} is damaged: {exc}") from exc
                return cls(folder, RepoConfig.from_toml(text, config))
        raise NotARepoError(
            f"not a map repository (or any parent): {here}; run `mapctl init` first"
        )

    def open_store(self) -> SqliteStore:
        """Open the repository's store."""
        return SqliteStore(self.store_path)
