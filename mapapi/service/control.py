"""The local control endpoint `mapctl` talks to while a peer daemon runs (DESIGN §9).

The daemon serves `ControlCall{op, args_json, token}` on an `Rpc` of its own,
bound to an ipc socket that only its owner can reach (mode 0600):
`.mapapi/control.sock` inside the repository, or, when that path
is too long for an ipc endpoint, a socket named after the repository in a
private runtime folder (`$XDG_RUNTIME_DIR/mapapi`, else `/tmp/mapapi-<uid>`,
mode 0700, refused if anyone else owns it). There is no tcp fallback: a tcp
port on 127.0.0.1 is open to every local user. As a second wall, every call
carries the owner's token from `.mapapi/control.token` (mode 0600, new at each
start); a call without it is refused and logged before anything runs, so the
daemon never reads or writes a path sent by a caller it has not authenticated.
It runs `Operations.call(op, args)` on its peer and answers `ControlResult{json}`.
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
import hashlib
import hmac
import json
import logging
import os
import secrets
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mapapi.core.clock import LamportClock
from mapapi.core.errors import (
    DaemonDied,
    NetworkError,
    NotOwner,
    PeerNotRunning,
    PeerUnavailable,
    RepoError,
    UsageError,
)
from mapapi.core.ids import PeerId
from mapapi.net.asking import ask_all
from mapapi.net.codec import Ping, Pong
from mapapi.net.messages import ChunkList, ChunkListQuery, ChunkSummary, ControlCall, ControlResult
from mapapi.net.rpc import Request, Rpc
from mapapi.net.transport import ZmqTransport
from mapapi.service.json_parts import dumps

if TYPE_CHECKING:
    import zmq.asyncio

    from mapapi.net.security import Security
    from mapapi.service.ops import Operations
    from mapapi.service.peer import Peer
    from mapapi.service.repo import PeerRecord, Repository

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
CLOSE_GRACE = 2.0  # seconds the calls running at a shutdown get to answer
MAX_MESSAGE_SIZE = 512 * 1024 * 1024
"""Replies as large as a big `ls --json` must fit through the local endpoint."""


TOKEN_FILE = "control.token"
"""The owner's secret in `.mapapi/`, mode 0600, written anew by every daemon start."""


def endpoint(repo: Repository) -> str:
    """The ipc endpoint where the daemon of `repo` serves `mapctl`.

    Raises:
        RepoError: the path is too long even in the runtime folder, or that
            folder is not private to this user.
    """
    inside = str(repo.control_path)
    if len(os.fsencode(inside)) <= IPC_PATH_MAX:
        return f"ipc://{inside}"
    # One socket per repository: the name hashes its resolved root.
    name = hashlib.sha256(os.fsencode(str(repo.root.resolve()))).hexdigest()[:32]
    path = str(private_runtime_dir() / f"{name}.sock")
    if len(os.fsencode(path)) > IPC_PATH_MAX:
        raise RepoError(
            f"no short private folder for the control socket ({path} is too long); "
            "set XDG_RUNTIME_DIR to a short folder only you can enter"
        )
    return f"ipc://{path}"


def private_runtime_dir() -> Path:
    """A folder only this user can enter, for control sockets of deep repositories:
    `$XDG_RUNTIME_DIR/mapapi` if the variable is set, else `/tmp/mapapi-<uid>`.

    Raises:
        RepoError: the folder exists but is a link, or another user owns it, or
            others may enter it (someone could listen in our place).
    """
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    base = Path(runtime) if runtime else Path(tempfile.gettempdir())
    folder = base / ("mapapi" if runtime else f"mapapi-{os.geteuid()}")
    with contextlib.suppress(FileExistsError):
        folder.mkdir(mode=0o700)
    info = folder.lstat()
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.geteuid() or info.st_mode & 0o077:
        raise RepoError(
            f"the control folder {folder} is not private to this user (owner uid "
            f"{info.st_uid}, mode {stat.filemode(info.st_mode)}); remove it and start again"
        )
    return folder


