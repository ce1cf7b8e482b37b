"""Work in a process of its own (mapapi.service.processes): the answer comes back,
so does an error, and a process that dies says so instead of hanging."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest

from mapapi.core.errors import MapError
from mapapi.service.processes import NICENESS, in_process

pytestmark = pytest.mark.slow  # each call starts a Python process


async def test_the_answer_comes_from_another_process() -> None:
    assert await in_process(os.getpid) != os.getpid()
    assert await in_process(math.hypot, 3.0, 4.0) == 5.0


async def test_an_error_is_raised_here() -> None:
    with pytest.raises(ValueError, match="math domain error"):
        await in_process(math.sqrt, -1.0)


async def test_a_process_that_dies_before_it_answers_is_an_error() -> None:
    with pytest.raises(MapError, match=r"died \(exit 3\)"):
        await in_process(os._exit, 3)


def _where_it_runs() -> tuple[int, int, str]:
    """The job's session, nice value and (where Linux has them) autogroup line."""
    group = Path("/proc/self/autogroup")
    return os.getsid(0), os.nice(0), group.read_text() if group.exists() else ""


async def test_a_job_runs_nicer_in_a_session_of_its_own() -> None:
    session, nice, group = await in_process(_where_it_runs)

    assert session != os.getsid(0)
    assert nice == min(19, os.nice(0) + NICENESS)
    if group:  # this kernel has autogroups: the job's own, as nice as the job
        assert group.split()[-1] == str(NICENESS)
