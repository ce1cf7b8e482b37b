"""`ask_all`: every answer of requests sent at once, failures sorted out by key."""

from __future__ import annotations

import asyncio

import pytest

from mapapi.core.errors import LockTimeout, MapError, RequestTimeout
from mapapi.net.asking import ask_all


async def _answer(value: int) -> int:
    return value


async def _fails(error: MapError) -> int:
    raise error


async def _after(gate: asyncio.Event, value: int) -> int:
    await gate.wait()
    return value


class TestAskAll:
    async def test_answers_and_failures_by_key_in_the_order_asked(self) -> None:
        timeout, refused = RequestTimeout("no reply"), LockTimeout("busy")
        got = await ask_all(
            {"c": _fails(timeout), "a": _answer(1), "b": _fails(refused), "d": _answer(4)}
        )
        assert got.ok == {"a": 1, "d": 4}
        assert list(got.failed.items()) == [("c", timeout), ("b", refused)]
        with pytest.raises(RequestTimeout):
            got.raise_first()

    async def test_waits_for_every_call_even_after_a_failure(self) -> None:
        gate = asyncio.Event()
        slow = asyncio.ensure_future(_after(gate, 7))

        async def fail_then_open() -> int:
            gate.set()  # the slow call finishes only after this one failed
            raise RequestTimeout("no reply")

        got = await ask_all({1: fail_then_open(), 2: slow})
        assert got.ok == {2: 7}
        assert list(got.failed) == [1]

    async def test_nothing_to_raise_when_every_call_answered(self) -> None:
        got = await ask_all({k: _answer(k) for k in range(3)})
        got.raise_first()
        assert got.ok == {0: 0, 1: 1, 2: 2}
        assert await ask_all({}) == type(got)()

    async def test_an_error_that_is_no_map_error_is_raised(self) -> None:
        gate = asyncio.Event()
        slow = asyncio.ensure_future(_after(gate, 1))

        async def bug() -> int:
            gate.set()
            raise KeyError("a bug, not a peer that failed")

        with pytest.raises(KeyError):
            await ask_all({"bug": bug(), "slow": slow, "late": _fails(RequestTimeout("x"))})
        assert slow.done()
        assert not slow.cancelled()  # every call ran to its end first
