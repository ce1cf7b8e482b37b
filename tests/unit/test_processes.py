"""Work in a process of its own (mapapi.service.processes): the answer comes back,
so does an error, and a process that dies says so instead of hanging."""

from __future__ import annotations

import math
import os

import pytest

from mapapi.core.errors import MapError
from mapapi.service.processes import in_process

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
