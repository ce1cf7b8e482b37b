"""The local control endpoint `mapctl` talks to while a peer daemon runs (DESIGN §9).

The daemon serves `ControlCall{op, args_json}` on an `Rpc` of its own, bound to
an ipc socket inside the repository (`.mapapi/control.sock`; tcp on 127.0.0.1
when that path is too long for an ipc endpoint), by running
`Operations.call(op, args)` on its peer and answering `ControlResult{json}`.
A `MapError` travels as an `ErrorReply` and is raised again on the client as
the same class, so a command exits with the same status whether a daemon runs
or not (a conflicting `commit` still exits 3). `RemoteOperations` is the
client: the same `async call(op, args)` as `Operations`.

`ask_chunk_list` asks a peer over its swarm port which chunks it holds
(`ChunkListQuery`, DESIGN §7 "by peer"): `mapctl chunk list --peer ADDR`, and
`mapctl clone --chunks all` through `ask_chunk_lists` to find every chunk of
the swarm.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from mapapi.clock import LamportClock
from mapapi.errors import (
    DaemonDied,
    MapError,
    NetworkError,
    PeerNotRunning,
    PeerUnavailable,
    UsageError,
)
from mapapi.ids import PeerId
from mapapi.net.codec import Ping, Pong
from mapapi.net.messages import ChunkList, ChunkListQuery, ChunkSummary, ControlCall, ControlResult
from mapapi.net.rpc import Request, Rpc
from mapapi.net.transport import ZmqTransport

if TYPE_CHECKING:
    import zmq.asyncio

    from mapapi.ops import Operations
    from mapapi.peer import Peer
    from mapapi.repo import Repository
    from mapapi.security import Security

log = logging.getLogger(__name__)

Json = Any

IPC_PATH_MAX = 100
"""Longest socket path used for ipc (sun_path holds 108 bytes on Linux, 104 on macOS)."""
PING_TIMEOUT = 5.0
"""Seconds a client waits for the daemon's first answer before calling it unresponsive."""
CALL_TIMEOUT = 600.0
"""Seconds one operation may take (participating in a large chunk takes a while)."""
ALIVE_CHECK = 0.5
"""Seconds between checks that the daemon still runs while an operation waits."""
QUERY_TIMEOUT = 5.0
"""Seconds to wait for another peer's list of chunks."""
MAX_MESSAGE_SIZE = 512 * 1024 * 1024
"""Replies as large as a big `ls --json` must fit through the local endpoint."""


def endpoints(repo: Repository) -> list[str]:
    """Where the daemon of `repo` tries to serve its control endpoint, in order."""
    path = str(repo.control_path)
    tried = [f"ipc://{path}"] if len(os.fsencode(path)) <= IPC_PATH_MAX else []
    return [*tried, "tcp://127.0.0.1:0"]


class ControlServer:
    """Serves `Operations` to `mapctl` processes on this machine.

    Args:
        ops: the operations over the daemon's peer.
    """

    def __init__(self, ops: Operations) -> None:
        self.ops = ops
        self.stopping = False
        self.rpc = self._new_rpc()
        self._bound: str | None = None

    def _new_rpc(self) -> Rpc:
        transport = ZmqTransport(
            self.ops.peer.id, LamportClock(), max_message_size=MAX_MESSAGE_SIZE
        )
        rpc = Rpc(transport)
        rpc.register(ControlCall, self.rpc_control_call)
        rpc.register(Ping, lambda req: Pong(req.body.payload))
        return rpc

    @property
    def address(self) -> str:
        """The bound endpoint, e.g. ipc:///home/robot/map/.mapapi/control.sock."""
        return self.rpc.address

    async def start(self, repo: Repository) -> str:
        """Bind the first endpoint of `endpoints(repo)` that works; returns it.

        Raises:
            NetworkError: no endpoint could be bound.
        """
        candidates = endpoints(repo)
        for index, endpoint in enumerate(candidates):
            if index:
                self.rpc = self._new_rpc()  # a transport binds once
            try:
                self._bound = await self.rpc.start(endpoint)
                return self._bound
            except NetworkError as exc:
                await self.rpc.close()
                if index == len(candidates) - 1:
                    raise
                log.warning("control endpoint %s failed (%s); trying the next", endpoint, exc)
        raise AssertionError("endpoints() always offers tcp")  # pragma: no cover

    async def rpc_control_call(self, req: Request) -> ControlResult:
        """Run one operation and answer its JSON result."""
        body: ControlCall = req.body
        if self.stopping:
            raise PeerNotRunning("the peer is stopping; run the command again once it stopped")
        args = _decode_args(body.args_json)
        result = await self.ops.call(body.op, args)
        return ControlResult(json.dumps(result))

    async def close(self) -> None:
        """Stop serving and close the endpoint (an ipc socket file is removed)."""
        await self.rpc.close()
        if self._bound is not None and self._bound.startswith("ipc://"):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self._bound.removeprefix("ipc://"))  # a quick local unlink


