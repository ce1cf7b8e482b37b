"""Asking several peers at once: every answer (`ask_all`), or the first good one
(`first_answer`). Requests run concurrently; a peer that fails with a `MapError`
counts as no answer, anything else is a bug and raised."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from mapapi.core.errors import MapError

T = TypeVar("T")
K = TypeVar("K", bound=Hashable)


async def first_answer(
    calls: Sequence[Awaitable[T]], accept: Callable[[T], bool] = lambda _answer: True
) -> T | None:
    """The first answer of `calls` (requests run at once) that `accept` takes; the
    others are cancelled. A call that fails with a MapError counts as no answer;
    None if no call gave one."""
    pending = [asyncio.ensure_future(call) for call in calls]
    try:
        for next_done in asyncio.as_completed(pending):
            try:
                answer = await next_done
            except MapError:
                continue
            if accept(answer):
                return answer
        return None
    finally:
        for fut in pending:
            fut.cancel()
        await asyncio.gather(*pending, return_exceptions=True)


@dataclass(frozen=True, slots=True)
class Answers(Generic[K, T]):
    """What `ask_all` gathered, by key, in the order the calls were given.

    Attributes:
        ok: the answers of the calls that succeeded.
        failed: the MapError of each call that failed (a peer that did not answer,
            or refused).
    """

    ok: dict[K, T] = field(default_factory=dict)
    failed: dict[K, MapError] = field(default_factory=dict)

    def raise_first(self) -> None:
        """Raise the first failure, in the order the calls were given, if any.

        Raises:
            MapError: that failure.
        """
        for error in self.failed.values():
            raise error


async def ask_all(calls: Mapping[K, Awaitable[T]]) -> Answers[K, T]:
    """Run `calls` (requests to several peers, say, keyed by peer) at once and
    wait for every one; a call failing with a MapError does not stop the others.
    The caller then raises the first failure (`Answers.raise_first`) or logs them.
    Give each call its own key: a dict comprehension repeating one drops a call unawaited.

    Raises:
        Exception: the first failure that is no MapError (a bug), once every call
            has finished; cancelling `ask_all` cancels the calls.
    """
    keys = list(calls)
    results = await asyncio.gather(*calls.values(), return_exceptions=True)
    answers: Answers[K, T] = Answers()
    for key, result in zip(keys, results, strict=True):
        if isinstance(result, MapError):
            answers.failed[key] = result
        elif isinstance(result, BaseException):
            raise result
        else:
            answers.ok[key] = result
    return answers
