"""CurveZMQ on the transport's sockets (DESIGN §10): pyzmq's `zmq.auth`, no crypto here.

- `ZapHandler` answers libzmq's ZAP requests for a secure ROUTER: a client is
  admitted when its public key is on the peer's trust list (or is the peer's own),
  and its key becomes the connection's User-Id, which every message carries.
- `secure_router` and `secure_dealer` set the CURVE socket options; a DEALER names
  the server key it expects, taken from the remote's address, so it also checks
  that the peer it reaches holds that key.
- `LinkWatch` reads a DEALER's monitor events and decides when a link is refused
  for good: the remote refused our key (ZAP status 400); the handshake broke the
  protocol (one peer secure and the other open, or a server without the key its
  address names; libzmq then stops retrying, so requests would only time out);
  or a link that never completed a handshake keeps having it cut (what the
  other side of such a mismatch sees; libzmq would retry silently forever).
"""

from __future__ import annotations

import inspect
import logging
from dataclasses import dataclass

import zmq
import zmq.asyncio
import zmq.auth

from mapapi.core.errors import AccessRefused
from mapapi.net.security import Security, key_text

log = logging.getLogger(__name__)

ZAP_DOMAIN = "mapapi"
MISMATCH_FAILURES = 2
"""Cut handshakes, with none completed, after which a link counts as refused.
One can be a peer that died mid-handshake; two in a row, 0.1 s apart, is a mismatch."""

WATCHED_EVENTS = int(
    zmq.EVENT_HANDSHAKE_SUCCEEDED
    | zmq.EVENT_HANDSHAKE_FAILED_AUTH
    | zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL
    | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL
)
"""The monitor events `LinkWatch` reads (a few per connection, none per message)."""

_SUCCEEDED = int(zmq.EVENT_HANDSHAKE_SUCCEEDED)
_AUTH = int(zmq.EVENT_HANDSHAKE_FAILED_AUTH)
_PROTOCOL = int(zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL)
_MECHANISM_MISMATCH = int(zmq.PROTOCOL_ERROR_ZMTP_MECHANISM_MISMATCH)
_CRYPTOGRAPHIC = int(zmq.PROTOCOL_ERROR_ZMTP_CRYPTOGRAPHIC)


class ZapHandler(zmq.auth.Authenticator):
    """ZAP for one secure peer: admits the keys `security` trusts.

    Unlike pyzmq's `AsyncioAuthenticator`, it runs no task of its own: the
    transport awaits `serve()` in a task it owns, cancels it and then calls
    `stop()`, so nothing is left pending when the loop closes.
    """

    def __init__(self, context: zmq.asyncio.Context, security: Security) -> None:
        super().__init__(context)
        self.security = security
        self._warned: set[bytes] = set()
        self.configure_curve_callback(ZAP_DOMAIN, self)

    def start(self) -> None:
        """Bind the context's ZAP endpoint with an asyncio socket."""
        sock = self.context.socket(zmq.REP)
        sock.setsockopt(zmq.LINGER, 0)
        sock.bind("inproc://zeromq.zap.01")
        self.zap_socket = sock

    async def serve(self) -> None:
        """Answer ZAP requests until cancelled."""
        sock = self.zap_socket
        assert isinstance(sock, zmq.asyncio.Socket), "start() first"
        while True:
            request: list[bytes] = await sock.recv_multipart()
            answered = self.handle_zap_message(request)
            if inspect.isawaitable(answered):  # a coroutine since pyzmq 25 (not before)
                await answered

    def curve_user_id(self, client_public_key: bytes) -> str:
        """The ZAP User-Id of an admitted client: its public key in hex. libzmq
        attaches it to every message of the connection, where the transport reads
        it (`zmq.Frame.get("User-Id")`) to check each message's sender against
        the key (docs/design.md "Secure swarm")."""
        from zmq.utils import z85

        key = client_public_key if len(client_public_key) == 32 else z85.decode(client_public_key)
        return key_text(key)

    def callback(self, domain: str, z85_key: bytes) -> bool:
        """zmq.auth's credentials provider: is this client key trusted?"""
        from zmq.utils import z85

        key = z85.decode(z85_key)
        try:
            trusted = self.security.trusts(key)
        except Exception:  # a damaged trust list must refuse, not stop the ZAP handler
            log.exception("cannot read the trust list; refusing key %s", key_text(key))
            return False
        if not trusted and key not in self._warned:
            self._warned.add(key)  # a refused client retries every 0.1 s: say it once
            log.warning(
                "refused a peer with key %s: it is not on the trust list "
                "(`mapctl trust add %s` admits it)",
                key_text(key),
                key_text(key),
            )
        return trusted


