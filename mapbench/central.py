"""Central key-value servers for `scripts/kv-compare.sh` (DESIGN §12): Redis and a
3-member etcd cluster, each started on 127.0.0.1 ports picked here, in a
scratch folder, and stopped (then killed) on the way out; and the smallest
clients paper Algorithm 1 needs against them, on the standard library alone:

- Redis: RESP over one TCP connection; an increment is WATCH, GET, then MULTI
  SET EXEC sent together (three round trips, as redis-py's transaction pipeline
  does it); EXEC answers nil when the watched key changed: an abort.
- etcd 3.4: its gRPC gateway's JSON (`/v3/kv/range`, `/v3/kv/txn`) over one
  HTTP/1.1 keep-alive connection; an increment is a (linearizable) range, then
  a txn that puts value + 1 if the key's mod_revision is still the one read.

The servers are Debian's `redis-server` and `etcd` (packages redis-server,
etcd-server); each dies with this process (PR_SET_PDEATHSIG) if it is killed.
"""

from __future__ import annotations

import base64
import contextlib
import functools
import http.client
import json
import shutil
import socket
import subprocess
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import IO, Any

from mapapi.core.errors import MapError
from mapbench.worker import die_with_parent

START_TIMEOUT = 30.0
CALL_TIMEOUT = 10.0
KEY = "counter"


class ServerFailed(MapError):
    """A server is missing, did not start in time, or answered an error."""


def free_ports(count: int) -> list[int]:
    """`count` distinct TCP ports free on 127.0.0.1 now (the OS picks them)."""
    with contextlib.ExitStack() as stack:
        socks = [stack.enter_context(socket.socket()) for _ in range(count)]
        for sock in socks:
            sock.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]


