"""Who is in the swarm, and a peer under hostile input (DESIGN §6, §11)."""

from __future__ import annotations

import asyncio
import random
from collections.abc import Awaitable, Callable

import pytest
import zmq
import zmq.asyncio

from mapapi import ChunkId, Peer, PeerId
from mapapi.core.errors import CorruptRepoError, JoinRefused, NotChunkLeader, ProtocolError
from mapapi.net import Ping, Pong, codec
from mapapi.net.codec import Envelope, ErrorReply, Kind
from mapapi.net.messages import Hello, Member, RaftPropose
from tests.swarm.conftest import TABLE, MakeSwarm, counter_chunk, increment, log_ids, net, value


class TestMembers:
    async def test_every_peer_learns_the_whole_swarm_from_one_member(
        self, swarm: MakeSwarm
    ) -> None:
        peers = await swarm(4)
        for peer in peers:
            others = {s.member.id for s in peer.members()}
            assert others == {p.id for p in peers} - {peer.id}
            assert {s.member.address for s in peer.members()} == {
                p.address for p in peers if p is not peer
            }

    async def test_a_late_joiner_through_any_member_is_known_to_all(
        self, swarm: MakeSwarm, make_peer: Callable[..., Awaitable[Peer]]
    ) -> None:
        peers = await swarm(3)
        late = await make_peer()
        await late.start()
        await late.join(peers[2].address)  # not the first peer
        everyone = [*peers, late]
        for peer in everyone:
            assert {s.member.id for s in peer.members()} == {p.id for p in everyone} - {peer.id}
        heard = [s for s in peers[0].members() if s.member.id == late.id]
        assert heard[0].last_seen is not None

    async def test_a_peer_that_closes_says_bye(self, swarm: MakeSwarm) -> None:
        peers = await swarm(4)
        leaving = peers.pop(1)
        leaving_address = leaving.address
        await leaving.close()
        for peer in peers:
            assert leaving.id not in {s.member.id for s in peer.members()}
            assert {s.member.id for s in peer.members()} == {p.id for p in peers} - {peer.id}
            # still a member of its chunks' groups: named, reached and remembered
            members = net(peer).members
            assert [m.id for m in members.departed()] == [leaving.id]
            assert members.address(leaving.id) == leaving_address

    async def test_a_hello_in_someone_elses_name_is_refused(self, swarm: MakeSwarm) -> None:
        a, b = await swarm(2)
        impostor = Member(PeerId.new(), "tcp://127.0.0.1:1")
        with pytest.raises(JoinRefused):
            await net(a).rpc.request(b.address, Hello(impostor))
        assert impostor.id not in {s.member.id for s in b.members()}


_RAW_PEER = PeerId("0f" * 16)


def _request(request_id: int, body: object) -> bytes:
    return codec.encode(Envelope(request_id, _RAW_PEER, 1, Kind.REQUEST, body))


class TestGarbage:
    @pytest.mark.parametrize("seed", [1, 2])
    async def test_a_peer_fed_garbage_keeps_serving_commits(
        self,
        swarm: MakeSwarm,
        raw_dealer: Callable[[str], zmq.asyncio.Socket],
        seed: int,
    ) -> None:
        """Random bytes, truncated envelopes, extra frames and well-formed but
        wrong swarm messages: each is dropped or refused, and commits go on."""
        a, b = await swarm(2)
        chunk, item = await counter_chunk(a)
        await b.participate(chunk)
        await increment(b, [(TABLE, item)])
        rng = random.Random(seed)
        raw = raw_dealer(b.address)
        valid = _request(1, Ping(b"x"))
        blobs = [rng.randbytes(rng.randint(0, 400)) for _ in range(60)]
        blobs += [b"", valid[:-2], valid[:4], b"\x08\x07" + rng.randbytes(50)]
        for blob in blobs:
            await raw.send(blob)
        await raw.send_multipart([b"three", b"frames", b"here"])
        wrong = {  # request id -> the error each must get (b is a learner: a leads)
            2: (RaftPropose(chunk, b"\x01garbage"), NotChunkLeader),
            3: (RaftPropose(ChunkId.new(), b""), NotChunkLeader),
            4: (Hello(Member(PeerId.new(), "")), JoinRefused),
        }
        for request_id, (body, _) in wrong.items():
            await raw.send(_request(request_id, body))
        await raw.send(_request(1000, Ping(b"last")))
        replies: dict[int, object] = {}
        async with asyncio.timeout(5):
            while not set(wrong) | {1000} <= set(replies):
                env = codec.decode(await raw.recv())
                replies[env.request_id] = env.body
        assert replies[1000] == Pong(b"last")
        for request_id, (_, error) in wrong.items():
            reply = replies[request_id]
            assert isinstance(reply, ErrorReply)
            assert codec.error_class(reply.code) is error, (request_id, reply)
        broken = [r for i, r in replies.items() if i not in wrong and i != 1000]
        # the leader refuses a proposal that is no log entry, and goes on
        leader = raw_dealer(a.address)
        await leader.send(_request(5, RaftPropose(chunk, b"\x01garbage")))
        async with asyncio.timeout(5):
            refused = codec.decode(await leader.recv()).body
        assert isinstance(refused, ErrorReply)
        assert codec.error_class(refused.code) is CorruptRepoError
        assert all(isinstance(r, ErrorReply) and r.code == ProtocolError.code for r in broken)
        stats = net(b).rpc.transport.stats
        assert stats.dropped_count("malformed") >= len(blobs)
        # b still serves: commits both ways reach both replicas
        await increment(a, [(TABLE, item)])
        await increment(b, [(TABLE, item)])
        assert await value(a, item) == await value(b, item) == 3
        assert await log_ids(a) == await log_ids(b)
        assert set(b.holders(chunk)) == {a.id, b.id}
