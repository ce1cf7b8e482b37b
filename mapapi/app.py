"""The application: a peer with the map tables' rules, and the full operation
table (the service's sets and the maps'), composed here, above both layers.

The service layer knows nothing of maps: `Peer` takes its commit rules, and the
peer daemon its peer and operations factories, as constructor arguments. This
module gives them the application's, and is what `mapctl`, `mapapi.testing`
and the benchmarks build peers and daemons with, so the mission rules (a vertex
index is unique in its mission, an edge's ends exist) hold wherever map data is
written through them, and their SQLite stores index and summarise every
mission's rows (`maps.labels`). A script that builds a bare `Peer` writes
without the rules, and reads missions by reading whole tables (a store it wrote
to is labelled again when a peer built here next opens it).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from mapapi.maps.align_ops import AlignOperations
from mapapi.maps.grid_ops import GridOperations
from mapapi.maps.labels import map_labels
from mapapi.maps.operations import MapOperations
from mapapi.maps.rules import map_rules
from mapapi.service import daemon, daemon_process
from mapapi.service.control import RemoteOperations
from mapapi.service.fsck import FsckOperations
from mapapi.service.gc import GcOperations
from mapapi.service.ops import DaemonOperations, Operations, RepoOperations
from mapapi.service.peer import Peer
from mapapi.service.repo import Repository
from mapapi.service.transfer_ops import SwarmOperations
from mapapi.service.view_ops import ViewOperations
from mapapi.service.watch_ops import WatchOperations
from mapapi.service.workspace import Workspace

if TYPE_CHECKING:
    from mapapi.service.loop_lag import LoopLag
    from mapapi.service.repo import PeerRecord


def peer_of(repo: Repository) -> Peer:
    """The peer of `repo`, keeping the map tables' rules at every commit, and
    their labels (each mission's rows indexed and summarised) in its store."""
    return Peer.of(repo, rules=map_rules(), labels=map_labels())


def open_peer(path: str | Path = ".") -> Peer:
    """The peer of the repository at (or above) `path`, with the map tables' rules."""
    return peer_of(Repository.find(path))


def memory_peer() -> Peer:
    """A scratch peer on a memory store, with the map tables' rules."""
    return Peer.in_memory(rules=map_rules())


def operations(
    peer: Peer,
    *,
    on_shutdown: Callable[[], None] | None = None,
    loop_lag: LoopLag | None = None,
) -> Operations:
    """Every operation `mapctl` runs, over `peer`: the repository's, the views',
    the swarm's (`peer status` with the daemon's `loop_lag`), watches, the maps'
    and (`on_shutdown` given: in a daemon) `shutdown`."""
    views = Workspace(peer)  # one per peer: it serialises the commits of each view
    grids = GridOperations(peer)
    return Operations(
        peer,
        (
            RepoOperations(peer),
            ViewOperations(peer, views),
            SwarmOperations(peer, loop_lag),
            WatchOperations(peer),
            MapOperations(peer, grids),
            AlignOperations(peer, views),
            grids,
            DaemonOperations(on_shutdown),
            FsckOperations(peer),
            GcOperations(peer),
        ),
    )


def attach(path: str | Path) -> Operations | RemoteOperations:
    """The operations of the repository at (or above) `path`: its running peer
    daemon's, over the control endpoint, else over its peer opened here (the
    caller closes its store)."""
    repo = Repository.find(path)
    record = repo.running_peer()
    if record is not None:
        return RemoteOperations.of(repo, record, alive=repo.peer_locked)
    return operations(peer_of(repo))


def run_daemon(
    repo: Repository,
    listen: str = "tcp://127.0.0.1:0",
    join: Sequence[str] = (),
    *,
    advertise: str | None = None,
    ready: Callable[[PeerRecord], None] | None = None,
) -> None:
    """Serve the peer of `repo` in the foreground until a signal or `peer stop`
    (`mapapi.service.daemon.run` with the application's peer and operations).

    The map jobs' modules (numpy, the readers) are imported now: imported at
    the first export, they would hold the event loop for a few hundred ms."""
    import mapapi.maps.jobs  # noqa: F401

    daemon.run(
        repo,
        listen,
        join,
        open_peer=peer_of,
        operations=operations,
        advertise=advertise,
        ready=ready,
    )


def start_daemon(
    repo: Repository,
    listen: str = "tcp://127.0.0.1:0",
    join: Sequence[str] = (),
    *,
    advertise: str | None = None,
    verbose: bool = False,
) -> PeerRecord:
    """Start the peer daemon of `repo` in the background (`mapctl peer start` in a
    new session); its record once it serves."""
    argv = daemon_process.daemon_command(repo, listen, join, advertise, verbose)
    return daemon_process.spawn_detached(repo, argv)