def _program(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        raise ServerFailed(f"{name} is not installed: apt-get install -y redis-server etcd-server")
    return path


@contextlib.contextmanager
def _processes(commands: Sequence[list[str]], logs: Sequence[Path]) -> Iterator[None]:
    """Start `commands` (stdout and stderr to `logs`); stop them all on exit."""
    started: list[subprocess.Popen[bytes]] = []
    files: list[IO[bytes]] = []
    try:
        for command, log in zip(commands, logs, strict=True):
            files.append(log.open("wb"))
            started.append(
                subprocess.Popen(
                    command, stdout=files[-1], stderr=subprocess.STDOUT, preexec_fn=die_with_parent
                )
            )
        yield
    finally:
        for proc in started:
            proc.terminate()
        for proc in started:
            try:
                proc.wait(10.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(10.0)
        for file in files:
            file.close()


def _wait(what: str, ready: Callable[[], bool], log: Path) -> None:
    """Poll `ready` until it holds (errors count as not yet), for START_TIMEOUT s."""
    deadline = time.monotonic() + START_TIMEOUT
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError, ServerFailed, http.client.HTTPException):
            if ready():
                return
        time.sleep(0.05)  # a server starting: nothing to await but its port
    tail = log.read_text(errors="replace")[-2000:] if log.exists() else ""
    raise ServerFailed(f"{what} did not start within {START_TIMEOUT:g} s; its log ends:\n{tail}")


# -- Redis -----------------------------------------------------------------------------
class RedisClient:
    """One RESP connection to a Redis server on 127.0.0.1."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=CALL_TIMEOUT)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.reader = self.sock.makefile("rb")

    def call(self, *commands: Sequence[str]) -> list[Any]:
        """Send `commands` at once (one round trip) and read their replies."""
        out = bytearray()
        for command in commands:
            out += b"*%d\r\n" % len(command)
            for word in command:
                data = word.encode()
                out += b"$%d\r\n%s\r\n" % (len(data), data)
        self.sock.sendall(out)
        return [self._reply() for _ in commands]

    def _reply(self) -> Any:
        line = self.reader.readline()
        kind, rest = line[:1], line[1:-2]
        if kind == b"+":
            return rest.decode()
        if kind == b"-":
            raise ServerFailed(f"redis: {rest.decode()}")
        if kind == b":":
            return int(rest)
        if kind == b"$":
            size = int(rest)
            return None if size < 0 else self.reader.read(size + 2)[:-2].decode()
        if kind == b"*":
            size = int(rest)
            return None if size < 0 else [self._reply() for _ in range(size)]
        raise ServerFailed(f"redis: unexpected reply {line!r}")

    def increment(self) -> bool:
        """One attempt of Algorithm 1; False when EXEC aborted (the key changed)."""
        self.call(("WATCH", KEY))
        (value,) = self.call(("GET", KEY))
        *_, done = self.call(("MULTI",), ("SET", KEY, str(int(value or 0) + 1)), ("EXEC",))
        return done is not None

    def value(self) -> int:
        """The counter now."""
        (value,) = self.call(("GET", KEY))
        return int(value or 0)

    def reset(self) -> None:
        """Set the counter to 0."""
        self.call(("SET", KEY, "0"))

    def close(self) -> None:
        """Close the connection."""
        self.reader.close()
        self.sock.close()


@contextlib.contextmanager
def redis_server(folder: Path) -> Iterator[list[int]]:
    """A Redis server in `folder` (no snapshots, no append-only file: its
    defaults but the RDB saves); yields [its port]."""
    (port,) = free_ports(1)
    command = [_program("redis-server"), "--port", str(port), "--bind", "127.0.0.1"]
    command += ["--save", "", "--appendonly", "no", "--dir", str(folder), "--daemonize", "no"]
    log = folder / "redis.log"
    with _processes([command], [log]):
        _wait("redis-server", lambda: _redis_ping(port), log)
        yield [port]


def _redis_ping(port: int) -> bool:
    client = RedisClient(port)
    try:
        return client.call(("PING",)) == ["PONG"]
    finally:
        client.close()


# -- etcd ------------------------------------------------------------------------------
def _b64(text: str) -> str:
    return base64.b64encode(text.encode()).decode()


class EtcdClient:
    """One keep-alive HTTP connection to an etcd member's JSON gateway."""

    def __init__(self, port: int) -> None:
        self.conn = http.client.HTTPConnection("127.0.0.1", port, timeout=CALL_TIMEOUT)

    def post(self, path: str, body: dict[str, Any]) -> dict[str, Any]:
        """POST `body` as JSON to `path`; the JSON answer."""
        self.conn.request("POST", path, json.dumps(body), {"Content-Type": "application/json"})
        response = self.conn.getresponse()
        data = response.read()
        if response.status != 200:
            raise ServerFailed(f"etcd {path}: {response.status} {data[:200]!r}")
        answer: dict[str, Any] = json.loads(data)
        return answer

    def read(self) -> tuple[int, int]:
        """(value, mod_revision) of the counter; (0, 0) while it does not exist."""
        kvs = self.post("/v3/kv/range", {"key": _b64(KEY)}).get("kvs", [])
        if not kvs:
            return 0, 0
        return int(base64.b64decode(kvs[0]["value"])), int(kvs[0].get("mod_revision", 0))

    def increment(self) -> bool:
        """One attempt of Algorithm 1; False when the txn's compare failed."""
        value, revision = self.read()
        compare = {"key": _b64(KEY), "target": "MOD", "result": "EQUAL"}
        compare["mod_revision"] = str(revision)
        put = {"request_put": {"key": _b64(KEY), "value": _b64(str(value + 1))}}
        answer = self.post("/v3/kv/txn", {"compare": [compare], "success": [put]})
        return bool(answer.get("succeeded", False))

    def value(self) -> int:
        """The counter now."""
        return self.read()[0]

    def reset(self) -> None:
        """Set the counter to 0."""
        self.post("/v3/kv/put", {"key": _b64(KEY), "value": _b64("0")})

    def close(self) -> None:
        """Close the connection."""
        self.conn.close()


@contextlib.contextmanager
def etcd_cluster(folder: Path, members: int = 3) -> Iterator[list[int]]:
    """An etcd cluster of `members` in `folder`; yields their client ports once
    every member reports healthy (a leader elected)."""
    ports = free_ports(2 * members)
    clients, peers = ports[:members], ports[members:]
    cluster = ",".join(f"e{i}=http://127.0.0.1:{p}" for i, p in enumerate(peers))
    commands, logs = [], []
    for i in range(members):
        client_url, peer_url = f"http://127.0.0.1:{clients[i]}", f"http://127.0.0.1:{peers[i]}"
        flags = {
            "--name": f"e{i}",
            "--data-dir": str(folder / f"e{i}"),
            "--listen-client-urls": client_url,
            "--advertise-client-urls": client_url,
            "--listen-peer-urls": peer_url,
            "--initial-advertise-peer-urls": peer_url,
            "--initial-cluster": cluster,
            "--initial-cluster-state": "new",
            "--initial-cluster-token": "kv-compare",
            "--logger": "zap",
        }
        commands.append([_program("etcd"), *(w for pair in flags.items() for w in pair)])
        logs.append(folder / f"etcd-{i}.log")
    with _processes(commands, logs):
        for port, log in zip(clients, logs, strict=True):
            _wait(f"etcd on port {port}", functools.partial(_etcd_healthy, port), log)
        yield clients


def _etcd_healthy(port: int) -> bool:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=CALL_TIMEOUT)
    try:
        conn.request("GET", "/health")
        return bool(json.loads(conn.getresponse().read()).get("health") == "true")
    finally:
        conn.close()
