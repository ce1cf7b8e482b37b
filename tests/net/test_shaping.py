"""Simulated latency and bandwidth: the arithmetic (pure) and that shaped links deliver."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mapapi.net import LinkShape, Ping, Pong, Shaper
from mapapi.net.shaping import schedule

from .conftest import MakeRpc

shapes = st.builds(
    LinkShape,
    latency=st.floats(0, 10, allow_nan=False),
    bandwidth=st.none() | st.floats(1, 1e9, allow_nan=False),
)
times = st.floats(0, 1e6, allow_nan=False)


class TestSchedule:
    @given(times, times, st.integers(0, 10**8), shapes)
    def test_delay_is_at_least_latency_plus_transmission(
        self, now: float, busy: float, size: int, shape: LinkShape
    ) -> None:
        arrival, busy_after = schedule(now, busy, size, shape)
        transmit = size / shape.bandwidth if shape.bandwidth else 0.0
        assert arrival - now >= shape.latency + transmit - 1e-6
        assert busy_after >= max(now, busy)
        assert arrival >= busy_after

    def test_idle_link(self) -> None:
        assert schedule(10.0, 0.0, 1000, LinkShape(0.05, 10_000)) == (10.15, 10.1)

    def test_back_to_back_messages_queue_behind_each_other(self) -> None:
        shape = LinkShape(latency=0.01, bandwidth=1000)
        first, busy = schedule(0.0, 0.0, 500, shape)
        second, _ = schedule(0.0, busy, 500, shape)
        assert (first, second) == (pytest.approx(0.51), pytest.approx(1.01))

    @pytest.mark.parametrize(
        "kwargs", [{"latency": -1}, {"latency": float("inf")}, {"bandwidth": 0}]
    )
    def test_invalid_shapes(self, kwargs: dict[str, float]) -> None:
        with pytest.raises(ValueError, match="must be"):
            LinkShape(**kwargs)


class TestShaper:
    def test_off_by_default(self) -> None:
        assert Shaper().arrival("peer", 10**6, now=5.0) is None

    def test_per_link_shape_overrides_the_default(self) -> None:
        shaper = Shaper(LinkShape(latency=0.1))
        shaper.set_link("fast", LinkShape())
        assert shaper.arrival("fast", 100, now=1.0) is None
        assert shaper.arrival("slow", 100, now=1.0) == pytest.approx(1.1)

    def test_arrivals_on_a_link_strictly_increase(self) -> None:
        shaper = Shaper(LinkShape(latency=0.5))
        arrivals = [shaper.arrival("p", 0, now=1.0) for _ in range(5)]
        assert all(a is not None for a in arrivals)
        assert arrivals == sorted(set(arrivals))  # type: ignore[type-var]


class TestShapedTransport:
    async def test_shaped_links_still_deliver_and_count(self, make_rpc: MakeRpc) -> None:
        shape = LinkShape(latency=0.005, bandwidth=1e6)
        client = await make_rpc(shaper=Shaper(shape))
        server = await make_rpc(shaper=Shaper(shape))
        server.register(Ping, lambda req: Pong(req.body.payload))
        assert await client.request(server.address, Ping(b"x" * 1000)) == Pong(b"x" * 1000)
        assert client.transport.stats.sent_by_type()["ping"].messages == 1
        assert server.transport.stats.sent_by_type()["pong"].messages == 1

    async def test_close_cancels_messages_still_in_flight(self, make_rpc: MakeRpc) -> None:
        client = await make_rpc(shaper=Shaper(LinkShape(latency=60)))
        server = await make_rpc()
        client.notify(server.address, Ping())
        await client.close()
        assert client.transport.stats.sent == {}
