"""`mapctl bench soak`: peers commit while others crash, stop, stall and come
back (issue 7 §7, issue 13 §4), and a checker verifies that nothing was lost.

P peer daemons (`LocalSwarm`: real processes on loopback) all hold two chunks:
a counter, and a bank of `ACCOUNTS` accounts whose balances sum to a fixed
total. One client per peer loops, through that peer's control endpoint and a
view of its own (the path `mapctl` takes): an increment of the counter or a
transfer between two accounts, retried on conflicts and on retriable errors.
Meanwhile the chaos (`mapbench/soak_chaos.py`) crashes a peer, stops one,
pauses one for seconds, or starts the one that is down again without `--join`,
half the time on a new port.

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
import random
import statistics
import time
from collections.abc import Callable
from dataclasses import asdict
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
from mapbench.demo.swarm import LocalSwarm, SwarmPeer
from mapbench.soak_chaos import Chaos, Node, Tally

log = logging.getLogger(__name__)

COUNTER, BANK = "soak_counter", "soak_bank"
ACCOUNTS, BALANCE = 8, 100
SETTLE_TIMEOUT = 120.0
"""Seconds the peers may take to agree once the chaos stopped."""
BACKOFF = 0.2
"""Seconds a client waits before it retries after a retriable error."""

Progress = Callable[[dict[str, Any]], None]


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
        self.chaos = Chaos(self.nodes, self.rng, self.tally, self._report)
        self.errors: list[str] = []  # errors a client did not expect

    async def run(self) -> dict[str, Any]:
        """Set up, run the clients and the chaos for `seconds`, settle and check."""
        started = time.monotonic()
        try:
            for node, peer in zip(self.nodes, await self.swarm.start(), strict=True):
                self._attach(node, peer)
            await self._setup()
            clients = [asyncio.create_task(self._client(i)) for i in range(len(self.nodes))]
            chaos = asyncio.create_task(self.chaos.run(self._stop))
            await asyncio.sleep(self.seconds)
            self._stop.set()
            await asyncio.gather(chaos)
            await asyncio.gather(*clients)
            for i, node in enumerate(self.nodes):
                if not node.up.is_set():
                    await self.chaos.start(i)
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
            "errors": [*self.errors, *self.chaos.errors],
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
