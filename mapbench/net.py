"""Round-trip measurement of the transport, against raw pyzmq (DESIGN §12).

    python -m mapbench.net -n 20000            # every figure, servers in subprocesses
    python -m mapbench.net -n 20000 --json
    python -m mapbench.net -n 20000 --uvloop   # if uvloop is installed

Four figures, each a Ping/Pong-sized request and its reply over loopback tcp:

- `raw-blocking`: a blocking pyzmq DEALER against a blocking ROUTER echo process (the floor);
- `raw-asyncio`: both ends through `zmq.asyncio`, one await per message;
- `rpc`: `Rpc.request` through `ZmqTransport` against an `Rpc` echo process;
- `rpc-in-process`: both `Rpc`s on one event loop, as in the swarm tests;
- `rpc-secure-in-process`: the same over CurveZMQ (a secure swarm, DESIGN §10).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Coroutine
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, TypeVar

import zmq
import zmq.asyncio

from mapapi.core.ids import PeerId
from mapapi.net.codec import Ping, Pong
from mapapi.net.rpc import Request, Rpc
from mapapi.net.security import Security
from mapapi.net.transport import ZmqTransport

T = TypeVar("T")


def _run(coro: Coroutine[Any, Any, T], use_uvloop: bool) -> T:
    if not use_uvloop:
        return asyncio.run(coro)
    import uvloop  # optional; only for this experiment

    return uvloop.run(coro)


@dataclass(frozen=True, slots=True)
class RoundTrip:
    """Latency percentiles of `n` sequential round trips, in microseconds, and the
    CPU this process used per round trip (all its threads; for an in-process figure
    that is both ends, the cost that load on a shared machine barely changes)."""

    label: str
    n: int
    p50_us: float
    p99_us: float
    mean_us: float
    cpu_us: float | None = None


def summarize(label: str, seconds: list[float], cpu_seconds: float | None = None) -> RoundTrip:
    """Percentiles of round-trip samples given in seconds (and `cpu_seconds`, the
    process CPU time they took in all)."""
    ordered = sorted(seconds)
    n = len(ordered)
    if n == 0:
        raise ValueError("no samples")
    return RoundTrip(
        label,
        n,
        ordered[n // 2] * 1e6,
        ordered[min(n - 1, int(n * 0.99))] * 1e6,
        statistics.fmean(ordered) * 1e6,
        None if cpu_seconds is None else cpu_seconds / n * 1e6,
    )


def _echo(req: Request) -> Pong:
    return Pong(req.body.payload)


async def measure_round_trip(
    n: int = 10_000,
    *,
    address: str | None = None,
    payload: int = 0,
    warmup: int = 500,
    secure: bool = False,
) -> RoundTrip:
    """Time `n` sequential `Rpc.request(Ping)` round trips.

    Args:
        n: samples to keep.
        address: an `Rpc` echo server (see `serve_rpc`); None starts one on this loop.
        payload: bytes of Ping payload.
        warmup: untimed round trips first (connection set-up, caches).
        secure: both ends on this loop over CurveZMQ, with keys that trust each other
            (ignores `address`).

    Returns:
        The percentiles, labelled "rpc", "rpc-in-process" or "rpc-secure-in-process".
    """
    with tempfile.TemporaryDirectory() as folder:
        keys = _trusting_pair(Path(folder)) if secure else (None, None)
        samples, cpu = await _round_trips(n, None if secure else address, payload, warmup, *keys)
    if secure:
        return summarize("rpc-secure-in-process", samples, cpu)
    return summarize("rpc" if address is not None else "rpc-in-process", samples, cpu)


def _trusting_pair(folder: Path) -> tuple[Security, Security]:
    """Two keypairs in `folder`, each trusting the other."""
    client, server = Security.create(folder / "client"), Security.create(folder / "server")
    client.trust.add(server.keys.public)
    server.trust.add(client.keys.public)
    return client, server


async def _round_trips(
    n: int,
    address: str | None,
    payload: int,
    warmup: int,
    client_keys: Security | None,
    server_keys: Security | None,
) -> tuple[list[float], float]:
    client = Rpc(ZmqTransport(PeerId.new(), security=client_keys))
    server: Rpc | None = None
    try:
        await client.start()
        if address is None:
            server = Rpc(ZmqTransport(PeerId.new(), security=server_keys))
            server.register(Ping, _echo)
            address = await server.start()
        body = Ping(b"x" * payload)
        samples: list[float] = []
        clock = time.perf_counter
        for _ in range(warmup):
            await client.request(address, body)
        cpu = time.process_time()
        for _ in range(n):
            start = clock()
            await client.request(address, body)
            samples.append(clock() - start)
        cpu = time.process_time() - cpu
    finally:
        await client.close()
        if server is not None:
            await server.close()
    return samples, cpu


def measure_raw_blocking(address: str, n: int, payload: bytes, warmup: int = 500) -> RoundTrip:
    """Blocking pyzmq DEALER round trips against a raw ROUTER echo."""
    ctx = zmq.Context()
    sock = ctx.socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.connect(address)
    samples: list[float] = []
    try:
        for i in range(warmup + n):
            start = time.perf_counter()
            sock.send(payload)
            sock.recv()
            if i >= warmup:
                samples.append(time.perf_counter() - start)
    finally:
        sock.close()
        ctx.term()
    return summarize("raw-blocking", samples)


async def measure_raw_asyncio(address: str, n: int, payload: bytes, warmup: int = 500) -> RoundTrip:
    """`zmq.asyncio` DEALER round trips (one await per message) against a ROUTER echo."""
    ctx = zmq.asyncio.Context()
    sock = ctx.socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.connect(address)
    samples: list[float] = []
    try:
        for i in range(warmup + n):
            start = time.perf_counter()
            await sock.send(payload)
            await sock.recv()
            if i >= warmup:
                samples.append(time.perf_counter() - start)
    finally:
        sock.close()
        ctx.term()
    return summarize("raw-asyncio", samples)


def serve_raw(bind: str) -> None:
    """A blocking ROUTER that echoes every message; prints its endpoint, runs until killed."""
    ctx = zmq.Context()
    sock = ctx.socket(zmq.ROUTER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.bind(bind)
    print(sock.getsockopt_string(zmq.LAST_ENDPOINT), flush=True)
    while True:
        sock.send_multipart(sock.recv_multipart())


async def serve_raw_asyncio(bind: str) -> None:
    """A `zmq.asyncio` ROUTER that echoes every message; prints its endpoint, runs until killed."""
    ctx = zmq.asyncio.Context()
    sock = ctx.socket(zmq.ROUTER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.bind(bind)
    print(sock.getsockopt_string(zmq.LAST_ENDPOINT), flush=True)
    while True:
        await sock.send_multipart(await sock.recv_multipart())


async def serve_rpc(bind: str) -> None:
    """An `Rpc` answering Ping with Pong; prints its endpoint, runs until cancelled."""
    server = Rpc(ZmqTransport(PeerId.new()))
    server.register(Ping, _echo)
    print(await server.start(bind), flush=True)
    try:
        await asyncio.Event().wait()
    finally:
        await server.close()


class _Server:
    """An echo server in a child process (`kind`: "raw", "raw-asyncio" or "rpc")."""

    def __init__(self, kind: str, use_uvloop: bool) -> None:
        extra = ["--uvloop"] if use_uvloop else []
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "mapbench.net", "--serve", kind, *extra],
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None
        self.address = self.proc.stdout.readline().strip()

    def __enter__(self) -> str:
        return self.address

    def __exit__(self, *exc: object) -> None:
        self.proc.terminate()
        self.proc.wait(timeout=10)
        if self.proc.stdout is not None:
            self.proc.stdout.close()


def run_all(n: int, payload: int, use_uvloop: bool = False) -> list[RoundTrip]:
    """Every figure of the module docstring, servers in subprocesses."""
    results = []
    raw = b"x" * (payload + 26)  # the size of an encoded Ping envelope
    with _Server("raw", use_uvloop) as address:
        results.append(measure_raw_blocking(address, n, raw))
    with _Server("raw-asyncio", use_uvloop) as address:
        results.append(_run(measure_raw_asyncio(address, n, raw), use_uvloop))
    with _Server("rpc", use_uvloop) as address:
        results.append(_run(measure_round_trip(n, address=address, payload=payload), use_uvloop))
    results.append(_run(measure_round_trip(n, payload=payload), use_uvloop))
    results.append(_run(measure_round_trip(n, payload=payload, secure=True), use_uvloop))
    return results


def main(argv: list[str] | None = None) -> None:
    """Command line: print the round-trip figures (text or --json)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=10_000, help="round trips per figure")
    parser.add_argument("--payload", type=int, default=0, help="Ping payload bytes")
    parser.add_argument("--json", action="store_true", help="one JSON list on stdout")
    parser.add_argument("--uvloop", action="store_true", help="run every loop on uvloop")
    parser.add_argument("--serve", choices=["raw", "raw-asyncio", "rpc"], help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve == "raw":
        serve_raw("tcp://127.0.0.1:0")
        return
    if args.serve == "raw-asyncio":
        _run(serve_raw_asyncio("tcp://127.0.0.1:0"), args.uvloop)
        return
    if args.serve == "rpc":
        _run(serve_rpc("tcp://127.0.0.1:0"), args.uvloop)
        return
    results = run_all(args.n, args.payload, args.uvloop)
    if args.json:
        print(json.dumps([asdict(r) for r in results]))
        return
    for r in results:
        cpu = f"  CPU {r.cpu_us:6.1f} µs" if r.cpu_us is not None else ""
        print(f"{r.label:22} n={r.n:6}  p50 {r.p50_us:7.1f} µs  p99 {r.p99_us:7.1f} µs{cpu}")


if __name__ == "__main__":
    main()
