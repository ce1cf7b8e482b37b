"""A secure swarm (issue 7 §6, DESIGN §10): CurveZMQ between peers on real sockets.

Trusted keys are admitted, untrusted ones can neither join, read nor write, a
relay in the middle sees no plaintext, and a secure peer and an open one fail
to connect with a message that says so instead of a timeout. A trusted peer
cannot speak as another: the key is the identity (issue 18 §2).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from pathlib import Path

import pytest

from mapapi import Peer, PeerId
from mapapi.core.errors import AccessRefused
from mapapi.net import codec
from mapapi.net.codec import Envelope, ErrorReply, Kind
from mapapi.net.messages import (
    ChunkList,
    ChunkListQuery,
    GroupJoin,
    GroupLeave,
    Hello,
    HoldersQuery,
    Member,
    RaftPropose,
)
from mapapi.net.rpc import Rpc
from mapapi.net.security import Security, key_text, keyed_address, peer_id_of, split_address
from mapapi.net.transport import ZmqTransport
from tests.swarm.conftest import TABLE, Counter, counter_chunk, log_ids, net, share, value

MakePeer = Callable[..., Awaitable[Peer]]
MARKER = "plaintext-marker-7f3c"


def keys_of(peer: Peer) -> Security:
    assert peer.security is not None, f"{peer.name} is not secure"
    return peer.security


def trust_each_other(peers: Sequence[Peer]) -> None:
    for peer in peers:
        for other in peers:
            if other is not peer:
                keys_of(peer).trust.add(keys_of(other).keys.public)


async def secure_swarm(make_peer: MakePeer, n: int) -> list[Peer]:
    """n secure peers that trust each other, joined through the first."""
    peers = [await make_peer(secure=True) for _ in range(n)]
    trust_each_other(peers)
    for peer in peers:
        await peer.start()
    for peer in peers[1:]:
        await peer.join(peers[0].address)
    return peers


def heard_from(peer: Peer, other: PeerId) -> bool:
    """Whether any message from `other` ever reached `peer`'s swarm endpoint."""
    return str(other) in net(peer).rpc.transport.stats.received_by_peer()


@pytest.fixture
async def client(tmp_path: Path) -> AsyncIterator[Callable[[Security | None], Awaitable[Rpc]]]:
    """Factory of bare started `Rpc` endpoints (not peers), closed after the test."""
    made: list[Rpc] = []

    async def _make(security: Security | None) -> Rpc:
        rpc = Rpc(ZmqTransport(PeerId.new(), security=security))
        await rpc.start()
        made.append(rpc)
        return rpc

    yield _make
    for rpc in made:
        await rpc.close()


class TestSecureSwarm:
    async def test_trusted_peers_form_a_swarm_and_replicate(self, make_peer: MakePeer) -> None:
        peers = await secure_swarm(make_peer, 3)
        for peer in peers:
            key = split_address(peer.address)[1]
            assert key == keys_of(peer).keys.public  # the address names the key
            assert {s.member.address for s in peer.members()} == {
                p.address for p in peers if p is not peer
            }
            ring = [s.address for s in net(peer).chord.successors]
            assert all(split_address(a)[1] is not None for a in ring)
        chunk, item = await counter_chunk(peers[0], 1)
        await share(chunk, peers[1:])
        for index, peer in enumerate(peers):
            tx = peer.begin()
            tx.update(TABLE, item, Counter(name="c", value=10 + index))
            await tx.commit(f"peer {index}")
            for other in peers:
                assert await value(other, item) == 10 + index


