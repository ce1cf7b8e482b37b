"""Large messages as parts (issue 18 §5): the pure reassembly and its budget, then
a message of several parts through real sockets."""

from __future__ import annotations

from mapapi.core import limits
from mapapi.net import Ping, Pong, parts
from tests.net.conftest import MakeRpc

MB = 2**20


def run(
    reassembly: parts.Reassembly, conn: str, data: bytes, transfer: int, now: float = 0.0
) -> list[object]:
    return [reassembly.add(conn, h, c, now) for h, c in parts.split(data, transfer, MB)]


class TestReassembly:
    def test_parts_make_the_message_again_and_release_their_reservation(self) -> None:
        r = parts.Reassembly(max_message=8 * MB, budget=16 * MB, stall=30)
        data = bytes(range(256)) * (3 * MB // 256 + 7)
        out = run(r, "a", data, 1)
        assert out[:-1] == [None] * (len(out) - 1)
        assert out[-1] == data
        assert r.reserved == 0
        assert r.peak == len(data)

    def test_a_message_over_the_limit_is_refused_at_its_first_part_and_never_held(self) -> None:
        r = parts.Reassembly(max_message=2 * MB, budget=16 * MB, stall=30)
        out = run(r, "a", b"x" * (5 * MB), 1)
        assert isinstance(out[0], parts.Refused)
        assert out[0].reason == "oversized"
        assert out[1:] == [None] * 4  # the rest is skipped, counted once
        assert r.reserved == r.peak == 0

    def test_a_transfer_beyond_the_total_budget_is_refused_until_one_ends(self) -> None:
        r = parts.Reassembly(max_message=8 * MB, budget=10 * MB, stall=30)
        first = list(parts.split(b"a" * (6 * MB), 1, MB))
        assert r.add("a", *first[0], 0.0) is None  # 6 MB reserved
        second = run(r, "b", b"b" * (6 * MB), 2)
        assert isinstance(second[0], parts.Refused)
        assert second[0].reason == "over-budget"
        for header, chunk in first[1:]:
            done = r.add("a", header, chunk, 0.0)
        assert done == b"a" * (6 * MB)
        assert run(r, "b", b"b" * (6 * MB), 3)[-1] == b"b" * (6 * MB)

    def test_a_stalled_transfer_gives_its_reservation_to_a_new_one(self) -> None:
        r = parts.Reassembly(max_message=8 * MB, budget=10 * MB, stall=30)
        first = list(parts.split(b"a" * (6 * MB), 1, MB))
        r.add("a", *first[0], 0.0)  # and then nothing more from "a"
        assert run(r, "b", b"b" * (6 * MB), 2, now=31.0)[-1] == b"b" * (6 * MB)
        assert r.add("a", *first[1], 32.0) is None  # its rest is dropped, not held
        assert r.reserved == 0

    def test_a_part_out_of_order_breaks_the_transfer(self) -> None:
        r = parts.Reassembly(max_message=8 * MB, budget=16 * MB, stall=30)
        split = list(parts.split(b"z" * (3 * MB), 1, MB))
        r.add("a", *split[0], 0.0)
        broken = r.add("a", *split[2], 0.0)
        assert isinstance(broken, parts.Refused)
        assert broken.reason == "malformed"
        assert r.reserved == 0


class TestOverSockets:
    async def test_a_message_larger_than_a_frame_travels_both_ways(self, make_rpc: MakeRpc) -> None:
        client, server = await make_rpc(), await make_rpc()
        server.register(Ping, lambda req: Pong(req.body.payload[::-1]))
        payload = bytes(range(256)) * (limits.FRAME_BYTES * 3 // 256 + 1)
        pong = await client.request(server.address, Ping(payload), timeout=10, expect=Pong)
        assert pong.payload == payload[::-1]
        assert server.transport.stats.dropped_count() == 0
        assert client.transport.stats.dropped_count() == 0
