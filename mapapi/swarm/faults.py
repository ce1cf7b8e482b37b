"""Fault injection points, for the failure tests and the soak bench (issue 7).

A few places of the commit protocol call `await reached("name")`. Nothing
happens there unless a test armed the point: in-process with `arm`, or in a
peer daemon through the environment, `MAPAPI_FAULTS="commit.staged=pause"`
(comma-separated). A daemon's actions are:

- ``pause``: log ``fault point NAME reached`` and wait for ever, so that a test
  can `kill -9` the process at exactly that moment of a commit;
- ``crash``: kill the process with SIGKILL on the spot;
- ``block:SECONDS``: block the daemon's event loop for SECONDS (a `time.sleep`
  on the loop, as a slow command once did), then go on: nothing is sent,
  received or ticked meanwhile, and the other peers carry on without it.

The points, both on the writer's side of a commit through the chunks' logs
(`swarm/log_commit.py`): ``commit.acknowledged`` (the chunk's log took the
commit: a majority of its voters hold it; the writer has not answered its
caller) and ``commit.prepared`` (every chunk of a multi-chunk transaction
holds its prepare; no decision is proposed yet, so the chunks' leaders settle
it from the first chunk's log, `swarm/tx_recovery.py`).
"""

from __future__ import annotations

import asyncio
import functools
import logging
import os
import signal
import time
from collections.abc import Awaitable, Callable, Mapping

from mapapi.core.errors import UsageError

log = logging.getLogger(__name__)

POINTS = ("commit.acknowledged", "commit.prepared")
ENV = "MAPAPI_FAULTS"

Action = Callable[[], Awaitable[None]]
_armed: dict[str, Action] = {}


async def reached(point: str) -> None:
    """Run the action armed at `point`, if any (normally none)."""
    action = _armed.get(point)
    if action is not None:
        await action()


def arm(point: str, action: Action) -> None:
    """Run `action` whenever `point` is reached (until `disarm`).

    Raises:
        UsageError: no such point.
    """
    if point not in POINTS:
        raise UsageError(f"no fault point {point!r}; the points are {', '.join(POINTS)}")
    _armed[point] = action


def disarm(point: str | None = None) -> None:
    """Disarm `point`, or every point."""
    if point is None:
        _armed.clear()
    else:
        _armed.pop(point, None)


async def _pause(point: str) -> None:
    log.warning("fault point %s reached; pausing until killed", point)
    await asyncio.Event().wait()


async def _crash(point: str) -> None:
    log.warning("fault point %s reached; crashing", point)
    os.kill(os.getpid(), signal.SIGKILL)


async def _block(point: str, seconds: float) -> None:
    log.warning("fault point %s reached; blocking the event loop for %g s", point, seconds)
    time.sleep(seconds)  # noqa: ASYNC251 (on purpose: the loop stops, as under a slow command)
    log.warning("fault point %s: the event loop runs again", point)


_ACTIONS = {"pause": _pause, "crash": _crash}


def arm_from_env(environ: Mapping[str, str]) -> None:
    """Arm the points `MAPAPI_FAULTS` names, e.g. ``commit.staged=pause``.

    Raises:
        UsageError: a malformed entry, an unknown point or action.
    """
    for entry in filter(None, (e.strip() for e in environ.get(ENV, "").split(","))):
        point, _, name = entry.partition("=")
        kind, _, text = name.partition(":")
        seconds = _seconds(text) if kind == "block" else None
        if seconds is not None:
            arm(point, functools.partial(_block, point, seconds))
            continue
        action = _ACTIONS.get(name)
        if action is None:
            raise UsageError(
                f"{ENV}: {entry!r} is not POINT=pause, POINT=crash or POINT=block:SECONDS"
            )
        arm(point, functools.partial(action, point))


def _seconds(text: str) -> float | None:
    """`text` as a number of seconds, or None."""
    try:
        value = float(text)
    except ValueError:
        return None
    return value if value >= 0 else None
