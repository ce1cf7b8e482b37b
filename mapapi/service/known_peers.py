"""Where a restarted peer daemon rejoins: the members it last knew (issue 7 §3).

The daemon keeps the addresses of the swarm's other members in
`.mapapi/members.json` while it runs. Started again without `--join` (after a
crash, a reboot, or `peer stop`), it joins through them, so it rejoins the
swarm and catches up on its shared chunks by itself.
"""

from __future__ import annotations

import json
import logging
import os
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
