"""The exception hierarchy (STYLE §4).

Every error mapapi raises on purpose is a `MapError`. `retriable` tells retry
loops whether the same call may succeed later; `code` travels in error replies
and picks the CLI's exit status through `exit_code`.

Network errors (exit 5) end their message with `advice`: what a person should
do next, which always begins with one of three verbs (`ADVICE_VERBS`):

- "retry now": transient, the same call is likely to succeed at once;
- "wait": a peer is restarting, a chunk's group is electing a leader or links are
  settling; the advice
  says roughly how long before retrying;
- "act": retrying cannot help until someone runs what the advice names.

A class gives the usual advice; a raise site that knows better passes its own
(`advice=`). The advice is part of the message, so it survives the trip from a
peer daemon to `mapctl` as an `ErrorReply`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

if TYPE_CHECKING:
    from mapapi.core.change import Conflict
    from mapapi.core.ids import ChunkId, PeerId
    from mapapi.core.transaction import Transaction


ADVICE_VERBS = ("retry now", "wait", "act")

# Seconds before a silent peer is declared dead (mapapi.swarm.failure.DEAD_AFTER,
# 3 s; requests to it then fail at once, and its chunks' groups have long elected
# another leader), plus a round of the heartbeat: the "wait" advice quotes it so
# people know how long "a moment" is.
SETTLE_S = 5


class MapError(Exception):
    """Base for every error mapapi raises on purpose.

    Args:
        message: what failed.
        advice: what to do next, appended to the message after "; ". None
            takes the class's `advice` (empty for most errors, whose
            messages say it themselves).
    """

    retriable: ClassVar[bool] = False
    code: ClassVar[int] = 1
    exit_code: ClassVar[int] = 1
    advice: str = ""

    def __init__(self, message: str = "", *, advice: str | None = None) -> None:
        if advice is not None:
            self.advice = advice
        if self.advice and not message.endswith(self.advice):
            message = f"{message}; {self.advice}" if message else self.advice
        super().__init__(message)


class UsageError(MapError, ValueError):
    """The caller asked for something malformed (bad JSON, unknown table, ...)."""

    code = 2
    exit_code = 2


class LimitExceeded(UsageError):
    """A message or value exceeds one of the limits in `mapapi.core.limits` (its
    message names the limit); refused before anything is allocated for it."""

    code = 3


class RepoError(MapError):
    """A problem with the on-disk repository."""

    code = 10


class NotARepoError(RepoError):
    """No `.mapapi` folder here or in any parent."""

    code = 11
    exit_code = 4


class AlreadyInitialisedError(RepoError):
    """`init` on a folder that already holds a repository."""

    code = 12


class CorruptRepoError(RepoError):
    """The repository's files are damaged or are not a mapapi repository."""

    code = 13


class NotOwner(RepoError):
    """A call reached a peer daemon's control endpoint without the owner's token
    (`.mapapi/control.token`, readable only by the user who runs the daemon)."""

    code = 14


class ChunkError(MapError):
    """A problem with a chunk."""

    code = 15


class ChunkNotFound(ChunkError):
    """No chunk with that id is known here."""

    code = 16


class ItemNotFound(MapError):
    """No item with that id exists at the time read."""

    code = 17


class NotParticipatingError(ChunkError):
    """This peer does not hold the chunk."""

    code = 18


class TransactionError(MapError):
    """A problem with a transaction or view."""

    code = 20


