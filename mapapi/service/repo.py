"""The repository on disk: `<repo>/.mapapi/` with config, identity and store (DESIGN §9).

Its config is `repo_config.py`; the lock a running daemon holds on it is `peer_lock.py`.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from mapapi.core.errors import (
    AlreadyInitialisedError,
    ConfigLost,
    CorruptRepoError,
    NotARepoError,
    RepoError,
    UsageError,
)
from mapapi.core.ids import PeerId
from mapapi.lookup.spatial import SpatialGrid
from mapapi.service.recover import RecoveredIdentity, recover_identity
from mapapi.service.repo_config import FIX_CONFIG, RepoConfig
from mapapi.store.sqlite import SqliteStore
from mapapi.store.sqlite_labelled import LabelledSqliteStore

if TYPE_CHECKING:
    from mapapi.net.security import Security
    from mapapi.store.labels import Labels

REPO_DIR = ".mapapi"
CONFIG = "config.toml"
STORE = "store.sqlite"
PID_FILE = "peer.pid"  # the running peer daemon: pid, id, addresses (mapapi.service.daemon)
PEER_LOCK = "peer.lock"  # held (flock) by the daemon for as long as it runs
PEER_LOG = "peer.log"  # a detached daemon's stdout and stderr
CONTROL_SOCKET = "control.sock"  # the daemon's local control endpoint (ipc)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PeerRecord:
    """What `.mapapi/peer.pid` says about the running peer daemon (`mapapi.service.daemon`).

    Attributes:
        pid: the daemon's process id.
        id: its peer id.
        name: its peer name.
        address: where the swarm reaches it.
        join: the exact string another peer passes to `--join` (its address).
        control: its local control endpoint (`mapapi.service.control`).
        started: when it started serving (Unix time).
    """

    pid: int
    id: str
    name: str
    address: str
    join: str
    control: str
    started: float

    def to_json(self) -> str:
        """The record as one JSON document."""
        return json.dumps(asdict(self))


class Repository:
    """A map repository folder.

    The peer daemon of a repository holds an exclusive `flock` on
    `.mapapi/peer.lock` while it runs. That lock, not the pid, tells a live
    daemon from a stale pid file: the kernel drops it when the process ends,
    however it ends (SIGKILL, a crash), and a recycled pid cannot fake it.
    """

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

    @property
    def pid_path(self) -> Path:
        """Where the running peer daemon describes itself."""
        return self.meta_dir / PID_FILE

    @property
    def lock_path(self) -> Path:
        """The file the running peer daemon keeps locked."""
        return self.meta_dir / PEER_LOCK

    @property
    def log_path(self) -> Path:
        """A detached peer daemon's log."""
        return self.meta_dir / PEER_LOG

    @property
    def control_path(self) -> Path:
        """The daemon's control socket (when the path fits an ipc endpoint)."""
        return self.meta_dir / CONTROL_SOCKET

    @classmethod
    def init(
        cls,
        path: str | Path,
        name: str | None = None,
        spatial: SpatialGrid | None = None,
        *,
        secure: bool = False,
    ) -> Repository:
        """Create a repository in `path` (created if missing), with the spatial
        index geometry `spatial` (default: `mapapi.lookup.spatial.DEFAULT_BOUNDS` and
        `DEFAULT_CELLS`); `secure` also makes its keypair and empty trust list.

        Raises:
            AlreadyInitialisedError: `path` already holds one.
        """
        root = Path(path).resolve()
        meta = root / REPO_DIR
        if (meta / CONFIG).exists():
            raise AlreadyInitialisedError(
                f"{root} is already a map repository; use it as is, or init another folder"
            )
        _refuse_a_kept_store(meta / STORE)
        meta.mkdir(parents=True, exist_ok=True)
        # A secure peer's id is derived from its key (docs/design.md "Secure swarm"),
        # so every peer can check which id a connection's key may speak as.
        peer_id = _make_keys(meta).peer_id if secure else PeerId.new()
        config = RepoConfig(
            name=name or root.name,
            peer_id=peer_id,
            spatial=spatial or SpatialGrid(),
            secure=secure,
        )
        SqliteStore(meta / STORE, create=True).close()
        _write_config(meta, config)  # last: its presence means "initialised"
        return cls(root, config)

    @classmethod
    def recover(
        cls,
        path: str | Path,
        name: str | None = None,
        spatial: SpatialGrid | None = None,
        *,
        peer_id: str | None = None,
    ) -> tuple[Repository, RecoveredIdentity]:
        """Rebuild the lost config of the repository in `path` from its store:
        the peer id and name (`mapapi.service.recover`), secure if its keypair
        is there; `spatial` (the default otherwise) is not in the store.

        Raises:
            AlreadyInitialisedError: the config is there: nothing to recover.
            NotARepoError: there is no store to recover from.
            UsageError: the store cannot tell the peer id (give `peer_id`).
        """
        from mapapi.net.security import KEY_DIR

        root = Path(path).resolve()
        meta = root / REPO_DIR
        if (meta / CONFIG).exists():
            raise AlreadyInitialisedError(
                f"{meta / CONFIG} is there: nothing to recover; use the repository as is"
            )
        if not (meta / STORE).exists():
            raise NotARepoError(
                f"no store to recover from in {meta}: `mapctl init` makes a new repository"
            )
        store = SqliteStore(meta / STORE)
        try:
            identity = recover_identity(store, peer_id)
        finally:
            store.close()
        config = RepoConfig(
            name=name or identity.name or root.name,
            peer_id=identity.peer_id,
            spatial=spatial or SpatialGrid(),
            secure=(meta / KEY_DIR).is_dir(),
        )
        _write_config(meta, config)
        return cls(root, config), identity

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
                    raise CorruptRepoError(f"{config} is damaged: {exc}; {FIX_CONFIG}") from exc
                except OSError as exc:
                    raise RepoError(
                        f"cannot read {config}: {exc.strerror or exc}; check its owner and "
                        "permissions (`ls -l`), or run mapctl as the user that owns the repository"
                    ) from exc
                return cls(folder, RepoConfig.from_toml(text, config))
        raise NotARepoError(
            f"not a map repository (or any parent): {here}; run `mapctl init` first"
        )

    def make_secure(self) -> None:
        """Make this open repository secure: a keypair and an empty trust list.
        Its data and its peer id are kept (its chunks' holder sets name that id),
        so the id is not derived from the key: other peers bind it to the key
        (`mapctl trust add KEY --id ID`, as `mapctl key show` prints). Its peer
        must be restarted to use them.

        Raises:
            UsageError: it is secure already, or its peer runs.
        """
        if self.config.secure:
            raise UsageError(f"{self.root} is a secure repository already")
        record = self.running_peer()
        if record is not None:
            raise UsageError(
                f"a peer runs on {self.root} (pid {record.pid}); stop it with "
                "`mapctl peer stop` before making the repository secure"
            )
        _make_keys(self.meta_dir)
        config = replace(self.config, secure=True)
        _write_config(self.meta_dir, config)
        self.config = config

    def security(self) -> Security | None:
        """The keypair and trust list of a secure repository; None for an open one.

        Raises:
            CorruptRepoError: the repository is secure but its secret key is
                missing or readable by other users.
        """
        if not self.config.secure:
            return None
        from mapapi.net.security import Security

        # An id that is not derived from the key (a repository made secure before
        # ids were, or by `make_secure`) stays this peer's id; the others bind it.
        return Security.load(self.meta_dir, self.config.peer_id)

    def open_store(self, labels: Labels | None = None) -> SqliteStore:
        """Open the repository's store; with `labels`, one that keeps their
        index (`mapapi.store.sqlite_labelled`)."""
        if labels is not None:
            return LabelledSqliteStore(self.store_path, labels)
        return SqliteStore(self.store_path)

    def is_empty(self) -> bool:
        """True while the repository holds no table, chunk or commit (as `init` left it)."""
        store = self.open_store()
        try:
            return not (store.tables() or store.chunks() or store.commits(limit=1))
        finally:
            store.close()

    # -- the peer daemon's pid file and lock -------------------------------------------
    def read_peer_record(self) -> PeerRecord | None:
        """The pid file's record, or None if there is none (or it is unreadable)."""
        try:
            return PeerRecord(**json.loads(self.pid_path.read_text(encoding="utf-8")))
        except FileNotFoundError:
            return None
        except (OSError, ValueError, TypeError) as exc:
            log.warning("ignoring the unreadable pid file %s: %s", self.pid_path, exc)
            return None

    def write_peer_record(self, record: PeerRecord) -> None:
        """Write the pid file atomically (readers see the old file or the new one)."""
        tmp = self.pid_path.with_name(f"{self.pid_path.name}.{os.getpid()}.tmp")
        tmp.write_text(record.to_json() + "\n", encoding="utf-8")
        tmp.replace(self.pid_path)

    def remove_peer_record(self, pid: int | None = None) -> None:
        """Remove the pid file (only if it is still the one of process `pid`, if given)."""
        record = self.read_peer_record()
        if record is not None and pid in (None, record.pid):
            self.pid_path.unlink(missing_ok=True)

    def peer_locked(self) -> bool:
        """True while a peer daemon process runs here (it holds `peer.lock`)."""
        import fcntl

        try:
            fd = os.open(self.lock_path, os.O_RDONLY)
        except FileNotFoundError:
            return False
        try:
            # A shared lock is granted unless a daemon holds its exclusive one; this
            # probe holds it for microseconds (PeerLock.acquire retries meanwhile).
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        finally:
            os.close(fd)  # also drops the probe's shared lock
        return False

    def running_peer(self) -> PeerRecord | None:
        """The record of the peer daemon running here; None when none runs (a stale
        pid file, left by a process that is gone, counts as none)."""
        record = self.read_peer_record()
        return record if record is not None and self.peer_locked() else None

    def stale_peer_record(self) -> PeerRecord | None:
        """The pid file's record if its daemon is gone, else None."""
        record = self.read_peer_record()
        return record if record is not None and not self.peer_locked() else None


