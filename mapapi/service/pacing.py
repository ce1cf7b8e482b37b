"""The interpreter settings that let a peer daemon's event loop keep its pace
(issue 14 §1), whatever its worker threads do.

Long reads and writes run in worker threads (`mapapi.store.offload`), but the
threads share the interpreter lock and the cyclic garbage collector with the
loop. Two settings of the interpreter, measured on the project's 2-core
machine with a 100,000-item export, a plot and a load of 50,000 items (see
docs/benchmarks.md), decide how late the loop then runs:

- **The garbage collector's full passes.** A full pass visits every object the
  process holds and keeps the lock all along: 100-800 ms with the 300,000
  objects of a chunk transfer in flight, and by default one runs whenever the
  objects that outlived younger passes grew by a quarter, which a transfer or
  a decoded mission does again and again (13 to 20 full passes, up to 0.9 s
  each, in one load). The daemon freezes what it holds once it serves (the
  modules, the protobuf descriptors: never garbage, now never visited), makes
  full passes rare (`FULL_AFTER` young passes instead of 10) and runs one
  itself every `FULL_EVERY` seconds, when it holds little else. The young
  generations keep their defaults: their passes visit only recent objects.
- **The switch interval.** A thread that wants the lock asks for it, and the
  holder lets go after the interval (5 ms by default); the loop asks again at
  every socket call and every wake-up, so beside a busy thread it waited up to
  the interval each time. `SWITCH_INTERVAL` (1 ms) lets it in sooner, at the
  cost of more switches for the threads.

Both are settings of the whole process: `Pacing` sets them for the daemon's
lifetime and puts the old ones back when it stops (a test serves daemons in
its own process).
"""

from __future__ import annotations

import asyncio
import gc
import logging
import sys
import time

log = logging.getLogger(__name__)

SWITCH_INTERVAL = 0.001
"""Seconds a thread holds the interpreter lock when another asks for it."""

FULL_AFTER = 10_000
"""Passes of the middle generation between two full passes the collector itself
decides on (Python's default: 10)."""

FULL_EVERY = 300.0
"""Seconds between the daemon's own full passes, which collect what the rare
automatic ones would have (reference cycles: a task's exception and its frames)."""


class Pacing:
    """The daemon's interpreter settings (see the module docstring)."""

    def __init__(self, full_every: float = FULL_EVERY) -> None:
        self.full_every = full_every
        self._saved: tuple[tuple[int, int, int], float] | None = None
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        """Set the switch interval and the collector's thresholds, and start the
        periodic full pass."""
        self._saved = (gc.get_threshold(), sys.getswitchinterval())
        young, middle, _ = self._saved[0]
        gc.set_threshold(young, middle, FULL_AFTER)
        sys.setswitchinterval(SWITCH_INTERVAL)
        self._task = asyncio.get_running_loop().create_task(self._collect(), name="gc")

    def settle(self) -> None:
        """Once the daemon serves: freeze what it holds (every later pass skips
        it). The little garbage starting left is frozen with it: collecting it
        first is a full pass, 100-150 ms on the loop, for a few hundred objects."""
        gc.freeze()
        log.debug("froze %d objects", gc.get_freeze_count())

    async def _collect(self) -> None:
        while True:
            await asyncio.sleep(self.full_every)
            started = time.perf_counter()
            found = gc.collect()
            log.debug("full collection: %d found in %.3f s", found, time.perf_counter() - started)

    async def close(self) -> None:
        """Stop the periodic pass and put the old settings back."""
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
        if self._saved is not None:
            threshold, switch = self._saved
            gc.unfreeze()
            gc.set_threshold(*threshold)
            sys.setswitchinterval(switch)
            self._saved = None
