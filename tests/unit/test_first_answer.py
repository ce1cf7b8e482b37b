"""`first_answer`: the first acceptable reply of requests sent at once."""

from __future__ import annotations

import asyncio

from mapapi.core.errors import RequestTimeout
from mapapi.net.asking import first_answer


async def _after(gate: asyncio.Event, value: int) -> int:
    await gate.wait()
    return value


async def _fails() -> int:
    raise RequestTimeout("no reply")


async def test_the_first_accepted_answer_wins_and_the_rest_are_cancelled() -> None:
    never = asyncio.Event()
    slow = asyncio.ensure_future(_after(never, 3))
    answered = asyncio.Event()
    answered.set()
    got = await first_answer(
        [_fails(), _after(answered, 0), _after(answered, 2), slow], lambda n: n > 0
    )
    assert got == 2
    assert slow.cancelled()


async def test_none_when_every_call_fails_or_is_refused() -> None:
    answered = asyncio.Event()
    answered.set()
    assert await first_answer([_fails(), _after(answered, 0)], lambda n: n > 0) is None
    assert await first_answer([]) is None
