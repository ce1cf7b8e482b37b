"""Peer-to-peer messaging: envelope codec, ZeroMQ transport, RPC, shaping, stats.

Typical use::

    rpc = Rpc(ZmqTransport(peer_id, clock))
    address = await rpc.start("tcp://127.0.0.1:0")
    rpc.register(Ping, lambda req: Pong(req.body.payload))
    pong = await rpc.request(other_address, Ping(b"hi"), timeout=1.0, expect=Pong)
    await rpc.close()
"""

from mapapi.net.codec import Envelope, ErrorReply, Kind, Ping, Pong
from mapapi.net.rpc import DEFAULT_TIMEOUT, Handler, Request, Rpc
from mapapi.net.shaping import LinkShape, Shaper
from mapapi.net.stats import Stats, Traffic
from mapapi.net.transport import DEFAULT_MAX_MESSAGE_SIZE, Inbound, Route, Transport, ZmqTransport

__all__ = [
    "DEFAULT_MAX_MESSAGE_SIZE",
    "DEFAULT_TIMEOUT",
    "Envelope",
    "ErrorReply",
    "Handler",
    "Inbound",
    "Kind",
    "LinkShape",
    "Ping",
    "Pong",
    "Request",
    "Route",
    "Rpc",
    "Shaper",
    "Stats",
    "Traffic",
    "Transport",
    "ZmqTransport",
]
