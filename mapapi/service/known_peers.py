"""Where a restarted peer daemon rejoins: the members it last knew (issue 7 §3).

The daemon keeps the addresses of the swarm's other members in
`.mapapi/members.json` while it runs. Started again without `--join` (after a
crash, a reboot, or `peer stop`), it joins through them, so it rejoins the
swarm and catches up on its shared chunks by itself.

It also keeps the endpoint it listened on (`.mapapi/listen`), and listens there
again when that port is free (consensus issue): after every peer of a swarm
stopped, each one's remembered addresses of the others are still right, so the
swarm re-forms without a manual `join`.
"""

from __future__ import annotations

import json
import logging
import os
import socket
from collections.abc import Iterable

from mapapi.service.repo import Repository

log = logging.getLogger(__name__)

FILE = "members.json"


def recall(repo: Repository) -> list[str]:
    """The member addresses last remembered for `repo` (none if never, or unreadable)."""
    path = repo.meta_dir / FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return []
    except (OSError, ValueError) as exc:
        log.warning("ignoring the unreadable %s: %s", path, exc)
        return []
    addresses = data.get("addresses") if isinstance(data, dict) else None
    if not isinstance(addresses, list):
        log.warning("ignoring %s: it lists no addresses", path)
        return []
    return [a for a in addresses if isinstance(a, str) and a]


def remember(repo: Repository, addresses: Iterable[str]) -> None:
    """Replace the remembered addresses, atomically (a reader sees old or new)."""
    path = repo.meta_dir / FILE
    tmp = path.with_name(f"{FILE}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps({"addresses": sorted(set(addresses))}) + "\n", encoding="utf-8")
    tmp.replace(path)


LISTEN_FILE = "listen"


def remember_listen(repo: Repository, bound: str) -> None:
    """Keep the endpoint this peer listens on (e.g. tcp://127.0.0.1:41235)."""
    path = repo.meta_dir / LISTEN_FILE
    tmp = path.with_name(f"{LISTEN_FILE}.{os.getpid()}.tmp")
    tmp.write_text(bound + "\n", encoding="utf-8")
    tmp.replace(path)


def preferred_listen(repo: Repository, listen: str) -> str:
    """`listen`, or, when it asks for any port (`:0`) on the host this peer last
    listened on, that same endpoint again if its port is free now."""
    try:
        last = (repo.meta_dir / LISTEN_FILE).read_text(encoding="utf-8").strip()
    except OSError:
        return listen
    host, _, port = listen.rpartition(":")
    last_host, _, last_port = last.rpartition(":")
    if port != "0" or host != last_host or not last_port.isdigit():
        return listen
    return last if _free(host.removeprefix("tcp://"), int(last_port)) else listen


def _free(host: str, port: int) -> bool:
    """Whether `host:port` can be bound now (a probe; the peer binds right after)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as zmq binds
        try:
            probe.bind((host, port))
        except OSError:
            return False
    return True
