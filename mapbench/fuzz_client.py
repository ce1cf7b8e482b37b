"""The fuzzer's side of `mapctl bench fuzz`: send hostile messages, sort the answers.

A plain zmq DEALER sends each `Shot` to the target's swarm port; what must
come back follows from decoding the shot the way the target does: a request
it can decode gets an `ErrorReply` or the reply its body calls for, a broken
message whose request id can still be read gets an `ErrorReply`, anything else
(no readable id, a notification, a stray reply) gets nothing. Replies are
matched by request id; up to `WINDOW` requests are in flight at once.
"""

from __future__ import annotations

import time
from collections import Counter as Tally
from dataclasses import dataclass, field

import zmq

from mapapi.core.errors import ProtocolError
from mapapi.core.ids import ChunkId, PeerId
from mapapi.net import codec, messages
from mapapi.net.codec import Envelope, ErrorReply, Kind, Ping, Pong
from mapbench.hostile import Pools, Shot

REPLY_TIMEOUT = 90.0
"""Seconds a request may wait for its reply: a proposal waits out an election or a
busy chunk (5 s) and a join pings the joiner (2 s) and changes the members (5 s)."""

WINDOW = 32
"""Requests in flight at once."""

_REPLIES: dict[type, type] = {
    Ping: Pong,
    messages.Hello: messages.Welcome,
    messages.HoldersQuery: messages.Holders,
    messages.ChunkListQuery: messages.ChunkList,
    messages.ChordFindSuccessor: messages.ChordHop,
    messages.ChordGetNeighbours: messages.ChordNeighbours,
    messages.ChordGet: messages.ChordValues,
    messages.ChainHead: messages.ChainHead,  # a holder's link, answered with ours
    messages.RaftPropose: messages.RaftProposed,
    messages.GroupJoin: messages.GroupChanged,
    messages.GroupLeave: messages.GroupChanged,
}
"""The reply of each request that is not answered with `Ack` (or an ErrorReply)."""

_ACKED = (
    messages.Bye,
    messages.RaftBatch,
    messages.ChordNotify,
    messages.ChordLeave,
    messages.ChordAdd,
    messages.ChordRemove,
    messages.ChordStore,
    messages.TriggerPush,
)


_CHANGES = (messages.RaftPropose, messages.GroupJoin, messages.GroupLeave)
"""The requests that change a chunk's replica once answered: a commit (or floor)
through its log, a holder joining or leaving its group."""


@dataclass
class _Pending:
    shot: Shot
    body: object | None  # the decoded body, None for a broken message
    deadline: float


@dataclass
class Outcome:
    """What happened to the messages sent so far."""

    messages: int = 0
    error_replies: int = 0
    valid_replies: int = 0
    notifications: int = 0
    dropped: int = 0
    missing_replies: int = 0
    internal_errors: int = 0
    wrong_replies: int = 0
    by_body: dict[str, Tally[str]] = field(default_factory=dict)
    by_mode: Tally[str] = field(default_factory=Tally)
    changed: set[ChunkId] = field(default_factory=set)  # chunks T acknowledged a change to
    regrouped: set[ChunkId] = field(default_factory=set)  # acknowledged joins and leaves
    problems: list[str] = field(default_factory=list)

    def count(self, body: str, what: str) -> None:
        """One more message of `body` that ended as `what`."""
        self.by_body.setdefault(body, Tally())[what] += 1

    def problem(self, text: str) -> None:
        """Remember a finding (the first 50 are kept)."""
        if len(self.problems) < 50:
            self.problems.append(text)


