"""`mapctl bench flood`: strangers send a peer huge messages; its memory must stay bounded.

Issue 18 §5's probe: 20 unauthenticated senders, each sending one 120 MB frame,
pushed an open peer to 1.65 GB resident. This benchmark starts a real peer
process (an open in-memory `Peer` on 127.0.0.1, `python -m mapbench.flood peer`),
floods it from N sender processes (`python -m mapbench.flood send`), samples the
peer's resident memory (VmRSS) every few milliseconds, pings it throughout, and
reports the peak as JSON. Two kinds of flood:

- `frame`: each sender sends its bytes as one zmq frame (the probe);
- `parts`: each sender sends them as a mapapi peer sends a large message, in
  parts of `limits.FRAME_BYTES` (`mapapi.net.parts`), so the peer's reassembly
  budget is what bounds it.

Senders send zero pages from an anonymous mmap, which costs them no memory.
"""

from __future__ import annotations

import asyncio
import json
import mmap
import os
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from mapapi.core import limits
from mapapi.core.ids import PeerId
from mapapi.net import Ping, Pong, Rpc, ZmqTransport, parts

MODES = ("frame", "parts")
SAMPLE_S = 0.005
"""How often the peer's resident memory is read."""
PING_S = 0.1
"""How often the peer is pinged during the flood."""
PING_TIMEOUT_S = 5.0


@dataclass
class FloodReport:
    """What one flood did to the peer.

    Attributes:
        mode: "frame" or "parts".
        senders: sender processes.
        megabytes: bytes each sent, in MB.
        rss_idle_mb: the peer's resident memory before the flood.
        rss_peak_mb: the most it was during the flood and the settling time.
        pings: pings answered during the flood (all sent were answered, or it fails).
        ping_max_ms: the slowest of them.
        dropped: the peer's drop counters by reason after the flood.
        parts_peak_mb: the most the peer held reserved for messages in parts.
    """

    mode: str
    senders: int
    megabytes: int
    rss_idle_mb: float
    rss_peak_mb: float
    pings: int
    ping_max_ms: float
    dropped: dict[str, int]
    parts_peak_mb: float


def rss_mb(pid: int) -> float:
    """Resident memory of process `pid` in MB (Linux /proc)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"no VmRSS for pid {pid}")


def run_flood(senders: int, megabytes: int, mode: str, settle: float = 1.0) -> FloodReport:
    """Start a peer process, flood it from `senders` processes of `megabytes`
    each in `mode`, and measure it (see the module doc).

    Raises:
        RuntimeError: the peer died, or a ping went unanswered.
    """
    if mode not in MODES:
        raise ValueError(f"mode is one of {MODES}, not {mode!r}")
    # Leaving the block closes the peer's stdin (it then stops) and waits for it.
    with subprocess.Popen(
        [sys.executable, "-m", "mapbench.flood", "peer"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    ) as peer:
        assert peer.stdin is not None
        assert peer.stdout is not None
        address = peer.stdout.readline().strip()
        if not address:
            raise RuntimeError("the flooded peer did not start")
        report = asyncio.run(_flood(peer.pid, address, senders, megabytes, mode, settle))
        peer.stdin.write("stats\n")
        peer.stdin.flush()
        stats = json.loads(peer.stdout.readline())
        report.dropped, report.parts_peak_mb = stats["dropped"], stats["parts_peak"] / 2**20
        return report


async def _flood(
    pid: int, address: str, senders: int, megabytes: int, mode: str, settle: float
) -> FloodReport:
    client = Rpc(ZmqTransport(PeerId.new()))
    await client.start()
    try:
        await client.request(address, Ping(b""), timeout=PING_TIMEOUT_S, expect=Pong)
        idle = rss_mb(pid)
        peak = [idle]
        sampler = asyncio.get_running_loop().create_task(_sample(pid, peak))
        procs = [
            await asyncio.create_subprocess_exec(
                sys.executable, "-m", "mapbench.flood", "send", address, str(megabytes), mode
            )
            for _ in range(senders)
        ]
        latencies: list[float] = []
        waiting = asyncio.gather(*(p.wait() for p in procs))
        try:
            while not waiting.done():
                latencies.append(await _ping(client, address))
                await asyncio.wait({waiting}, timeout=PING_S)  # a pace, not a sync
            deadline = time.monotonic() + settle  # what libzmq still holds drains
            while time.monotonic() < deadline:
                latencies.append(await _ping(client, address))
                await asyncio.sleep(PING_S)  # sync-ok: the settling window's pace
        finally:
            sampler.cancel()
            await asyncio.gather(sampler, waiting, return_exceptions=True)
        return FloodReport(
            mode, senders, megabytes, round(idle, 1), round(peak[0], 1),
            len(latencies), round(max(latencies) * 1000, 1), {}, 0.0,
        )  # fmt: skip
    finally:
        await client.close()


async def _ping(client: Rpc, address: str) -> float:
    began = time.perf_counter()
    await client.request(address, Ping(b""), timeout=PING_TIMEOUT_S, expect=Pong)
    return time.perf_counter() - began


async def _sample(pid: int, peak: list[float]) -> None:
    while True:
        peak[0] = max(peak[0], rss_mb(pid))
        await asyncio.sleep(SAMPLE_S)  # sync-ok: a sampling period


# -- the child processes ------------------------------------------------------------------
async def _serve_peer() -> None:
    from mapapi import Peer

    peer = Peer.in_memory()
    address = await peer.start()
    print(address, flush=True)
    loop = asyncio.get_running_loop()
    try:
        while line := await loop.run_in_executor(None, sys.stdin.readline):
            if line.strip() == "stats":
                assert peer.swarm is not None
                transport = peer.swarm.rpc.transport
                dropped: dict[str, int] = {}
                for (_, reason), traffic in transport.stats.dropped.items():
                    dropped[reason] = dropped.get(reason, 0) + traffic.messages
                peak = transport.parts.peak if isinstance(transport, ZmqTransport) else 0
                print(json.dumps({"dropped": dropped, "parts_peak": peak}), flush=True)
    finally:
        await peer.close()


def _send(address: str, megabytes: int, mode: str) -> None:
    import zmq

    size = megabytes * 1_000_000
    zeros = mmap.mmap(-1, size)  # zero pages: no memory until written
    ctx = zmq.Context()
    sock = ctx.socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 30_000)  # long enough for the bytes to leave
    sock.connect(address)
    try:
        if mode == "frame":
            sock.send(memoryview(zeros), copy=False)
        else:
            view = memoryview(zeros)
            step = limits.FRAME_BYTES
            for offset in range(0, size, step):
                header = parts.header(os.getpid(), size, offset)
                sock.send_multipart([header, view[offset : offset + step]], copy=False)
    finally:
        sock.close()  # LINGER: returns once the queued bytes left (or after 30 s)
        ctx.term()


def main(argv: list[str]) -> None:
    """`peer` serves until stdin closes; `send ADDRESS MEGABYTES MODE` floods."""
    if argv[:1] == ["peer"]:
        asyncio.run(_serve_peer())
    elif argv[:1] == ["send"] and len(argv) == 4:
        _send(argv[1], int(argv[2]), argv[3])
    else:
        raise SystemExit("usage: python -m mapbench.flood peer | send ADDRESS MEGABYTES MODE")


if __name__ == "__main__":
    main(sys.argv[1:])


__all__ = ["MODES", "FloodReport", "asdict", "rss_mb", "run_flood"]
