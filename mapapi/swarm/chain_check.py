"""Does a chunk's stored history still match its hash chain (issue 18 §3)?

Every commit applied from a chunk's log left a link (`core/chain.py`).
`check_chain` recomputes each link from the commit's record and revisions as
stored now: a payload changed on disk, a commit gone (a rolled-back file), a
link that does not follow from the one before, or a commit of the chunk with no
link (written into the file behind the store's back) is reported, never
repaired silently. Holders compare their heads with `chain_watch.ChainWatch`,
and a chunk's leader takes in no new holder while its replica no longer matches
its chain (`refuse_to_hand_on`).
"""

from __future__ import annotations

import logging

from mapapi.core import chain
from mapapi.core.errors import CorruptRepoError
from mapapi.core.ids import ChunkId, PeerId
from mapapi.store.base import ReplicaStore
from mapapi.store.offload import off_loop

log = logging.getLogger(__name__)


async def refuse_to_hand_on(store: ReplicaStore, chunk: ChunkId, me: PeerId) -> None:
    """Refuse to take a new holder of `chunk` in while this replica's history no
    longer matches its hash chain: the newcomer receives this replica's state (a
    snapshot) or its log, and rebuilds the chain from the history it receives, so
    what it gets must be what the chain says (issue 18 §3). The chain is rebuilt
    off the event loop.

    Raises:
        CorruptRepoError: it does not (logged here; the newcomer asks another holder).
    """
    if await off_loop(store, _chain_holds, store, chunk):
        return
    problem = (
        f"chunk {chunk.short}: the history of this replica no longer matches its hash "
        f"chain, so it is not sent to another peer; run `mapctl fsck` on peer {me.short}"
    )
    log.error("%s", problem)
    raise CorruptRepoError(problem)


def _chain_holds(store: ReplicaStore, chunk: ChunkId) -> bool:
    """Whether the chunk's chain is a prefix of the one its history rebuilds (any
    thread). Read in this order, the history holds at least the chained commits:
    commits applied meanwhile only add links past them."""
    links = store.chain_links(chunk)
    revisions = store.chunk_revisions(chunk)
    commits = {c.id: c for c in store.chunk_commits(chunk)}
    try:
        rebuilt = chain.rebuild(chunk, commits, revisions, store.chain_base(chunk))
    except KeyError:  # a revision whose commit record is gone
        return False
    return rebuilt[: len(links)] == links


def check_chain(store: ReplicaStore, chunk: ChunkId) -> list[str]:
    """What is wrong with `chunk`'s history against its chain; empty when sound."""
    problems: list[str] = []
    base = store.chain_base(chunk)  # commits `gc` took revisions of: their links stand
    previous = base[-1][1] if base else chain.GENESIS
    links = store.chain_links(chunk)
    for commit_id, stored in links[len(base) :]:
        record = store.commit_record(commit_id)
        if record is None:
            problems.append(
                f"chunk {chunk.short}: commit {commit_id.short} of its chain is gone "
                "(the store was rolled back or damaged)"
            )
            previous = stored
            continue
        revisions = [r for r in store.commit_revisions(commit_id) if r.chunk_id == chunk]
        if chain.link(previous, chunk, record, revisions) != stored:
            problems.append(
                f"chunk {chunk.short}: commit {commit_id.short} no longer matches its link "
                "(its record or data changed after it was written)"
            )
        previous = stored
    linked = {commit_id for commit_id, _ in links}
    for record in store.chunk_commits(chunk):
        if record.id not in linked:
            problems.append(
                f"chunk {chunk.short}: commit {record.id.short} is in its history but not in "
                "its chain (it was written into the store behind its back)"
            )
    return problems