class Fuzzer:
    """Sends `Shot`s to the target's swarm port and sorts the answers.

    Args:
        address: the target's endpoint.
        pools: updated with what the answers reveal (its clock).
    """

    def __init__(self, address: str, pools: Pools) -> None:
        self.pools = pools
        self.outcome = Outcome()
        self._context = zmq.Context()
        self._socket = self._context.socket(zmq.DEALER)
        self._socket.setsockopt(zmq.LINGER, 0)
        self._socket.connect(address)
        self._pending: dict[int, _Pending] = {}
        self._awaited: dict[int, object | None] = {}  # replies `request` waits for

    def close(self) -> None:
        """Close the socket and its context."""
        self._socket.close(linger=0)
        self._context.term()

    def send(self, shot: Shot) -> None:
        """Send one message (waiting first while too many are in flight)."""
        out = self.outcome
        out.messages += 1
        out.by_mode[shot.mode] += 1
        out.count(shot.body, "sent")
        request_id, body, expect = _expectation(shot.frames)
        if expect in ("dropped", "notifications"):
            setattr(out, expect, getattr(out, expect) + 1)
            out.count(shot.body, expect)
            if isinstance(body, _CHANGES):  # a notification may change it, unseen
                out.changed.add(body.chunk)
            if isinstance(body, messages.RaftBatch):  # a member's messages may, too
                out.changed |= {m.chunk for m in body.messages}
        else:
            assert request_id is not None
            while request_id in self._pending or len(self._pending) >= WINDOW:
                self.collect(1.0)
            deadline = time.monotonic() + REPLY_TIMEOUT
            self._pending[request_id] = _Pending(shot, body, deadline)
        self._socket.send_multipart(shot.frames)

    def request(self, shot: Shot) -> object | None:
        """Send `shot` and wait for its reply body (None: no reply was due, or came)."""
        request_id, _, expect = _expectation(shot.frames)
        if request_id is None or expect not in ("reply", "error"):
            self.send(shot)
            return None
        while request_id in self._pending:  # an earlier message with the same id
            self.collect(0.5)
        self._awaited[request_id] = None
        self.send(shot)
        while request_id in self._pending:
            self.collect(0.5)
        return self._awaited.pop(request_id)

    @property
    def in_flight(self) -> int:
        """Requests still waiting for their reply."""
        return len(self._pending)

    def collect(self, timeout: float = 0.0) -> None:
        """Take in the replies that arrive within `timeout` seconds (none waits
        beyond the first one); fail requests whose deadline passed."""
        if self._socket.poll(int(timeout * 1000)):
            while self._socket.poll(0):
                self._answer(self._socket.recv_multipart())
        now = time.monotonic()
        for request_id, pending in list(self._pending.items()):
            if pending.deadline < now:
                del self._pending[request_id]
                self.outcome.missing_replies += 1
                self.outcome.count(pending.shot.body, "missing")
                self.outcome.problem(f"no reply to {_describe(pending)}")

    def drain(self, timeout: float = REPLY_TIMEOUT) -> None:
        """Wait until every request is answered or past its deadline."""
        end = time.monotonic() + timeout
        while self._pending and time.monotonic() < end:
            self.collect(0.5)
        for pending in self._pending.values():
            pending.deadline = 0.0
        self.collect()

    def ping(self) -> bool:
        """Whether the target answers a valid Ping with a Pong within 10 s."""
        env = Envelope(2**63, PeerId.new(), self.pools.lamport, Kind.REQUEST, Ping(b"ok"))
        self._socket.send(codec.encode(env))
        end = time.monotonic() + 10.0
        while time.monotonic() < end:
            if self._socket.poll(500):
                reply = codec.decode(self._socket.recv_multipart()[0])
                if reply.request_id == env.request_id:
                    return reply.body == Pong(b"ok")
        return False

    def _answer(self, frames: list[bytes]) -> None:
        out = self.outcome
        try:
            reply = codec.decode(frames[0])
        except ProtocolError as exc:
            out.wrong_replies += 1
            out.problem(f"undecodable reply: {exc}")
            return
        pending = self._pending.pop(reply.request_id, None)
        if pending is None:
            out.wrong_replies += 1
            out.problem(f"a reply nobody waits for: {reply.body_name} {reply.request_id}")
            return
        self.pools.lamport = max(self.pools.lamport, min(reply.lamport, 2**40))
        body, name = reply.body, pending.shot.body
        if reply.request_id in self._awaited:
            self._awaited[reply.request_id] = body
        if isinstance(body, ErrorReply):
            out.error_replies += 1
            out.count(name, "error")
            if body.message.startswith("internal error"):
                out.internal_errors += 1
                out.problem(f"{_describe(pending)} -> {body.message}")
            return
        expected = _REPLIES.get(type(pending.body), messages.Ack)
        if pending.body is None or not (
            isinstance(body, expected)
            and (expected is not messages.Ack or isinstance(pending.body, _ACKED))
        ):
            out.wrong_replies += 1
            out.problem(f"{_describe(pending)} -> {reply.body_name}")
            return
        out.valid_replies += 1
        out.count(name, "valid")
        if isinstance(pending.body, _CHANGES):
            out.changed.add(pending.body.chunk)
        if isinstance(pending.body, messages.GroupJoin | messages.GroupLeave):
            out.regrouped.add(pending.body.chunk)
        if isinstance(pending.body, messages.RaftBatch):  # a member's messages may change it
            out.changed |= {m.chunk for m in pending.body.messages}


def _expectation(frames: list[bytes]) -> tuple[int | None, object | None, str]:
    """(request id, decoded body, what must happen) for a message the target gets:
    "reply" (an ErrorReply or a valid reply), "error" (an ErrorReply),
    "dropped" or "notifications" (no answer)."""
    data = frames[0]
    request_id = codec.peek_request_id(data)
    if len(frames) != 1:
        return (request_id, None, "error") if request_id else (None, None, "dropped")
    try:
        env = codec.decode(data)
    except ProtocolError:
        return (request_id, None, "error") if request_id else (None, None, "dropped")
    if env.kind is Kind.REPLY:
        return None, None, "dropped"
    if env.kind is Kind.NOTIFY:
        return None, env.body, "notifications"
    return env.request_id, env.body, "reply"


def _describe(pending: _Pending) -> str:
    frames = pending.shot.frames
    head = frames[0][:48].hex()
    return f"{pending.shot.body} ({pending.shot.mode}, {len(frames[0])} bytes: {head}...)"