class TestTrust:
    async def test_an_untrusted_peer_is_refused_then_admitted_once_trusted(
        self, make_peer: MakePeer
    ) -> None:
        a, b = await make_peer(secure=True), await make_peer(secure=True)
        keys_of(b).trust.add(keys_of(a).keys.public)  # b trusts a; a trusts nobody
        await a.start()
        await b.start()
        mine = key_text(keys_of(b).keys.public)
        with pytest.raises(AccessRefused, match=f"refused this peer's key {mine}") as refused:
            await b.join(a.address)
        assert f"mapctl trust add {mine}" in str(refused.value)
        assert b.id not in {s.member.id for s in a.members()}
        assert not heard_from(a, b.id)

        keys_of(a).trust.add(keys_of(b).keys.public)  # the running peer reads it at once
        await b.join(a.address)
        assert {s.member.id for s in a.members()} == {b.id}
        assert {s.member.id for s in b.members()} == {a.id}

    async def test_a_peer_does_not_connect_to_a_key_it_does_not_trust(
        self, make_peer: MakePeer
    ) -> None:
        a, b = await make_peer(secure=True), await make_peer(secure=True)
        keys_of(a).trust.add(keys_of(b).keys.public)  # a trusts b; b does not trust a
        await a.start()
        await b.start()
        theirs = key_text(keys_of(a).keys.public)
        with pytest.raises(AccessRefused, match=f"does not trust the key .*{theirs}"):
            await b.join(a.address)
        assert not heard_from(a, b.id)

    async def test_an_untrusted_client_can_neither_read_nor_write(
        self,
        make_peer: MakePeer,
        client: Callable[[Security | None], Awaitable[Rpc]],
        tmp_path: Path,
    ) -> None:
        (a,) = await secure_swarm(make_peer, 1)
        chunk, _ = await counter_chunk(a, 5)
        stranger_keys = Security.create(tmp_path / "stranger")
        stranger_keys.trust.add(keys_of(a).keys.public)  # it knows whom it talks to
        stranger = await client(stranger_keys)
        me = Member(stranger.transport.peer_id, stranger.address)
        with pytest.raises(AccessRefused):
            await stranger.request(a.address, ChunkListQuery())  # read
        with pytest.raises(AccessRefused):
            await stranger.request(a.address, Hello(me, a.grid.config_fingerprint()))  # join
        assert not heard_from(a, stranger.transport.peer_id)
        assert me.id not in {s.member.id for s in a.members()}

        # the same client, once trusted, reads: the refusals above were the trust list's
        keys_of(a).trust.add(stranger_keys.keys.public)
        answer = await stranger.request(a.address, ChunkListQuery(), expect=ChunkList)
        assert [c.chunk for c in answer.chunks] == [chunk]

    async def test_a_removed_key_is_refused_at_its_next_connection(
        self, make_peer: MakePeer
    ) -> None:
        a, b = await secure_swarm(make_peer, 2)
        keys_of(a).trust.remove(keys_of(b).keys.public)
        await net(b).rpc.forget(a.address)  # b's next message opens a new connection
        with pytest.raises(AccessRefused, match="refused this peer's key"):
            await net(b).rpc.request(a.address, ChunkListQuery())
        keys_of(a).trust.add(keys_of(b).keys.public)  # so that they part without waiting


