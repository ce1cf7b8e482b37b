"""`mapctl bench soak`: peers commit while others crash, leave and come back
(issue 7 §7), and a checker verifies that nothing was lost.

P peer daemons (`LocalSwarm`: real processes on loopback) all hold two chunks:
a counter, and a bank of `ACCOUNTS` accounts whose balances sum to a fixed
total. One client per peer loops, through that peer's control endpoint and a
view of its own (the path `mapctl` takes): an increment of the counter or a
transfer between two accounts, retried on conflicts and on retriable errors.
Meanwhile a chaos loop, every few seconds, kills a random peer with SIGKILL,
stops one gracefully (it leaves its chunks), or starts a stopped one again
without `--join` (it rejoins through the members it remembered and catches
up). At most one peer is down at a time, so the others are always a quorum.

At the end every peer runs again and, once they agree, the checker verifies:

- the counter: every acknowledged increment is there, and nothing else but
  increments whose outcome was unknown (their peer died mid-commit, or the
  commit was reported uncertain): `acked <= value - a0 <= acked + unknown`;
  `lost_commits` counts acknowledged increments missing;
- the bank: the total is exactly what it was;
- histories: every peer holds the same commits of both chunks, in order.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import random
import signal
import statistics
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from mapapi.core.errors import (
    CommitUncertain,
    ConflictError,
    DaemonDied,
    MapError,
    PeerNotRunning,
    ViewClosedError,
)
from mapapi.service.control import RemoteOperations
from mapapi.service.daemon_process import daemon_command, spawn_detached, stop_daemon
from mapapi.service.repo import Repository
from mapbench.demo.swarm import LocalSwarm, SwarmPeer

log = logging.getLogger(__name__)

COUNTER, BANK = "soak_counter", "soak_bank"
ACCOUNTS, BALANCE = 8, 100
CHAOS_PERIOD = (2.0, 5.0)
"""Seconds between two chaos actions (uniform)."""
SETTLE_TIMEOUT = 120.0
"""Seconds the peers may take to agree once the chaos stopped."""
BACKOFF = 0.2
"""Seconds a client waits before it retries after a retriable error."""

Progress = Callable[[dict[str, Any]], None]


@dataclass
class Tally:
    """What the clients and the chaos loop did."""

    increments: int = 0  # acknowledged
    transfers: int = 0  # acknowledged
    unknown_increments: int = 0  # the peer died mid-commit, or the commit was uncertain
    unknown_transfers: int = 0
    conflicts: int = 0
    retries: int = 0
    crashes: int = 0
    stops: int = 0
    restarts: int = 0
    restart_s: list[float] = field(default_factory=list)  # each restart until it served


@dataclass
class Node:
    """One peer of the soak: its repository and, while it runs, its client."""

    repo: Repository
    ops: RemoteOperations | None = None
    up: asyncio.Event = field(default_factory=asyncio.Event)

    async def call(self, op: str, **args: Any) -> Any:
        assert self.ops is not None
        return await self.ops.call(op, args)


class Soak:
    """One soak run (see the module docstring)."""

    def __init__(
        self, root: Path, peers: int, seconds: float, seed: int, progress: Progress | None = None
    ) -> None:
        self.swarm = LocalSwarm(root, [f"s{i}" for i in range(peers)])
        self.nodes = [Node(repo) for repo in self.swarm.repos]
        self.seconds = seconds
        self.rng = random.Random(seed)
        self.progress = progress
        self.tally = Tally()
        self.items: dict[str, Any] = {}
        self._stop = asyncio.Event()
        self.errors: list[str] = []  # errors a client did not expect

    async def run(self) -> dict[str, Any]:
        """Set up, run the clients and the chaos for `seconds`, settle and check."""
        started = time.monotonic()
        try:
            for node, peer in zip(self.nodes, await self.swarm.start(), strict=True):
                self._attach(node, peer)
            await self._setup()
            clients = [asyncio.create_task(self._client(i)) for i in range(len(self.nodes))]
            chaos = asyncio.create_task(self._chaos())
            await asyncio.sleep(self.seconds)
            self._stop.set()
            await asyncio.gather(chaos)
            await asyncio.gather(*clients)
            for i, node in enumerate(self.nodes):
                if not node.up.is_set():
                    await self._start(i)
            checked = await self._settle()
        finally:
            for node in self.nodes:
                if node.ops is not None:
                    await node.ops.close()
            await asyncio.to_thread(self.swarm.stop)
        restarts = self.tally.restart_s
        return {
            **checked,
            "commits": self.tally.increments + self.tally.transfers,
            "crashes": self.tally.crashes,
            "restarts": self.tally.restarts,
            **{k: v for k, v in asdict(self.tally).items() if k != "restart_s"},
            "restart_s_median": round(statistics.median(restarts), 2) if restarts else None,
            "restart_s_max": round(max(restarts), 2) if restarts else None,
            "errors": self.errors,
            "peers": len(self.nodes),
            "seconds": round(time.monotonic() - started, 1),
        }

    # -- setup ------------------------------------------------------------------------
    def _attach(self, node: Node, peer: SwarmPeer) -> None:
        node.ops = RemoteOperations.of(node.repo, peer.record, alive=node.repo.peer_locked)
        node.up.set()

    async def _setup(self) -> None:
        first = self.nodes[0]
        await first.call("table_create", name=COUNTER, type_name="mapapi.v1.Counter")
        await first.call("table_create", name=BANK, type_name="mapapi.v1.Account")
        chunks = {t: (await first.call("chunk_create", table=t))["id"] for t in (COUNTER, BANK)}
        await first.call("view_open", view="setup")
        data = json.dumps({"name": "c", "value": 0})
        self.items["counter"] = (await first.call("set", view="setup", table=COUNTER, data=data))[
            "id"
        ]
        self.items["accounts"] = [
            (
                await first.call(
                    "set",
                    view="setup",
                    table=BANK,
                    data=json.dumps({"owner": f"a{i}", "balance": BALANCE}),
                )
            )["id"]
            for i in range(ACCOUNTS)
        ]
        await first.call("commit", view="setup", message="soak: counter and bank")
        for node in self.nodes[1:]:
            for chunk in chunks.values():
                await node.call("participate", chunk=chunk)

    # -- the clients ---------------------------------------------------------------------
    async def _client(self, index: int) -> None:
        node, view = self.nodes[index], f"soak{index}"
        while not self._stop.is_set():
            if not node.up.is_set():
                waiting = asyncio.create_task(node.up.wait())
                stopping = asyncio.create_task(self._stop.wait())
                await asyncio.wait({waiting, stopping}, return_when=asyncio.FIRST_COMPLETED)
                waiting.cancel()
                stopping.cancel()
                continue
            transfer = self.rng.random() < 0.3
            try:
                await self._one(node, view, transfer)
            except MapError as exc:  # not retriable: unexpected, reported
                self.errors.append(f"{node.repo.root.name}: {type(exc).__name__}: {exc}")
                log.warning("soak client %d: %s", index, exc)

    async def _one(self, node: Node, view: str, transfer: bool) -> None:
        """One increment or transfer, retried until it commits or its peer goes down."""
        kind = "transfers" if transfer else "increments"
        while node.up.is_set() and not self._stop.is_set():
            try:
                await self._fresh_view(node, view)
                await (self._stage_transfer(node, view) if transfer else self._stage(node, view))
            except (DaemonDied, PeerNotRunning):  # it died or stops: nothing was committed
                return
            except MapError as exc:
                await self._back_off(exc)
                continue
            try:
                await node.call("commit", view=view, message=kind)
            except ConflictError:
                self.tally.conflicts += 1
                continue
            except PeerNotRunning:  # it refused the commit: it is stopping
                return
            except (DaemonDied, CommitUncertain):
                self._count(f"unknown_{kind}")
                return
            except MapError as exc:
                await self._back_off(exc)
                continue
            self._count(kind)
            return

    def _count(self, what: str) -> None:
        setattr(self.tally, what, getattr(self.tally, what) + 1)

    async def _back_off(self, exc: MapError) -> None:
        """Wait a little before a retry; an error that no retry can cure is raised."""
        if not exc.retriable:
            raise exc
        self.tally.retries += 1
        await asyncio.sleep(BACKOFF)

    @staticmethod
    async def _fresh_view(node: Node, view: str) -> None:
        with contextlib.suppress(ViewClosedError):  # none open: fine
            await node.call("view_abort", view=view)
        await node.call("view_open", view=view)

    async def _stage(self, node: Node, view: str) -> None:
        item = self.items["counter"]
        got = await node.call("get", view=view, table=COUNTER, item=item)
        value = got["data"]["value"] + 1
        data = json.dumps({"name": "c", "value": value})
        await node.call("set", view=view, table=COUNTER, data=data, item=item)

    async def _stage_transfer(self, node: Node, view: str) -> None:
        source, target = self.rng.sample(self.items["accounts"], 2)
        amount = self.rng.randint(1, 10)
        for item, delta in ((source, -amount), (target, amount)):
            got = await node.call("get", view=view, table=BANK, item=item)
            balance = int(got["data"].get("balance", 0)) + delta
            data = json.dumps({"owner": got["data"]["owner"], "balance": balance})
            await node.call("set", view=view, table=BANK, data=data, item=item)

    # -- chaos -------------------------------------------------------------------------------
    async def _chaos(self) -> None:
        while True:
            pause = self.rng.uniform(*CHAOS_PERIOD)
            try:
                await asyncio.wait_for(self._stop.wait(), pause)
                return
            except TimeoutError:
                pass
            down = [i for i, n in enumerate(self.nodes) if not n.up.is_set()]
            try:
                if down:
                    await self._start(down[0])
                elif self.rng.random() < 0.7:
                    await self._crash(self.rng.randrange(len(self.nodes)))
                else:
                    await self._leave(self.rng.randrange(len(self.nodes)))
            except MapError as exc:  # reported; the node stays down and starts again later
                self.errors.append(f"chaos: {type(exc).__name__}: {exc}")
                log.warning("soak chaos: %s", exc)
            self._report()

    async def _crash(self, index: int) -> None:
        node = self.nodes[index]
        record = node.repo.running_peer()
        node.up.clear()
        if record is not None:
            os.kill(record.pid, signal.SIGKILL)  # no goodbye, as a crash
            self.tally.crashes += 1
            log.info("soak: killed %s (pid %d)", node.repo.root.name, record.pid)
        # The client keeps its connection: a call in flight must end in DaemonDied
        # (its outcome unknown), not in a closed connection that hides the commit.

    async def _leave(self, index: int) -> None:
        node = self.nodes[index]
        node.up.clear()  # the client finishes the operation it is in, then waits
        self.tally.stops += 1
        try:
            await asyncio.to_thread(stop_daemon, node.repo)
        except MapError:
            record = node.repo.running_peer()
            if record is not None:  # it would not stop: end it, as a crash
                os.kill(record.pid, signal.SIGKILL)
            raise
        log.info("soak: stopped %s", node.repo.root.name)

    async def _start(self, index: int) -> None:
        node = self.nodes[index]
        await self._disconnect(node)
        argv = daemon_command(node.repo)  # no --join: it rejoins through the members it knew
        began = time.monotonic()
        record = await asyncio.to_thread(spawn_detached, node.repo, argv)  # kills one that hangs
        self.tally.restart_s.append(time.monotonic() - began)
        node.ops = RemoteOperations.of(node.repo, record, alive=node.repo.peer_locked)
        node.up.set()
        self.tally.restarts += 1
        log.info("soak: started %s again", node.repo.root.name)

    async def _disconnect(self, node: Node) -> None:
        if node.ops is not None:
            await node.ops.close()
            node.ops = None

    def _report(self) -> None:
        if self.progress is not None:
            self.progress(asdict(self.tally))

    # -- the checker ---------------------------------------------------------------------------
    async def _state(self, node: Node) -> dict[str, Any]:
        await self._fresh_view(node, "check")
        counter = await node.call("get", view="check", table=COUNTER, item=self.items["counter"])
        total = 0
        for item in self.items["accounts"]:
            got = await node.call("get", view="check", table=BANK, item=item)
            total += int(got["data"].get("balance", 0))
        history = [c["commit"] for c in await node.call("log")]
        await node.call("view_abort", view="check")
        return {
            "counter": int(counter["data"].get("value", 0)),
            "total": total,
            "history": history,
        }

    async def _settle(self) -> dict[str, Any]:
        """Wait until every peer holds the same history, then check the invariants."""
        deadline = time.monotonic() + SETTLE_TIMEOUT
        error: MapError | None = None
        while True:
            try:
                states = [await self._state(n) for n in self.nodes]
            except MapError as exc:
                states, error = [], exc
            else:
                error = None
                if len({tuple(s["history"]) for s in states}) == 1:
                    break
            if time.monotonic() > deadline:
                return {
                    "invariants_ok": False,
                    "lost_commits": None,
                    "problems": [f"the peers did not agree within {SETTLE_TIMEOUT:g} s: {error}"],
                }
            await asyncio.sleep(0.5)
        return self._check(states)

    def _check(self, states: list[dict[str, Any]]) -> dict[str, Any]:
        tally, problems = self.tally, []
        value = states[0]["counter"]
        lost = max(0, tally.increments - value)
        if lost:
            problems.append(f"{lost} acknowledged increment(s) missing")
        if value > tally.increments + tally.unknown_increments:
            problems.append(f"counter {value} counts increments nobody made")
        if {s["counter"] for s in states} != {value}:
            problems.append("the peers read different counters")
        totals = {s["total"] for s in states}
        if totals != {ACCOUNTS * BALANCE}:
            problems.append(f"the bank holds {sorted(totals)}, not {ACCOUNTS * BALANCE}")
        return {
            "invariants_ok": not problems,
            "lost_commits": lost,
            "counter": value,
            "bank_total": sorted(totals),
            "history": len(states[0]["history"]),
            "problems": problems,
        }


async def measure_soak(
    root: Path, peers: int, seconds: float, seed: int, progress: Progress | None = None
) -> dict[str, Any]:
    """One soak run in the empty folder `root` (see the module docstring)."""
    return await Soak(root, peers, seconds, seed, progress).run()
