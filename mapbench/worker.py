"""A peer process for swarm experiments, driven over stdin/stdout (STYLE §7).

    python -m mapbench.worker --repo DIR [--name NAME] [--uvloop] [--secure]

The worker opens the repository in DIR (creating it if needed, secure with
`--secure`: its address then carries its key, DESIGN §10), starts a peer on
tcp://127.0.0.1:0 and prints `ready {"id", "address", "name"}`. It then reads one
command per line from stdin and answers each with exactly one line
`WORD {json}` (or `error {"error", "message"}`), so the parent always knows
which step finished:

    trust KEY...                  -> trusted {"keys"}              a secure peer's trust list
    join ADDR                     -> joined {"members"}
    create A0                     -> created {"chunk", "item"}     table + chunk + counter
    participate CHUNK             -> participating {"chunk", "holders"}
    holders CHUNK                 -> holders {"holders"}
    run N ITEM [DEADLINE_S]       -> ran {"commits", "aborts", "conflicts", "lock_timeouts",
                                          "other_retries", "increment_ms", "commit_ms",
                                          "seconds", "cpu_s", "loop_thread_cpu_s",
                                          "messages_sent", "messages_received",
                                          "sent_by_type"}
    value ITEM                    -> value {"value", "log"}
    log                           -> log {"ids"}                   newest first
    stats                         -> stats {"cpu_s", "sent", "sent_bytes", "received",
                                            "sent_by_type"}
    robot | seed | stream | digest                                 a mapping robot's
                                  commands (`bench mapping`), see `mapbench.robot`
    quit                          -> bye {}                        then the process exits

`run` is paper Algorithm 1: N times, begin a transaction, read the counter,
write value + 1 and commit, beginning again after a conflict, a lock timeout
or any other retriable error. Every wait has a deadline (`run` defaults to 120
s for all N increments; the network calls have their own). The worker exits on
`quit`, on end of stdin, and (on Linux) when its parent dies.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import os
import signal
import sys
import time
from collections import Counter as Tally
from pathlib import Path
from typing import Any

from mapapi.app import peer_of
from mapapi.core.errors import ConflictError, LockTimeout, MapError, UsageError
from mapapi.core.ids import ChunkId, ItemId
from mapapi.core.table import message_class
from mapapi.net.security import parse_key
from mapapi.service.peer import Peer
from mapapi.service.repo import Repository
from mapbench import robot

log = logging.getLogger(__name__)

TABLE = "counters"
TYPE = "mapapi.v1.Counter"
RUN_DEADLINE = 120.0
_PR_SET_PDEATHSIG = 1


def die_with_parent() -> None:
    """Ask Linux to SIGKILL this process when its parent exits (best effort)."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)


def open_repo(folder: Path, name: str, secure: bool = False) -> Repository:
    """The repository in `folder`, initialised first (`secure` or open) if there is none."""
    if (folder / ".mapapi").is_dir():
        return Repository.find(folder)
    return Repository.init(folder, name, secure=secure)


