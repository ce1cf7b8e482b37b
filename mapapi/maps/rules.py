"""The rules of a mission's pose graph, checked by the writer at every commit
(issue 15): a vertex index is unique in its mission, and an edge's ends exist.

`MissionRules` is a `CommitRule` every peer of the application (`mapapi.app`)
gets at construction (DESIGN "hooks passed in at construction"), so the rules
hold whoever commits through it: `mapctl set`, the daemon, a script that opens
`mapapi.open_peer`, an import. It runs on the writer's replicas: alone, inside
the store's exclusive section (two racing commits cannot both pass); in a
swarm, before the writer proposes to the chunks' logs, so two writers on two
peers racing on one mission can both pass (a holder decides a commit from its
replica of the chunk alone, and this rule reads other chunks).

Cost follows the commit: each rule keeps an index of the rows held here
(key -> items), brought up to date chunk by chunk from the revisions written
since it last looked (`changed_since`, per chunk: a chunk's commits arrive in
time order, its log's), then looks up each committed row's keys. A new
process reads each held chunk once on its first vertex or edge commit.

What cannot be judged here is let through: an edge end in another mission no
vertex of which this peer holds (an inter-robot edge to a robot not loaded).
A landmark observation's end is a landmark, not a vertex: only its pose is
checked.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING

from mapapi.maps.errors import MissionRuleError
from mapapi.maps.schema import EDGES, VERTICES, Edge, Vertex, edge_ends

if TYPE_CHECKING:
    from mapapi.core.change import Change
    from mapapi.core.history import Revision
    from mapapi.core.ids import ChunkId, ItemId
    from mapapi.store.base import Store
    from mapapi.swarm.commit_check import CommitRule

Key = tuple[str, int]  # (mission, vertex index)
KeysOf = Callable[[bytes], tuple[Key, ...]]


def vertex_keys(data: bytes) -> tuple[Key, ...]:
    """The (mission, index) a vertex payload takes ("" data: none, a removal)."""
    if not data:
        return ()
    vertex = Vertex.FromString(data)
    return ((vertex.mission, vertex.index),)


def edge_keys(data: bytes) -> tuple[Key, ...]:
    """The vertices an edge payload ends at: (from, to); a landmark
    observation's `to` names a landmark, so only (from,)."""
    if not data:
        return ()
    edge = Edge.FromString(data)
    ends = edge_ends(edge)
    return ends[:1] if edge.kind == Edge.Kind.LANDMARK else ends


class KeyIndex:
    """key -> items of one table's rows held here, kept up to date incrementally.

    It holds an entry per row of every mission held, so it is kept lean (a
    daemon's memory grew by 9 MB per 13.6k-vertex mission with a set per key and
    a tuple of tuples per item): a key's items are one `ItemId` or a tuple of
    several, an item's keys one flat tuple (mission, index, mission, index, ...)
    that is the key itself for a vertex, and mission names are shared.
    """

    def __init__(self, table: str, keys_of: KeysOf) -> None:
        self.table = table
        self.keys_of = keys_of
        self._seen: dict[ChunkId, int] = {}  # chunk -> newest update time read
        self._in_chunk: dict[ChunkId, list[ItemId]] = defaultdict(list)
        self._keys: dict[ItemId, tuple[str | int, ...]] = {}
        self._items: dict[Key, ItemId | tuple[ItemId, ...]] = {}
        self._names: dict[str, str] = {}
        self._missions: Counter[str] = Counter()  # rows per mission of the keys

    def holders(self, key: Key) -> tuple[ItemId, ...]:
        """The items held here whose row has `key`."""
        found = self._items.get(key, ())
        return found if isinstance(found, tuple) else (found,)

    def keys(self, item: ItemId) -> tuple[Key, ...]:
        """The keys of `item`'s row held here (none: no such row)."""
        flat = self._keys.get(item, ())
        return tuple(zip(flat[::2], flat[1::2], strict=True))  # type: ignore[arg-type]

    def rows(self, mission: str) -> int:
        """Keys of rows of `mission` held here."""
        return self._missions[mission]

    def catch_up(self, store: Store) -> None:
        """Read what was written to the held chunks since the last call; forget
        the chunks no longer held."""
        # chunk ids, not `chunks()`: that counts every item of every chunk, at each commit
        held = set(store.chunk_ids(self.table)) if self.table in store.tables() else set()
        for chunk in set(self._seen) - held:
            for item in self._in_chunk.pop(chunk, []):
                self._set(item, ())
            del self._seen[chunk]
        for chunk in held:
            for revision in store.changed_since(self._seen.get(chunk, -1), chunk=chunk):
                self._apply(chunk, revision)

    def _apply(self, chunk: ChunkId, revision: Revision) -> None:
        self._seen[chunk] = max(self._seen.get(chunk, -1), revision.update_time)
        if revision.item_id not in self._keys:
            self._in_chunk[chunk].append(revision.item_id)  # forgetting twice does no harm
        self._set(revision.item_id, self.keys_of(b"" if revision.removed else revision.data))

    def _set(self, item: ItemId, keys: tuple[Key, ...]) -> None:
        for key in self.keys(item):
            left = tuple(i for i in self.holders(key) if i != item)
            self._store(key, left)
            self._missions[key[0]] -= 1
        self._keys.pop(item, None)
        if not keys:
            return
        shared = tuple((self._names.setdefault(m, m), i) for m, i in keys)
        self._keys[item] = shared[0] if len(shared) == 1 else tuple(v for k in shared for v in k)
        for key in shared:
            self._store(key, (*self.holders(key), item))
            self._missions[key[0]] += 1

    def _store(self, key: Key, items: tuple[ItemId, ...]) -> None:
        if not items:
            self._items.pop(key, None)
        else:
            self._items[key] = items[0] if len(items) == 1 else items


