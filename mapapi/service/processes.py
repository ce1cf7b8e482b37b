"""Work that holds the interpreter for long, in a process of its own (issue 14 §1).

A worker thread keeps the event loop free only while the thread waits (on
SQLite, on the disk) or runs Python bytecode, which hands the interpreter lock
over every few milliseconds. Drawing a picture runs long stretches of C (Agg)
without letting go, so a picture drawn in a thread still stalls heartbeats for
hundreds of milliseconds. `in_process` runs such work in a new process instead.

The process is started with "spawn": a daemon has threads and sockets that a
fork would copy in whatever state they were. Starting it costs about a second
(a fresh interpreter imports what the work needs), so this is for work that
takes seconds. Arguments and the result travel pickled: give arrays and small
values, not graphs of many small objects, whose pickling holds the lock too.
"""

from __future__ import annotations

import asyncio
import contextlib
import multiprocessing
import os
import pickle
from collections.abc import Callable
from functools import partial
from multiprocessing.connection import Connection
from pathlib import Path
from typing import ParamSpec, TypeVar, cast

from mapapi.core.errors import MapError

P = ParamSpec("P")
T = TypeVar("T")

NICENESS = 10
"""How much nicer (lower in the OS scheduler's priority) a job's process runs."""

AUTOGROUP = Path("/proc/self/autogroup")
"""Where a Linux process reads and sets its session's scheduling group's nice value."""


async def in_process(fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
    """`fn(*args, **kwargs)` in a new process (see the module docstring); its
    result, or what it raised. `fn` must be importable by name (a module's
    function), and its arguments and result picklable. The process is started
    and waited for from a worker thread (starting one forks and waits), and
    does one job: it exits once it answered, even if this process died meanwhile.

    Raises:
        MapError: the process died before it answered.
    """
    return await asyncio.to_thread(_run_in_child, partial(fn, *args, **kwargs))


def _run_in_child(call: Callable[[], T]) -> T:
    spawn = multiprocessing.get_context("spawn")
    receive, send = spawn.Pipe(duplex=False)
    # Pickled here and unpickled by the child once it is nicer: unpickling imports the
    # job's modules, most of a job's start (0.3 s of CPU), which must not compete with
    # the daemon at its own priority.
    job = pickle.dumps(call)
    child = spawn.Process(target=_serve, args=(job, send), name="mapapi-job", daemon=True)
    child.start()
    send.close()  # the child's end: the pipe ends (EOF) if the child dies
    try:
        ok, value = receive.recv()
    except EOFError:
        child.join()
        raise MapError(
            f"the job's process died (exit {child.exitcode}); see the peer's log"
        ) from None
    finally:
        receive.close()
    child.join()
    if ok:
        return cast(T, value)
    raise value


def _step_back() -> None:
    """Make this process `NICENESS` steps nicer, in a session of its own as nice.

    Linux's autogroups (on by default in many kernels, this project's machines
    included) weigh each session as one task: a job left in the daemon's session
    took its CPU time out of the daemon's own share, whatever its nice value: in
    the stall benchmark the peers' loops waited in the run queue for up to 0.3 s
    at a time (their main threads' /proc/PID/task/TID/schedstat). A session of its own,
    made as nice as the job, takes the time from the job's share alone.
    """
    with contextlib.suppress(OSError):
        os.nice(NICENESS)
    with contextlib.suppress(OSError):  # no autogroups here, or may not set them
        os.setsid()
        AUTOGROUP.write_text(str(NICENESS), encoding="ascii")


def _serve(job: bytes, send: Connection) -> None:
    """What the child runs: the pickled call, then its result or error down the
    pipe. It runs `NICENESS` steps nicer than the daemon, from before it imports
    what the call needs, so on a busy machine the daemon's loop gets a core first
    (a job only takes longer)."""
    _step_back()
    try:
        answer: tuple[bool, object] = (True, pickle.loads(job)())
    except Exception as exc:  # sent to the parent, which raises it
        answer = (False, exc)
    try:
        send.send(answer)
    except Exception as exc:  # an answer that does not pickle
        send.send((False, MapError(f"the job's answer could not be sent back: {exc!r}")))
    finally:
        send.close()