class Worker:
    """One peer and the commands of the module docstring."""

    def __init__(self, peer: Peer) -> None:
        self.peer = peer
        self.counter = message_class(TYPE)
        self.robot = robot.Robot(peer)

    def _stats(self) -> Any:
        assert self.peer.swarm is not None
        return self.peer.swarm.rpc.transport.stats

    async def handle(self, words: list[str]) -> tuple[str, dict[str, Any]]:
        """Run one command; returns the reply word and its JSON body."""
        verb, args = words[0], words[1:]
        if verb in robot.COMMANDS:
            return await self.robot.handle(verb, args)
        if verb == "join":
            members = await self.peer.join(_arg(args, 0))
            return "joined", {"members": len(members)}
        if verb == "trust":
            if self.peer.security is None:
                raise UsageError("this peer is open: start it with --secure")
            added = [self.peer.security.trust.add(parse_key(k)) for k in args]
            return "trusted", {"keys": len(added)}
        if verb == "create":
            return "created", await self.create(int(args[0]) if args else 0)
        if verb == "participate":
            chunk = ChunkId(_arg(args, 0))
            await self.peer.participate(chunk)
            return "participating", {"chunk": str(chunk), "holders": len(self.peer.holders(chunk))}
        if verb == "holders":
            return "holders", {"holders": [str(p) for p in self.peer.holders(ChunkId(args[0]))]}
        if verb == "run":
            deadline = float(args[2]) if len(args) > 2 else RUN_DEADLINE
            return "ran", await self.run(int(_arg(args, 0)), ItemId(_arg(args, 1)), deadline)
        if verb == "value":
            return "value", await self.value(ItemId(_arg(args, 0)))
        if verb == "log":
            return "log", {"ids": [str(c.id) for c in self.peer.log()]}
        if verb == "stats":
            stats = self._stats()
            return "stats", {
                "cpu_s": time.process_time(),
                "sent": sum(t.messages for t in stats.sent.values()),
                "sent_bytes": sum(t.bytes for t in stats.sent.values()),
                "received": sum(t.messages for t in stats.received.values()),
                "sent_by_type": {k: t.messages for k, t in stats.sent_by_type().items()},
            }
        raise UsageError(f"unknown command {verb!r}")

    async def create(self, a0: int) -> dict[str, Any]:
        """A table, a chunk held here, and one counter starting at `a0`."""
        if TABLE not in self.peer.store.tables():
            await self.peer.create_table(TABLE, TYPE)
        chunk = await self.peer.create_chunk(TABLE)
        tx = self.peer.begin()
        item = tx.insert(TABLE, self.counter(name="a", value=a0), chunk)
        await tx.commit("create the counter")
        return {"chunk": str(chunk), "item": str(item)}

    async def value(self, item: ItemId) -> dict[str, Any]:
        """The counter's value as a new transaction reads it, and the log length."""
        message = await self.peer.begin().get(TABLE, item)
        if message is None:
            raise UsageError(f"no counter {item} here")
        return {"value": int(message.value), "log": len(self.peer.log())}  # type: ignore[attr-defined]

    async def run(self, n: int, item: ItemId, deadline: float) -> dict[str, Any]:
        """Paper Algorithm 1: `n` increments of `item`, retried until each commits."""
        stats = self._stats()
        sent0 = {k: t.messages for k, t in stats.sent_by_type().items()}
        received0 = sum(t.messages for t in stats.received.values())
        retries: Tally[str] = Tally()
        increment_ms: list[float] = []
        commit_ms: list[float] = []
        clock = time.perf_counter
        cpu0, thread0 = time.process_time(), time.thread_time()
        started = clock()
        async with asyncio.timeout(deadline):
            for _ in range(n):
                first = clock()
                while True:
                    try:  # the whole attempt: a read may fail for a moment too (NoQuorum)
                        tx = self.peer.begin()
                        current = await tx.get(TABLE, item)
                        if current is None:
                            raise UsageError(f"no counter {item} here")
                        value = int(current.value) + 1  # type: ignore[attr-defined]
                        tx.update(TABLE, item, self.counter(name="a", value=value))
                        attempt = clock()
                        await tx.commit(f"{self.peer.name} -> {value}")
                    except MapError as exc:
                        if not exc.retriable:
                            raise
                        retries[_retry_kind(exc)] += 1
                        continue
                    done = clock()
                    commit_ms.append((done - attempt) * 1e3)
                    increment_ms.append((done - first) * 1e3)
                    break
        seconds = clock() - started
        cpu, thread = time.process_time() - cpu0, time.thread_time() - thread0
        sent = {k: t.messages - sent0.get(k, 0) for k, t in stats.sent_by_type().items()}
        return {
            "commits": n,
            "aborts": sum(retries.values()),
            "conflicts": retries["conflict"],
            "lock_timeouts": retries["lock_timeout"],
            "other_retries": retries["other"],
            "increment_ms": [round(x, 4) for x in increment_ms],
            "commit_ms": [round(x, 4) for x in commit_ms],
            "seconds": seconds,
            "cpu_s": cpu,
            "loop_thread_cpu_s": thread,
            "messages_sent": sum(sent.values()),
            "messages_received": sum(t.messages for t in stats.received.values()) - received0,
            "sent_by_type": {k: v for k, v in sorted(sent.items()) if v},
        }


def _retry_kind(exc: MapError) -> str:
    if isinstance(exc, ConflictError):
        return "conflict"
    if isinstance(exc, LockTimeout):
        return "lock_timeout"
    log.info("retrying after %s: %s", type(exc).__name__, exc)
    return "other"


def _arg(args: list[str], index: int) -> str:
    if len(args) <= index:
        raise UsageError(f"missing argument {index + 1}")
    return args[index]


def _say(word: str, body: dict[str, Any]) -> None:
    sys.stdout.write(f"{word} {json.dumps(body)}\n")
    sys.stdout.flush()


async def _stdin_lines() -> asyncio.StreamReader:
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader(limit=1 << 20)
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    return reader


async def serve(args: argparse.Namespace) -> None:
    """Start the peer, announce it, and answer commands until quit or EOF."""
    repo = open_repo(Path(args.repo), args.name or Path(args.repo).name, args.secure)
    peer = peer_of(repo)  # the application's peer, with the map tables' rules
    try:
        address = await peer.start(args.listen)
        _say("ready", {"id": str(peer.id), "address": address, "name": peer.name})
        worker = Worker(peer)
        reader = await _stdin_lines()
        while True:
            raw = await reader.readline()
            words = raw.decode().split()
            if not raw or words[:1] == ["quit"]:
                break
            if not words:
                continue
            try:
                word, body = await worker.handle(words)
            except (MapError, ValueError, TimeoutError) as exc:
                log.warning("command %s failed: %s", words[0], exc)
                word, body = "error", {"error": type(exc).__name__, "message": str(exc)}
            _say(word, body)
    finally:
        await peer.close()
    _say("bye", {})


def main(argv: list[str] | None = None) -> None:
    """Command line: see the module docstring."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", required=True, help="repository folder (created if missing)")
    parser.add_argument("--name", default="", help="peer name for a new repository")
    parser.add_argument("--listen", default="tcp://127.0.0.1:0", help="zmq endpoint")
    parser.add_argument("--uvloop", action="store_true", help="run the event loop on uvloop")
    parser.add_argument("--secure", action="store_true", help="a new repository is secure")
    parser.add_argument("--log-level", default="WARNING", help="stderr logging level")
    args = parser.parse_args(argv)
    die_with_parent()
    logging.basicConfig(
        level=args.log_level,
        stream=sys.stderr,
        format=f"%(asctime)s {os.getpid()} %(levelname)s %(name)s: %(message)s",
    )
    if args.uvloop:
        import uvloop  # optional; only for experiments

        uvloop.run(serve(args))
    else:
        asyncio.run(serve(args))


if __name__ == "__main__":
    main()