class ConflictError(TransactionError):
    """The commit lost a race: items it changed were changed by someone else.

    A ConflictError that crossed the wire (from a peer daemon to `mapctl`, or
    from a holder to a writer) keeps its conflicts as far as the wire carries
    them (table, item, chunk, base, ours, theirs) and `seen_at`, but not the
    transaction: only `merge()` where that transaction lives works.

    Attributes:
        conflicts: one `Conflict` (base, ours, theirs) per conflicting item.
        seen_at: the time the conflicts were seen; `merge()` begins there.
    """

    retriable = True
    code = 21
    exit_code = 3

    def __init__(
        self, conflicts: list[Conflict], transaction: Transaction | None, seen_at: int
    ) -> None:
        self.conflicts = conflicts
        self.seen_at = seen_at
        self._transaction = transaction
        super().__init__(self._hint("mapctl"))

    @classmethod
    def received(cls, message: str, conflicts: list[Conflict], seen_at: int) -> ConflictError:
        """The error another process raised, as its reply carried it: `message`
        whole (hint included), no transaction to merge."""
        exc = cls(conflicts, None, seen_at)
        exc.args = (message,)
        return exc

    def _hint(self, mapctl: str) -> str:
        return (
            f"{len(self.conflicts)} conflicting item(s); run `{mapctl} diff` and "
            f"`{mapctl} resolve`, then commit again"
        )

    def name_view(self, mapctl: str) -> None:
        """Point the hint at one view's commands, `mapctl` being the command
        line that reaches it (say `mapctl --view bob`)."""
        self.args = (self._hint(mapctl),)

    def merge(self) -> Transaction:
        """A new transaction, begun when the conflicts were seen, holding every
        change of the failed one that did not conflict (git-like).

        Raises:
            UsageError: the error came from another process (`received`), which
                holds the transaction: merge there, or begin anew here.
        """
        if self._transaction is None:
            raise UsageError(
                "this conflict was reported by another process; its transaction lives "
                "there, so merge it where it was committed (or begin a new transaction "
                "here and apply your changes again)"
            )
        return self._transaction.merged(self)


class ViewClosedError(TransactionError):
    """The transaction or view is not in a state that allows this."""

    code = 22


class UnresolvedConflicts(TransactionError):
    """A view still holds conflicts, so it cannot commit."""

    code = 23
    exit_code = 3


class LockError(MapError):
    """A lock could not be taken (the repository's store, held while writing it)."""

    code = 30


class LockTimeout(LockError):
    """A lock was not granted in time (another process kept the store locked)."""

    retriable = True
    code = 31


class NetworkError(MapError):
    """A message could not be delivered or answered."""

    retriable = True
    code = 40
    exit_code = 5
    advice = "retry now; if it fails again, see who answers with `mapctl peers`"


class PeerUnavailable(NetworkError):
    """The peer cannot be reached, or the local transport closed before it answered."""

    retriable = True
    code = 41
    advice = (
        f"wait about {SETTLE_S} s and retry: the peer may be restarting, or its chunks' "
        "groups electing another leader; if it persists, check `mapctl peers`"
    )


class RequestTimeout(NetworkError):
    """A request got no reply before its deadline."""

    retriable = True
    code = 42
    advice = (
        "retry now (a reply can be lost on a busy link); if it times out again, wait "
        f"about {SETTLE_S} s for the peer to restart or a new leader to be elected, then "
        "check `mapctl peers`"
    )


class ProtocolError(NetworkError):
    """A message was malformed, truncated, unknown or oversized (DESIGN §11)."""

    retriable = False
    code = 43
    advice = (
        "act: run one mapapi version on every peer (`mapctl --version`); retrying will not help"
    )


class DaemonDied(PeerUnavailable):
    """The peer daemon died (a crash, `kill -9`) while it ran an operation for this
    client: whether the operation took effect is unknown until it runs again."""

    retriable = False
    code = 45
    advice = (
        "act: start the peer again (`mapctl peer start --detach`), check with `mapctl log` "
        "whether the operation took effect, and run it again if not"
    )


class CommitUncertain(NetworkError):
    """A transaction over several chunks was prepared on all of them, but whether
    its first chunk's log took the decision could not be learnt: the chunks'
    leaders settle it from that log (see docs/guarantees.md, Failures)."""

    retriable = False
    code = 44
    advice = (
        f"wait about {SETTLE_S} s for the chunks' leaders to settle it, then check with "
        "`mapctl log` whether the commit is there; do not commit it again before"
    )


class ProposalLost(NetworkError):
    """A proposal's log entry was overwritten by a new leader before it committed,
    or a multi-chunk transaction was aborted: it did not take effect."""

    retriable = True
    code = 46
    advice = "retry now: nothing was written"


class NotChunkLeader(NetworkError):
    """A proposal reached a peer that does not lead the chunk's group (or none
    does yet: an election runs)."""

    retriable = True
    code = 47
    advice = "retry now: the group elects a leader within a second or so"

    @classmethod
    def of(cls, chunk: ChunkId, leader: PeerId | None) -> NotChunkLeader:
        """The error for `chunk`, naming the leader this peer knows (or the election)."""
        where = f"peer {leader.short} leads it" if leader else "it is electing a leader"
        return cls(f"this peer does not lead chunk {chunk.short}: {where}")


