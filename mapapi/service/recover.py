"""Rebuilding a lost `config.toml` from the store (`mapctl init --recover`, issue 18).

The config holds the peer's id, its name, the spatial index geometry and
whether it is secure. A new id over an old store locks the peer out of its own
chunks (their holder sets name the old id), so `init` refuses a folder whose
store holds a map and no config, and `--recover` finds the old id again.

What the store keeps, and what it does not:

- The id: the store has no record of its own. But a peer stores only the
  chunks it holds, and every chunk's holder set names it, so the id is the one
  peer every holder set shares. When no chunk has a holder set, or several
  peers hold every chunk, the store cannot tell: `--peer-id` says which.
- The name: each commit records its writer's name; the recovered id's newest
  commit gives it (else the folder's name, as `init` does).
- Secure or open: the keypair in `.mapapi/curve/` survives the config's loss.
- The spatial index geometry is nowhere in the store: `--bounds`/`--cells`
  must repeat the swarm's (the default otherwise), else joining is refused.
"""

from __future__ import annotations

from dataclasses import dataclass

from mapapi.core.errors import UsageError
from mapapi.core.ids import PeerId
from mapapi.store.sqlite import SqliteStore


@dataclass(frozen=True)
class RecoveredIdentity:
    """What the store says about the peer that kept it.

    Attributes:
        peer_id: its id.
        name: its name as its newest commit recorded it ("" if it wrote none).
        how: how the id was found, for the person who asked.
    """

    peer_id: PeerId
    name: str
    how: str


def recover_identity(store: SqliteStore, peer_id: str | None = None) -> RecoveredIdentity:
    """The id and name of the peer whose store `store` is.

    Args:
        peer_id: the id, when the person knows it (it must hold every chunk).

    Raises:
        UsageError: the store cannot tell the id (it says exactly why, and
            which ids are candidates), or `peer_id` holds no chunk of it.
    """
    holdings = store.holdings()
    chunks = [c.id for c in store.chunks()]
    held = [set(holdings.get(c, ())) for c in chunks if holdings.get(c)]
    candidates = sorted(set.intersection(*held)) if held else []
    if peer_id is not None:
        wanted = PeerId(peer_id)
        if held and wanted not in candidates:
            raise UsageError(
                f"peer id {wanted} does not hold every chunk of this store "
                f"(ids that do: {', '.join(candidates) or 'none'})"
            )
        return RecoveredIdentity(wanted, _name(store, wanted), "as given (--peer-id)")
    if len(candidates) == 1:
        how = f"the one holder of all {len(held)} chunk(s) with a holder set"
        return RecoveredIdentity(candidates[0], _name(store, candidates[0]), how)
    if not held:
        why = f"none of its {len(chunks)} chunk(s) records its holders"
    else:
        why = f"{len(candidates)} peers hold every chunk ({', '.join(candidates)})"
    raise UsageError(
        f"cannot recover the peer id from the store: {why}, and the store keeps no "
        "record of its own id; give it with `mapctl init --recover --peer-id ID` (another "
        "peer of the swarm lists it: `mapctl peers`, or `mapctl log --json` for authors)"
    )


def _name(store: SqliteStore, peer_id: PeerId) -> str:
    """The name the peer's newest commit recorded ("" if none did)."""
    for record in store.commits():
        if record.author == peer_id and record.author_name:
            return record.author_name
    return ""