def issue_token(repo: Repository) -> str:
    """Write a fresh owner's token to `.mapapi/control.token` (mode 0600); returns it."""
    token = secrets.token_hex(32)
    path = repo.meta_dir / TOKEN_FILE
    tmp = path.with_name(f"{TOKEN_FILE}.{os.getpid()}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="ascii") as out:
        out.write(token)
    tmp.replace(path)
    return token


def read_token(repo: Repository) -> str:
    """The owner's token of the daemon of `repo`.

    Raises:
        NotOwner: this user cannot read it (the daemon belongs to someone else).
        PeerNotRunning: there is none (no daemon started here).
    """
    path = repo.meta_dir / TOKEN_FILE
    try:
        return path.read_text(encoding="ascii").strip()
    except PermissionError as exc:
        raise NotOwner(
            f"the peer of {repo.root} belongs to another user: only its owner can "
            "drive it (run mapctl as that user)"
        ) from exc
    except FileNotFoundError as exc:
        raise PeerNotRunning(
            f"no peer runs on {repo.root} ({path} is missing); start it with `mapctl peer start`"
        ) from exc


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
        self._token: str | None = None

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
        """Issue a new owner's token and bind `endpoint(repo)`; returns the endpoint.

        Raises:
            NetworkError: the endpoint could not be bound.
            RepoError: there is no private place for it.
        """
        self._token = issue_token(repo)
        self._bound = await self.rpc.start(endpoint(repo))
        # Connecting to a unix socket needs write permission on it: owner only,
        # whatever the umask (the token guards the instant before this chmod).
        os.chmod(self._bound.removeprefix("ipc://"), 0o600)
        return self._bound

    async def rpc_control_call(self, req: Request) -> ControlResult:
        """Run one operation for the owner and answer its JSON result.

        Raises:
            NotOwner: the call does not carry the owner's token.
        """
        body: ControlCall = req.body
        if self._token is None or not hmac.compare_digest(
            body.token.encode(), self._token.encode()
        ):
            log.warning("refused control call %r without the owner's token", body.op[:40])
            raise NotOwner("the control call does not carry the owner's token; refused")
        if self.stopping:
            raise PeerNotRunning("the peer is stopping; run the command again once it stopped")
        args = _decode_args(body.args_json)
        result = await self.ops.call(body.op, args)
        return ControlResult(await asyncio.to_thread(dumps, result))  # in parts: json_parts

    async def close(self) -> None:
        """Stop serving and close the endpoint (an ipc socket file is removed); calls
        still running, `peer stop`'s own among them, get `CLOSE_GRACE` s to answer."""
        await self.rpc.close(grace=CLOSE_GRACE)
        if self._bound is not None and self._bound.startswith("ipc://"):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self._bound.removeprefix("ipc://"))  # a quick local unlink


class RemoteOperations:
    """The client of a `ControlServer`: `Operations.call` over the control endpoint.

    Args:
        endpoint: the daemon's control endpoint (its pid file says which).
        token: the owner's token (`read_token`), sent with every call.
        who: how errors name the daemon, e.g. "the peer of /maps/a (pid 42)".
        timeout: seconds one operation may take.
        alive: tells whether the daemon process still runs; checked every
            `ALIVE_CHECK` seconds while an operation waits, so a daemon that dies
            (a crash, `kill -9`) fails the call at once rather than at `timeout`.
    """

    def __init__(
        self,
        endpoint: str,
        token: str,
        who: str = "the peer",
        timeout: float = CALL_TIMEOUT,
        alive: Callable[[], bool] | None = None,
    ) -> None:
        self.endpoint = endpoint
        self.token = token
        self.who = who
        self.timeout = timeout
        self.alive = alive
        self._context: zmq.asyncio.Context | None = None
        self._rpc: Rpc | None = None

    @classmethod
    def of(
        cls, repo: Repository, record: PeerRecord, who: str | None = None, **options: Any
    ) -> RemoteOperations:
        """The client of the daemon that `record` (the pid file of `repo`) describes,
        with the owner's token; `options` as for the constructor.

        Raises:
            NotOwner: this user cannot read the token (another user's daemon).
        """
        who = who or f"the peer of {repo.root} (pid {record.pid})"
        return cls(record.control, read_token(repo), who, **options)

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
        call = ControlCall(op, json.dumps(args), self.token)
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
    answers = await ask_all({m.id: ask_chunk_list(m.address, rpc=rpc) for m in members})
    for member, error in answers.failed.items():
        log.warning("member %s did not list its chunks: %s", member.short, error)
    return answers.ok