class Relay:
    """A TCP relay that keeps every byte it forwards: what a wiretap would see."""

    def __init__(self, endpoint: str) -> None:
        host, port = endpoint.removeprefix("tcp://").rsplit(":", 1)
        self.target = (host, int(port))
        self.seen = bytearray()
        self._server: asyncio.Server | None = None
        self._writers: list[asyncio.StreamWriter] = []
        self._pumps: set[asyncio.Task[None]] = set()

    async def start(self) -> str:
        self._server = await asyncio.start_server(self._connected, "127.0.0.1", 0)
        port = self._server.sockets[0].getsockname()[1]
        return f"tcp://127.0.0.1:{port}"

    async def _connected(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        up_reader, up_writer = await asyncio.open_connection(*self.target)
        self._writers += [writer, up_writer]
        for source, sink in ((reader, up_writer), (up_reader, writer)):
            task = asyncio.get_running_loop().create_task(self._pump(source, sink))
            self._pumps.add(task)

    async def _pump(self, source: asyncio.StreamReader, sink: asyncio.StreamWriter) -> None:
        while data := await source.read(65536):
            self.seen += data
            sink.write(data)
            await sink.drain()
        sink.close()

    async def close(self) -> None:
        for task in self._pumps:
            task.cancel()
        await asyncio.gather(*self._pumps, return_exceptions=True)
        for writer in self._writers:
            writer.close()
            with contextlib.suppress(ConnectionError):
                await writer.wait_closed()
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()


class TestWire:
    @pytest.mark.parametrize("secure", [False, True], ids=["open", "secure"])
    async def test_what_a_wiretap_between_two_peers_sees(
        self, make_peer: MakePeer, secure: bool
    ) -> None:
        a, b = await make_peer(secure=secure), await make_peer(secure=secure)
        if secure:
            trust_each_other([a, b])
        await a.start()
        bound = await b.start()
        relay = Relay(split_address(bound)[0])
        try:
            net(b).advertise(await relay.start())  # every peer reaches b through the relay
            await b.join(a.address)
            chunk, item = await counter_chunk(a, 1, name=MARKER)
            await b.participate(chunk)  # a sends b the chunk through the relay
            tx = a.begin()
            tx.update(TABLE, item, Counter(name=MARKER, value=2))
            await tx.commit("through the relay")  # and the commit
            assert await value(b, item) == 2
        finally:
            for peer in (b, a):  # while the relay still carries their goodbyes
                await peer.close()
            await relay.close()
        assert len(relay.seen) > 1000  # the chunk and the commit did cross it
        assert (MARKER.encode() in relay.seen) is not secure


class TestMixed:
    """A secure peer and an open one never talk; each side says why."""

    async def test_an_open_peer_given_a_secure_join_string(self, make_peer: MakePeer) -> None:
        secure, open_peer = await make_peer(secure=True), await make_peer()
        await secure.start()
        await open_peer.start()
        with pytest.raises(AccessRefused, match="is a secure swarm and this peer is open") as e:
            await open_peer.join(secure.address)
        assert "mapctl init --secure" in str(e.value)
        assert not secure.members()

    async def test_a_secure_peer_given_an_open_address(self, make_peer: MakePeer) -> None:
        secure, open_peer = await make_peer(secure=True), await make_peer()
        await secure.start()
        await open_peer.start()
        with pytest.raises(AccessRefused, match="names no key, and this peer is secure"):
            await secure.join(open_peer.address)
        assert not open_peer.members()

    async def test_an_open_peer_at_a_secure_peers_bare_endpoint(self, make_peer: MakePeer) -> None:
        secure, open_peer = await make_peer(secure=True), await make_peer()
        await secure.start()
        await open_peer.start()
        bare = split_address(secure.address)[0]  # the key left out: only the handshake tells
        with pytest.raises(AccessRefused, match="secure swarm"):
            await open_peer.join(bare)
        assert not secure.members()

    async def test_a_secure_peer_at_an_open_endpoint(self, make_peer: MakePeer) -> None:
        secure, open_peer = await make_peer(secure=True), await make_peer()
        await secure.start()
        await open_peer.start()
        # an open endpoint dressed with a key the secure peer trusts (its own)
        dressed = keyed_address(open_peer.address, keys_of(secure).keys.public)
        with pytest.raises(AccessRefused, match="open swarm"):
            await secure.join(dressed)
        assert not open_peer.members()

    async def test_an_address_with_another_peers_key(self, make_peer: MakePeer) -> None:
        a, b, c = await secure_swarm(make_peer, 3)
        await c.close()  # c's key stays trusted by b
        forged = keyed_address(split_address(a.address)[0], keys_of(c).keys.public)
        with pytest.raises(AccessRefused, match="does not hold the key"):
            await net(b).rpc.request(forged, ChunkListQuery())


class HostileClient:
    """A trusted-but-hostile peer's hand-made CURVE connection: it authenticates
    with its own key and writes any `sender` it likes into the envelopes."""

    def __init__(self, keys: Security, address: str) -> None:
        import zmq
        import zmq.asyncio

        from mapapi.net import curve

        endpoint, server_key = split_address(address)
        assert server_key is not None
        self.context = zmq.asyncio.Context()
        self.sock = self.context.socket(zmq.DEALER)
        self.sock.setsockopt(zmq.LINGER, 0)
        curve.secure_dealer(self.sock, keys, server_key)
        self.sock.connect(endpoint)
        self._ids = iter(range(1, 1_000_000))

    async def ask(self, sender: PeerId, body: object) -> Envelope:
        """Send a request as `sender` and return the reply (within 5 s)."""
        request_id = next(self._ids)
        await self.sock.send(codec.encode(Envelope(request_id, sender, 1, Kind.REQUEST, body)))
        async with asyncio.timeout(5):
            reply = codec.decode(await self.sock.recv())
        assert reply.request_id == request_id
        return reply

    def close(self) -> None:
        self.sock.close(linger=0)
        self.context.term()


@contextlib.asynccontextmanager
async def hostile(keys: Security, address: str) -> AsyncIterator[HostileClient]:
    client = HostileClient(keys, address)
    try:
        yield client
    finally:
        client.close()


def refused(reply: Envelope) -> bool:
    return isinstance(reply.body, ErrorReply) and reply.body.code == AccessRefused.code


class TestIdentityIsTheKey:
    """Issue 18 §2: a trusted peer cannot speak as another (the probe's case)."""

    async def test_a_secure_repositorys_id_is_derived_from_its_key(
        self, make_peer: MakePeer
    ) -> None:
        peer = await make_peer(secure=True)
        assert peer.id == peer_id_of(keys_of(peer).keys.public)
        assert keys_of(peer).peer_id == peer.id

    async def test_a_trusted_peer_cannot_commit_or_join_as_another(
        self, make_peer: MakePeer, caplog: pytest.LogCaptureFixture
    ) -> None:
        s1, s2, rogue = await secure_swarm(make_peer, 3)
        chunk, _ = await counter_chunk(s1, 1)
        await share(chunk, [s2])  # s1 and s2 hold it; the rogue holds nothing
        before = await log_ids(s1)
        stats = net(s1).rpc.transport.stats
        forged = [
            RaftPropose(chunk, b"\x00" * 16),
            GroupJoin(chunk),
            GroupLeave(chunk),
        ]
        async with hostile(keys_of(rogue), s1.address) as client:
            for body in forged:
                reply = await client.ask(s2.id, body)
                assert refused(reply), f"{type(body).__name__} as s2 was {reply.body}"
            # the same connection under its own id is served: the key is why
            own = await client.ask(rogue.id, HoldersQuery(chunk, None))
            assert not refused(own)
        assert stats.dropped_count("forged") == len(forged)
        warnings = [r.getMessage() for r in caplog.records if "claiming to be peer" in r.message]
        assert any(str(s2.id) in w and key_text(keys_of(rogue).keys.public) in w for w in warnings)
        assert await log_ids(s1) == before  # nothing applied
        assert await log_ids(s2) == before
        assert set(s1.holders(chunk)) == {s1.id, s2.id}  # nobody joined or left

    async def test_a_bound_id_is_accepted_and_only_from_its_key(
        self,
        make_peer: MakePeer,
        client: Callable[[Security | None], Awaitable[Rpc]],
        tmp_path: Path,
    ) -> None:
        (a,) = await secure_swarm(make_peer, 1)
        # a repository made secure before ids were derived keeps its old id
        made = Security.create(tmp_path / "legacy")
        made.trust.add(keys_of(a).keys.public)
        legacy = dataclasses.replace(made, own_id=PeerId.new())
        keys_of(a).trust.add(legacy.keys.public)  # trusted, but its id is not bound
        rpc = await client(legacy)
        assert rpc.transport.peer_id == legacy.own_id  # it sends as its id
        with pytest.raises(AccessRefused, match="is not the peer of this connection's key"):
            await rpc.request(a.address, ChunkListQuery())
        keys_of(a).trust.add(legacy.keys.public, legacy.own_id)  # `trust add KEY --id ID`
        await rpc.request(a.address, ChunkListQuery(), expect=ChunkList)