class _After:
    """One table's keys as they would be once a commit's changes are applied."""

    def __init__(self, index: KeyIndex, changes: Iterable[Change]) -> None:
        self.index = index
        self.new = {c.item_id: index.keys_of(c.data) for c in changes}
        self.by_key: dict[Key, list[ItemId]] = defaultdict(list)
        for item, keys in self.new.items():
            for key in keys:
                self.by_key[key].append(item)

    def holders(self, key: Key) -> list[ItemId]:
        """The items with `key` after the commit: the untouched ones first."""
        kept = sorted(i for i in self.index.holders(key) if i not in self.new)
        return kept + self.by_key.get(key, [])

    def gone(self) -> set[Key]:
        """Keys the changed items held before and no item holds after."""
        before = {k for item in self.new for k in self.index.keys(item)}
        return {k for k in before if not self.holders(k)}

    def knows(self, mission: str) -> bool:
        """Whether any row of `mission` is held here (or comes with the commit)."""
        return self.index.rows(mission) > 0 or any(k[0] == mission for k in self.by_key)


class MissionRules:
    """The `CommitRule` of the vertices and edges tables (see the module docstring)."""

    def __init__(self) -> None:
        self.vertices = KeyIndex(VERTICES, vertex_keys)
        self.edges = KeyIndex(EDGES, edge_keys)

    def check(self, store: Store, changes: Sequence[Change]) -> None:
        """Refuse a commit that would give a mission one vertex index twice, an
        edge an end that does not exist, or remove a vertex an edge ends at.

        Raises:
            MissionRuleError: naming the mission, the index and both items.
        """
        vertex_changes = [c for c in changes if c.table == VERTICES]
        edge_changes = [c for c in changes if c.table == EDGES]
        if not vertex_changes and not edge_changes:
            return
        self.vertices.catch_up(store)
        vertices = _After(self.vertices, vertex_changes)
        _unique(vertices)
        edges = _After(self.edges, edge_changes)
        _ends_exist(vertices, edges, edge_changes)
        gone = vertices.gone()
        if gone:
            self.edges.catch_up(store)
            _not_referenced(gone, _After(self.edges, edge_changes))


def _unique(vertices: _After) -> None:
    for key in vertices.by_key:
        first, *others = vertices.holders(key)
        if others:
            mission, index = key
            raise MissionRuleError(
                f"mission {mission!r} would have vertex {index} twice: items {first} and "
                f"{others[0]}; give one another index, or update the other instead",
                mission=mission,
                index=index,
                items=(str(first), str(others[0])),
            )


def _ends_exist(vertices: _After, edges: _After, changes: Sequence[Change]) -> None:
    for change in changes:
        keys = edges.new[change.item_id]
        if not keys:
            continue
        own = Edge.FromString(change.data).mission
        for mission, index in keys:
            judged = mission == own or vertices.knows(mission)
            if judged and not vertices.holders((mission, index)):
                raise MissionRuleError(
                    f"edge {change.item_id} of mission {own!r} ends at vertex {index} of "
                    f"mission {mission!r}, which does not exist; insert the vertex first",
                    mission=mission,
                    index=index,
                    items=(str(change.item_id),),
                )


def _not_referenced(gone: set[Key], edges: _After) -> None:
    for mission, index in sorted(gone):
        users = edges.holders((mission, index))
        if users:
            raise MissionRuleError(
                f"vertex {index} of mission {mission!r} is an end of edge {users[0]}; "
                "remove or change the edge first",
                mission=mission,
                index=index,
                items=(str(users[0]),),
            )


def map_rules() -> tuple[CommitRule, ...]:
    """The rules every peer keeps over the map tables (a new index per peer)."""
    return (MissionRules(),)
