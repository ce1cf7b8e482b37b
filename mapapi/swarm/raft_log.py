"""A Raft node's log in memory: a snapshot base, the entries after it, and what is persisted.

Pure (DESIGN §13). Model: etcd-io/raft `log.go` / `log_unstable.go`, folded into one list:
entries up to `stable` were handed out in a `Ready` and acknowledged by `advance`.
"""

from __future__ import annotations

from collections.abc import Sequence

from .raft_types import Config, Entry, EntryKind, Snapshot


class RaftLog:
    """The entries after `snapshot`, with the commit and apply marks.

    Args:
        snapshot: the compacted prefix; its `index`/`term` anchor the log.
        entries: the entries after it, consecutive from `snapshot.index + 1`.
        committed: the persisted commit index.
        applied: what the state machine already holds (at least `snapshot.index`).
    """

    def __init__(
        self, snapshot: Snapshot, entries: Sequence[Entry], committed: int, applied: int
    ) -> None:
        self.snapshot = snapshot
        self._entries = list(entries)
        for offset, entry in enumerate(self._entries):
            assert entry.index == snapshot.index + 1 + offset, "entries must be consecutive"
        self.committed = max(committed, snapshot.index)
        self.applied = max(applied, snapshot.index)
        assert self.committed <= self.last_index, "commit index beyond the persisted log"
        self.stable = self.last_index
        self.pending_snapshot: Snapshot | None = None  # restored, not yet persisted
        self._configs: list[tuple[int, Config]] = []  # the CONF_CHANGE entries in the log
        self._index_configs(self._entries)

    @property
    def first_index(self) -> int:
        """The first index still in the log."""
        return self.snapshot.index + 1

    @property
    def last_index(self) -> int:
        """The index of the last entry (the snapshot's when the log is empty)."""
        return self.snapshot.index + len(self._entries)

    def last_term(self) -> int:
        """The term of the last entry."""
        term = self.term(self.last_index)
        assert term is not None
        return term

    def term(self, index: int) -> int | None:
        """The term of the entry at `index`, or None if compacted away or beyond the end."""
        if index == self.snapshot.index:
            return self.snapshot.term
        if self.snapshot.index < index <= self.last_index:
            return self._entries[index - self.first_index].term
        return None

    def entry(self, index: int) -> Entry:
        """The entry at `index`, which must be in the log."""
        return self._entries[index - self.first_index]

    def match_term(self, index: int, term: int) -> bool:
        """Whether the log holds an entry at `index` with `term`."""
        return self.term(index) == term

    def is_up_to_date(self, index: int, term: int) -> bool:
        """Whether a log ending at (`index`, `term`) is at least as up to date (paper §5.4.1)."""
        last_term = self.last_term()
        return term > last_term or (term == last_term and index >= self.last_index)

    def find_conflict_by_term(self, index: int, term: int) -> tuple[int, int]:
        """The last entry at or below `index` whose term is at most `term`, as (index, term).

        No entry between the answer and `index` can match a log whose entry at `index` has
        `term`, so a leader may skip them all at once (etcd's fast backtracking; paper §5.3).
        Answers (index, 0) where the log is compacted.
        """
        index = min(index, self.last_index)
        while True:
            found = self.term(index)
            if found is None:
                return index, 0
            if found <= term:
                return index, found
            index -= 1

    def maybe_append(
        self, index: int, log_term: int, commit: int, entries: Sequence[Entry]
    ) -> int | None:
        """Accept an AppendEntries (paper Fig. 2, receiver steps 2-5).

        Returns:
            the index of the last new entry, or None when the log lacks (`index`, `log_term`).
        """
        if not self.match_term(index, log_term):
            return None
        last_new = index + len(entries)
        for entry in entries:
            if not self.match_term(entry.index, entry.term):
                # Log Matching: drop the conflicting entry and all after it (paper §5.3).
                self.append(entries[entry.index - index - 1 :])
                break
        self.commit_to(min(commit, last_new))
        return last_new

    def append(self, entries: Sequence[Entry]) -> None:
        """Store `entries`, replacing any entry at or after the first one's index."""
        if not entries:
            return
        start = entries[0].index
        assert start > self.committed, f"truncating committed entry {start} <= {self.committed}"
        assert start <= self.last_index + 1, "gap in the log"
        del self._entries[start - self.first_index :]
        self._entries.extend(entries)
        self.stable = min(self.stable, start - 1)
        while self._configs and self._configs[-1][0] >= start:
            self._configs.pop()  # a truncated config change no longer applies (thesis §4.1)
        self._index_configs(entries)

    def _index_configs(self, entries: Sequence[Entry]) -> None:
        for entry in entries:
            if entry.kind is EntryKind.CONF_CHANGE:
                self._configs.append((entry.index, Config.decode(entry.data)))

    @property
    def config(self) -> Config:
        """The configuration in force: the last one in the log, committed or not (§4.1)."""
        return self._configs[-1][1] if self._configs else self.snapshot.config

    @property
    def previous_config(self) -> Config:
        """The configuration `config` replaced."""
        return self._configs[-2][1] if len(self._configs) > 1 else self.snapshot.config

    @property
    def config_index(self) -> int:
        """The index of the entry that set `config` (the snapshot's when none is left)."""
        return self._configs[-1][0] if self._configs else self.snapshot.index

    def slice(self, lo: int, max_entries: int, max_bytes: int) -> list[Entry]:
        """Entries from `lo` on, at most `max_entries`, and `max_bytes` (but at least one)."""
        out: list[Entry] = []
        size = 0
        for entry in self._entries[lo - self.first_index :][:max_entries]:
            size += len(entry.data)
            if out and size > max_bytes:
                break
            out.append(entry)
        return out

    def commit_to(self, index: int) -> list[Entry]:
        """Raise the commit index; returns the newly committed entries still in the log."""
        if index <= self.committed:
            return []
        assert index <= self.last_index, f"commit {index} beyond last index {self.last_index}"
        old, self.committed = self.committed, index
        return self._entries[max(old + 1, self.first_index) - self.first_index : index]

    def unstable_entries(self) -> tuple[Entry, ...]:
        """Entries not yet handed out for persisting."""
        return tuple(self._entries[self.stable + 1 - self.first_index :])

    def unapplied_entries(self) -> tuple[Entry, ...]:
        """Committed entries the state machine has not applied."""
        lo = max(self.applied, self.snapshot.index) + 1
        return tuple(self._entries[lo - self.first_index : self.committed - self.snapshot.index])

    def stable_to(self, index: int, term: int) -> None:
        """Mark the entries up to (`index`, `term`) persisted, unless replaced since."""
        if self.match_term(index, term):
            self.stable = max(self.stable, index)

    def restore(self, snapshot: Snapshot) -> None:
        """Replace the whole log by a leader's snapshot (paper §7, InstallSnapshot 6-8)."""
        self.snapshot = snapshot
        self._entries = []
        self.committed = self.stable = snapshot.index
        self.pending_snapshot = snapshot
        self._configs = []

    def compact(self, snapshot: Snapshot) -> None:
        """Drop the entries covered by an applied `snapshot` of this node's own state."""
        assert self.snapshot.index < snapshot.index <= self.applied, "compact beyond applied"
        del self._entries[: snapshot.index - self.snapshot.index]
        self.snapshot = snapshot
        self._configs = [(i, c) for i, c in self._configs if i > snapshot.index]

    def config_at(self, index: int) -> Config:
        """The configuration in force when the log ended at `index`."""
        earlier = [config for at, config in self._configs if at <= index]
        return earlier[-1] if earlier else self.snapshot.config