class NoQuorum(NetworkError):
    """A chunk's group cannot commit (or confirm a read) from here: most of its
    voters do not answer (DESIGN §13: a minority never commits). Names them."""

    retriable = True
    code = 56  # 40-49 are taken
    advice = (
        "act: bring the voters named back, or reconnect this peer to them (`mapctl peers`); "
        "the chunk commits again once a majority of its voters is reachable"
    )

    @classmethod
    def of(cls, chunk: ChunkId, voters: int, down: list[str]) -> NoQuorum:
        """The error for `chunk`, of whose `voters` those named in `down` do not answer."""
        reachable = voters - len(down)
        return cls(
            f"no quorum for chunk {chunk.short}: {reachable} of {voters} voters reachable "
            f"({', '.join(down)} down)"
        )


class ChunkBusy(NetworkError):
    """A chunk stayed held by another transaction's two-phase commit (prepared,
    awaiting its decision) for as long as the writer could wait."""

    retriable = True
    code = 48
    advice = (
        f"wait about {SETTLE_S} s: a transaction over several chunks is being decided, "
        "or settled by the chunks' leaders if its writer went away; then retry"
    )


class AccessRefused(NetworkError):
    """A secure link was refused (DESIGN §10): a peer does not trust the other's
    key, or one peer is secure and the other open. Not retriable: trust must change
    first (`mapctl trust add`)."""

    retriable = False
    code = 49
    advice = "act: change the trust lists (`mapctl trust add KEY`, `mapctl key show`)"


class SwarmError(MapError):
    """A problem with swarm membership."""

    code = 50
    exit_code = 5


class JoinRefused(SwarmError):
    """A peer refused to let this one join (or is not a mapapi peer)."""

    code = 51


class NoPeersError(SwarmError):
    """This peer knows no other peer to ask."""

    retriable = True
    code = 52


class PeerNotRunning(SwarmError):
    """The command needs the repository's peer daemon, and none runs."""

    code = 53


class QueryError(MapError):
    """A lookup or spatial query could not be answered as asked."""

    code = 60
    exit_code = 2


class WatchTimeout(QueryError):
    """`mapctl watch --timeout` ran out before the changes it waited for arrived."""

    code = 62
    exit_code = 1


class InvalidBBox(QueryError, ValueError):
    """A bounding box is malformed: min > max, or a coordinate is NaN or infinite."""

    code = 61
    exit_code = 2


class NoSpaceLeft(RepoError):
    """The disk holding the repository is full: a write was refused whole (SQLite
    rolls its transaction back), nothing stored was lost; free space and retry."""

    code = 70


class CorruptPayload(CorruptRepoError, UsageError):
    """A payload's bytes do not parse as its table's type.

    Read from the store, the store is damaged: `at` names the file and the
    item, and the CLI exits 1. It is also a UsageError because a revision
    received from another peer that does not parse is that peer's mistake
    (`mapapi.swarm.commit_check` refuses a proposal with it).

    Args:
        table: the item's table.
        type_name: the table's message type.
        data: the bytes that do not parse (kept so that a caller who knows the
            store can find the item: `at`).
        why: the parser's complaint.
        where: which item of which store (set by `at`).
    """

    code = 71
    exit_code = 1

    def __init__(
        self, table: str, type_name: str, data: bytes = b"", why: str = "", where: str = ""
    ) -> None:
        self.table, self.type_name, self.data, self.why = table, type_name, data, why
        self.where = where
        what = f"payload of {len(data)} bytes does not parse as {type_name}" + (
            f" ({why})" if why else ""
        )
        if where:
            what = (
                f"{where} is damaged: its {what}; restore the store from a backup or "
                "clone the repository again"
            )
        else:
            what = f"an item of table {table!r}: its {what}"
        super().__init__(what)

    def at(self, path: object, items: list[str]) -> CorruptPayload:
        """The same error naming the store file and the items holding the bytes."""
        which = f"item {', '.join(items)}" if items else "an item"
        return CorruptPayload(
            self.table,
            self.type_name,
            self.data,
            self.why,
            where=f"{which} of table {self.table!r} in {path}",
        )


class ConfigLost(RepoError):
    """`init` over a folder whose store holds a map but whose config is gone: a
    new peer id would lock the peer out of its own chunks (`init --recover`).
    Like `AlreadyInitialisedError`, but a usage error: the folder is no
    repository yet, and `init` must be asked differently."""

    code = 72
    exit_code = 2