class RemoteOperations:
    """The client of a `ControlServer`: `Operations.call` over the control endpoint.

    Args:
        endpoint: the daemon's control endpoint (its pid file says which).
        who: how errors name the daemon, e.g. "the peer of /maps/a (pid 42)".
        timeout: seconds one operation may take.
        alive: tells whether the daemon process still runs; checked every
            `ALIVE_CHECK` seconds while an operation waits, so a daemon that dies
            (a crash, `kill -9`) fails the call at once rather than at `timeout`.
    """

    def __init__(
        self,
        endpoint: str,
        who: str = "the peer",
        timeout: float = CALL_TIMEOUT,
        alive: Callable[[], bool] | None = None,
    ) -> None:
        self.endpoint = endpoint
        self.who = who
        self.timeout = timeout
        self.alive = alive
        self._context: zmq.asyncio.Context | None = None
        self._rpc: Rpc | None = None

    async def _connect(self) -> Rpc:
        if self._rpc is None:
            import zmq.asyncio

            self._context = zmq.asyncio.Context()
            # No ROUTER of our own: requests leave on a DEALER and replies come back on it.
            transport = ZmqTransport(
                PeerId.new(), context=self._context, max_message_size=MAX_MESSAGE_SIZE
            )
            self._rpc = Rpc(transport)
            await self._ping(self._rpc, PING_TIMEOUT)
        return self._rpc

    async def ping(self, timeout: float = PING_TIMEOUT) -> None:  # noqa: ASYNC109
        """Check that the daemon answers.

        Raises:
            PeerUnavailable: it did not answer within `timeout` seconds.
        """
        await self._ping(await self._connect(), timeout)

    async def _ping(self, rpc: Rpc, timeout: float) -> None:  # noqa: ASYNC109
        try:
            await rpc.request(self.endpoint, Ping(), timeout=timeout, expect=Pong)
        except NetworkError as exc:
            raise PeerUnavailable(
                f"{self.who} does not answer on {self.endpoint}; look at .mapapi/peer.log, "
                "or restart it with `mapctl peer stop` and `mapctl peer start`"
            ) from exc

    async def call(self, op: str, args: dict[str, Json]) -> Json:
        """Run operation `op` with keyword `args` in the daemon; its JSON result.

        Raises:
            MapError: the class the daemon raised (ConflictError, UsageError, ...).
            RequestTimeout: no answer within `timeout` seconds.
        """
        rpc = await self._connect()
        call = ControlCall(op, json.dumps(args))
        reply = asyncio.ensure_future(
            rpc.request(self.endpoint, call, timeout=self.timeout, expect=ControlResult)
        )
        try:
            while not (await asyncio.wait({reply}, timeout=ALIVE_CHECK))[0]:
                if self.alive is not None and not self.alive():
                    raise DaemonDied(
                        f"{self.who} stopped while it ran `{op}` (it crashed or was killed); "
                        "start it again with `mapctl peer start`, then check with `mapctl log` "
                        "whether the operation took effect"
                    )
        finally:
            if not reply.done():
                reply.cancel()
                await asyncio.gather(reply, return_exceptions=True)
        return json.loads(reply.result().json)

    async def close(self) -> None:
        """Close the connection (idempotent)."""
        if self._rpc is not None:
            await self._rpc.close()
            self._rpc = None
        if self._context is not None:
            self._context.destroy(linger=0)
            self._context = None


def _decode_args(text: str) -> dict[str, Json]:
    try:
        args = json.loads(text or "{}")
    except json.JSONDecodeError as exc:
        raise UsageError(f"control call arguments are not JSON: {exc}") from exc
    if not isinstance(args, dict):
        raise UsageError("control call arguments must be a JSON object")
    return args


# -- lookup by peer ------------------------------------------------------------------
async def ask_chunk_list(
    address: str,
    table: str | None = None,
    *,
    rpc: Rpc | None = None,
    security: Security | None = None,
) -> list[ChunkSummary]:
    """The chunks the peer at `address` holds (of `table`, or all), asked over
    its swarm port on `rpc`, or on a connection of its own without one (with
    the keys of `security` when the asking repository is secure).

    Raises:
        NetworkError: the peer did not answer within `QUERY_TIMEOUT` seconds.
        UsageError: it has no such table.
    """
    query = ChunkListQuery(table or "")
    if rpc is not None:
        answer = await rpc.request(address, query, timeout=QUERY_TIMEOUT, expect=ChunkList)
        return list(answer.chunks)
    import zmq.asyncio

    context = zmq.asyncio.Context()
    # a DEALER only: nothing to bind
    own = Rpc(ZmqTransport(PeerId.new(), context=context, security=security))
    try:
        answer = await own.request(address, query, timeout=QUERY_TIMEOUT, expect=ChunkList)
        return list(answer.chunks)
    finally:
        await own.close()
        context.destroy(linger=0)


async def ask_chunk_lists(peer: Peer) -> dict[PeerId, list[ChunkSummary]]:
    """The chunks every other member holds, by member; members that do not
    answer are left out (and logged).

    Raises:
        PeerNotRunning: the peer is not on the network.
    """
    if peer.swarm is None:
        raise PeerNotRunning("no peer runs on this repository; start it with `mapctl peer start`")
    rpc = peer.swarm.rpc
    members = [s.member for s in peer.members()]
    answers = await asyncio.gather(
        *(ask_chunk_list(m.address, rpc=rpc) for m in members), return_exceptions=True
    )
    found: dict[PeerId, list[ChunkSummary]] = {}
    for member, answer in zip(members, answers, strict=True):
        if isinstance(answer, MapError):
            log.warning("peer %s did not list its chunks: %s", member.id.short, answer)
        elif isinstance(answer, BaseException):
            raise answer
        else:
            found[member.id] = answer
    return found