def secure_router(sock: zmq.asyncio.Socket, security: Security) -> None:
    """Make `sock` (before it binds) a CURVE server that asks ZAP about each client."""
    sock.setsockopt(zmq.CURVE_SERVER, 1)
    sock.setsockopt(zmq.CURVE_SECRETKEY, security.keys.secret)
    sock.setsockopt(zmq.CURVE_PUBLICKEY, security.keys.public)
    sock.setsockopt(zmq.ZAP_DOMAIN, ZAP_DOMAIN.encode())


def secure_dealer(sock: zmq.asyncio.Socket, security: Security, server_key: bytes) -> None:
    """Make `sock` (before it connects) a CURVE client of the server with `server_key`."""
    sock.setsockopt(zmq.CURVE_SERVERKEY, server_key)
    sock.setsockopt(zmq.CURVE_SECRETKEY, security.keys.secret)
    sock.setsockopt(zmq.CURVE_PUBLICKEY, security.keys.public)


def check_link(address: str, endpoint: str, key: bytes | None, security: Security | None) -> None:
    """Refuse, before connecting, a link whose two ends cannot talk.

    Raises:
        AccessRefused: an open peer was given a secure peer's address, a secure
            peer an open one's, or a secure peer an address whose key it does not trust.
    """
    if security is None:
        if key is not None:
            raise AccessRefused(
                f"{endpoint} is a secure swarm and this peer is open",
                advice=(
                    "act: make this repository secure (`mapctl init --secure`), trust its key "
                    f"(`mapctl trust add {key_text(key)}`) and have it trust yours "
                    "(`mapctl key show`)"
                ),
            )
        return
    if key is None:
        raise AccessRefused(
            f"{address} names no key, and this peer is secure: it talks only to secure "
            "peers, through the address they print (…#curve=KEY)",
            advice="act: join through that address, or join an open swarm from an open repository",
        )
    if not security.trusts(key):
        raise AccessRefused(
            f"this peer does not trust the key of {endpoint} ({key_text(key)})",
            advice=f"act: run `mapctl trust add {key_text(key)}` if it belongs to your swarm",
        )


_MAKE_SECURE = (
    "act: make this repository secure (`mapctl init --secure`), trust its key and join "
    "through the address it prints (…#curve=KEY)"
)


@dataclass
class LinkWatch:
    """Judges the handshakes of one outgoing link (DEALER) from its monitor events.

    Attributes:
        endpoint: what the link connects to.
        security: this peer's keys (None: an open peer).
        succeeded: a handshake on this link completed once.
        failures: handshakes ended since the last one that completed.
    """

    endpoint: str
    security: Security | None
    succeeded: bool = False
    failures: int = 0

    def on_event(self, event: int, value: int) -> AccessRefused | None:
        """The error that refuses the link for good after `event` (whose detail is
        `value`: a ZAP status or a protocol error code), or None."""
        if event == _SUCCEEDED:
            self.succeeded, self.failures = True, 0
            return None
        if event == _AUTH:
            return self._key_refused(value)
        if event == _PROTOCOL:
            return self._mismatch(value)
        self.failures += 1  # the handshake was cut
        if self.succeeded or self.failures < MISMATCH_FAILURES:
            return None  # a link that worked before: the peer restarts, or crashed
        return self._cut()

    def _key_refused(self, status: int) -> AccessRefused:
        mine = key_text(self.security.keys.public) if self.security else "?"
        return AccessRefused(
            f"{self.endpoint} refused this peer's key {mine} (status {status}): it is not "
            "on that peer's trust list",
            advice=f"act: run `mapctl trust add {mine}` there",
        )

    def _mismatch(self, code: int) -> AccessRefused:
        if code == _MECHANISM_MISMATCH and self.security is None:
            return AccessRefused(
                f"{self.endpoint} is a secure swarm and this peer is open (the handshake failed)",
                advice=_MAKE_SECURE,
            )
        if code == _MECHANISM_MISMATCH:
            return AccessRefused(
                f"{self.endpoint} is an open swarm and this peer is secure (the handshake failed)",
                advice="act: join it from an open repository, or make every peer secure",
            )
        if code == _CRYPTOGRAPHIC:
            return AccessRefused(
                f"{self.endpoint} does not hold the key its address names (the handshake failed)",
                advice="act: join through the address it prints now",
            )
        return AccessRefused(f"the handshake with {self.endpoint} failed (protocol error {code})")

    def _cut(self) -> AccessRefused:
        if self.security is None:
            return AccessRefused(
                f"{self.endpoint} cut every handshake: it is no open mapapi peer, most likely "
                "a secure swarm",
                advice=_MAKE_SECURE,
            )
        return AccessRefused(
            f"{self.endpoint} cut every handshake: it is an open swarm, or it does not hold "
            "the key its address names",
            advice="act: join it from an open repository, or through the address it prints now",
        )
