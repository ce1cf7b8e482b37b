"""Named views kept in the repository between commands: git's index for maps.

`mapctl view open` records a begin time; `set`/`rm` stage changes; `commit`
commits them. A failed commit keeps the non-conflicting changes and records
the conflicts in the view, begun again at the time the conflicts were seen;
`resolve` picks a side per conflict and `commit` runs again (DESIGN §9).
Every mutation of a view happens under the store's write lock, so two
processes working on one view cannot lose each other's staged changes.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager

from mapapi.core import codec
from mapapi.core.errors import ConflictError, UnresolvedConflicts, UsageError, ViewClosedError
from mapapi.core.history import CommitRecord
from mapapi.core.ids import ChunkId, ItemId
from mapapi.core.transaction import Isolation, Transaction
from mapapi.core.view import Side, View, discards, mapctl_in, settle
from mapapi.service.peer import Peer
from mapapi.service.stale import StaleReads


class Workspace:
    """The views of one peer's repository."""

    def __init__(self, peer: Peer) -> None:
        self.peer = peer
        self._view_locks: dict[str, asyncio.Lock] = {}

    # -- persistence ---------------------------------------------------------
    def get(self, name: str) -> View | None:
        """The view called `name`, or None."""
        blob = self.peer.store.load_view(name)
        if blob is None:
            return None
        return codec.decode_view(blob)

    def _save(self, view: View) -> None:
        self.peer.store.save_view(view.name, codec.encode_view(view))

    @contextmanager
    def _editing(self, name: str, *, create: bool = True) -> Iterator[View]:
        """Load (or open at now) a view under the write lock, save it after."""
        with self.peer.store.exclusive():
            view = self.get(name)
            if view is None:
                if not create:
                    raise ViewClosedError(
                        f"no open view {name!r}; run `{mapctl_in(name)} view open`"
                    )
                view = View(name, self.peer.now())
            yield view
            self._save(view)

    def views(self) -> list[View]:
        """Every view, by name."""
        return [v for n in sorted(self.peer.store.views()) if (v := self.get(n)) is not None]

    def open(
        self,
        name: str,
        at: int | None = None,
        isolation: Isolation = "snapshot",
        stale: bool = False,
    ) -> View:
        """Begin a view now, or at the past logical time `at`, or (`stale`) on this
        peer's replicas as they are (`service/stale.py`).

        Raises:
            ViewClosedError: the view exists and holds staged changes or conflicts.
        """
        tx = self.peer.begin(at, isolation=isolation, stale=stale)  # validates `at`
        with self.peer.store.exclusive():
            old = self.get(name)
            if old is not None and (old.changes or old.conflicts):
                raise ViewClosedError(
                    f"view {name!r} has {len(old.changes)} staged change(s) and "
                    f"{len(old.conflicts)} conflict(s); commit or "
                    f"`{mapctl_in(name)} view abort` first"
                )
            view = View(name, tx.begin_time, isolation, stale=stale)
            self._save(view)
        return view

    def abort(self, name: str) -> None:
        """Drop a view with its staged changes and conflicts."""
        if self.get(name) is None:
            raise ViewClosedError(f"no open view {name!r}; `mapctl view list` shows the open views")
        self.peer.store.delete_view(name)

    # -- reads and staging -----------------------------------------------------
    def transaction(self, view: View) -> Transaction:
        """A live transaction equivalent to the view."""
        backend = StaleReads(self.peer) if view.stale else self.peer
        tx = Transaction(
            backend, view.begin_time, self.peer.id, isolation=view.isolation, view=view.name
        )
        for change in view.changes:
            tx.stage(change)
        tx.note_reads(view.read_set, view.scopes)
        return tx

    def reader(self, name: str, at: int | None = None) -> Transaction:
        """What `get`/`ls` read through: the view if open (and no `at`), else the map."""
        view = self.get(name) if at is None else None
        return self.transaction(view) if view is not None else self.peer.begin(at)

    def remember_reads(self, name: str, tx: Transaction) -> None:
        """Keep what `tx` read in view `name`, if it is an open serializable view,
        so the commit validates reads made by earlier commands too."""
        with self.peer.store.exclusive():
            view = self.get(name)
            if view is None or view.isolation != "serializable":
                return
            view.read_set |= tx.read_set
            view.scopes |= tx.scopes
            self._save(view)

    async def pin(self, name: str, item_id: ItemId) -> None:
        """Before view `name` writes an item it may not have read: make the item's
        chunk final up to the view's time (in a swarm, `Peer.pin` closes its log
        there, best effort), so a commit to it from now on, on any peer, is
        stamped past the view and found as its conflict. Without this a blind
        write would take a commit made meanwhile on a peer with a slower Lamport
        clock as already seen, and overwrite it."""
        view = self.get(name)
        if view is not None and view.stale:
            return  # it asks no one (a commit built on a stale read conflicts at the leader)
        await self.peer.pin(item_id, self.peer.now() if view is None else view.begin_time)

    def stage_set(
        self, name: str, table: str, data: str, item_id: ItemId | None, chunk: ChunkId | None
    ) -> ItemId:
        """Stage an insert (no `item_id`) or an update of JSON `data`."""
        descriptor = self.peer.table(table)
        message = descriptor.from_json(data)
        with self._editing(name) as view:
            tx = self.transaction(view)
            if item_id is None:
                item_id = tx.insert(table, message, chunk or self._default_chunk(table))
            else:
                if chunk is not None:
                    raise UsageError("--chunk only applies to inserts (no ID given)")
                tx.update(table, item_id, message)
            view.changes = tx.changes
        return item_id

    def stage(self, name: str, write: Callable[[Transaction], None]) -> None:
        """Stage in view `name` (opened if need be) what `write` buffers in the
        view's transaction: a program's edit of several items at once."""
        with self._editing(name) as view:
            tx = self.transaction(view)
            write(tx)
            view.changes = tx.changes

    def _default_chunk(self, table: str) -> ChunkId:
        chunks = self.peer.chunks(table)
        if len(chunks) == 1:
            return chunks[0].id
        if not chunks:
            raise UsageError(f"table {table!r} has no chunk; run `mapctl chunk create {table}`")
        raise UsageError(f"table {table!r} has {len(chunks)} chunks; pass --chunk ID")

    def stage_remove(self, name: str, table: str, item_id: ItemId) -> None:
        """Stage the removal of an item."""
        with self._editing(name) as view:
            tx = self.transaction(view)
            tx.remove(table, item_id)
            view.changes = tx.changes

    # -- commit and conflicts -----------------------------------------------
    async def commit(self, name: str, message: str) -> CommitRecord | None:
        """Commit a view's staged changes; the view closes on success.

        Returns:
            The commit record, or None when the open view had nothing to write
            (say every conflict was resolved as theirs); the view closes too.

        Raises:
            UsageError: no such view.
            UnresolvedConflicts: the view still holds conflicts.
            ConflictError: the commit conflicted; the view now holds the
                conflicts plus the non-conflicting changes, begun again.
        """
        if self.peer.swarm is None:
            # Alone, other processes may work on the same views: hold the store's
            # write lock throughout (the local commit never awaits the network).
            # A conflict is raised only after the block, so the saved conflicts stay.
            with self.peer.store.exclusive():
                try:
                    return await self._commit(name, message)
                except ConflictError as err:
                    failure = err
            raise failure
        # In a swarm the peer daemon is the only writer of its store, and the
        # commit awaits other peers: serialise per view with an asyncio lock, never
        # hold SQLite's write lock across an await.
        async with self._view_locks.setdefault(name, asyncio.Lock()):
            return await self._commit(name, message)

    async def _commit(self, name: str, message: str) -> CommitRecord | None:
        view = self.get(name)
        if view is None:
            raise UsageError(f"nothing to commit in view {name!r}; stage changes with `set`")
        # Conflicts first: a failed commit may leave nothing staged but conflicts.
        if view.conflicts:
            raise UnresolvedConflicts(
                f"view {name!r} has {len(view.conflicts)} unresolved conflict(s); "
                f"run `{mapctl_in(name)} diff`, then `{mapctl_in(name)} resolve`"
            )
        if not (view.changes or view.isolation == "serializable"):
            self.peer.store.delete_view(name)
            return None
        try:
            record = await self.transaction(view).commit(message)
        except ConflictError as err:
            merged = err.merge()
            view.begin_time, view.changes = merged.begin_time, merged.changes
            view.read_set, view.scopes = set(), set()  # reads were of the old snapshot
            view.conflicts = err.conflicts
            self._save(view)
            err.name_view(mapctl_in(name))
            raise
        self.peer.store.delete_view(name)
        return record

    def resolve(
        self,
        name: str,
        side: Side,
        item_ids: Iterable[ItemId] = (),
        edited: dict[ItemId, bytes] | None = None,
        *,
        force: bool = False,
    ) -> list[ItemId]:
        """Settle conflicts: keep `side`, or the `edited` payload where given.

        "ours" is what the view has staged now: an edit staged after the
        conflict wins over the side that conflicted.

        Args:
            item_ids: which conflicts (all when empty); prefixes are not expanded here.
            edited: item -> payload that replaces both sides.
            force: discard edits staged after the conflict where the resolution
                replaces them; without it such a resolution is refused.

        Returns:
            The items resolved.

        Raises:
            UsageError: an id without conflict, or an edit staged after the
                conflict would be discarded (nothing is resolved then).
        """
        edited = edited or {}
        with self._editing(name, create=False) as view:
            wanted = set(item_ids) or {c.item_id for c in view.conflicts}
            unknown = wanted - {c.item_id for c in view.conflicts}
            if unknown:
                raise UsageError(f"no conflict on item(s) {', '.join(sorted(unknown))}")
            staged = view.staged_since_conflict()
            settled = {
                c.item_id: settle(c, staged.get(c.item_id), side, edited.get(c.item_id))
                for c in view.conflicts
                if c.item_id in wanted
            }
            lost = sorted(i for i, change in settled.items() if discards(staged.get(i), change))
            if lost and not force:
                raise UsageError(_refusal(name, side, sorted(item_ids), lost, bool(edited)))
            tx = self.transaction(view)
            for item_id, change in settled.items():
                if change is None:
                    tx.unstage(item_id)
                else:
                    tx.stage(change)
            view.changes = tx.changes
            view.conflicts = [c for c in view.conflicts if c.item_id not in wanted]
        return sorted(wanted)


def _refusal(name: str, side: Side, given: list[ItemId], lost: list[ItemId], edited: bool) -> str:
    """One line: which staged edits a resolution would discard, and what to run."""
    mapctl, ids = mapctl_in(name), "".join(f" {i}" for i in given)
    items = f"item {lost[0]} holds" if len(lost) == 1 else f"items {', '.join(lost)} hold"
    if edited:  # only an interactive resolve edits; it shows the staged edit first
        return (
            f"{items} an edit staged after the conflict, which the edited payload would "
            f"replace; run `{mapctl} resolve{ids}` again on a terminal to edit from it"
        )
    return (
        f"{items} an edit staged after the conflict, which --{side} would discard; "
        f"run `{mapctl} resolve --{side} --force{ids}` to discard it, "
        f"or `{mapctl} resolve --ours{ids}` to keep it"
    )