def _write_config(meta: Path, config: RepoConfig) -> None:
    """Write `config.toml` atomically (readers see the old file or the new one)."""
    tmp = meta / (CONFIG + ".tmp")
    tmp.write_text(config.to_toml(), encoding="utf-8")
    tmp.replace(meta / CONFIG)


def _refuse_a_kept_store(path: Path) -> None:
    """Refuse to `init` over a store that holds a map but lost its config: a new
    peer id would lock the peer out of its own chunks. An empty store (an `init`
    that stopped before writing the config) is taken over.

    Raises:
        ConfigLost: naming what the store holds and how to recover.
    """
    if not path.exists() or not path.stat().st_size:
        return
    store = SqliteStore(path)
    try:
        commits, chunks = len(store.commits()), len(store.chunks())
        tables = len(store.tables())
    finally:
        store.close()
    if commits or chunks or tables:
        raise ConfigLost(
            f"{path.parent} has no {CONFIG}, but its store holds a map ({commits} commit(s), "
            f"{chunks} chunk(s), {tables} table(s)); a new peer id would lock this peer out "
            "of its own chunks: run `mapctl init --recover` to rebuild the config from the "
            "store (or move the store away to start afresh)"
        )


def _make_keys(meta: Path) -> Security:
    """The keypair and empty trust list of a new secure repository; `.mapapi/` is
    made private (0700): it holds the secret key, the store and the control socket."""
    from mapapi.net.security import Security

    meta.chmod(0o700)
    return Security.create(meta)
