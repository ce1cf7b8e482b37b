"""Keys and trust of a secure swarm (DESIGN §10).

A secure repository has a CurveZMQ keypair, made and read by pyzmq's `zmq.auth`
certificate functions, and a trust list: the public keys of the peers it talks
to. Both live in `.mapapi/curve/` (a 0700 folder; the secret certificate is
0600). No cryptography is written here: this module stores and names keys; the
transport (`mapapi.net.curve`) hands them to libzmq.

A public key travels inside a peer's address, `tcp://HOST:PORT#curve=KEY`, so
everything that carries an address (Welcome lists, holder sets, the Chord ring,
the join string) also carries what is needed to authenticate the peer there.
Keys are written as 64 hex digits (safe to paste into a shell); the 40-character
Z85 form that zmq tools print is accepted too.

The key is the identity (docs/design.md "Secure swarm"): a secure peer's id is
`peer_id_of` its public key, so any peer can tell which id a connection's key
may speak as without asking anyone. A repository made secure before ids were
derived keeps its id; its key is then bound to that id on every other peer's
trust list (a line `KEY ID`, `mapctl trust add KEY --id ID`).
"""

from __future__ import annotations

import functools
import hashlib
import logging
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path

from mapapi.core.errors import CorruptRepoError, UsageError
from mapapi.core.ids import PeerId

log = logging.getLogger(__name__)

KEY_DIR = "curve"
"""The folder of keys inside `.mapapi/`."""
CERT_NAME = "peer"  # zmq.auth writes peer.key (public) and peer.key_secret
TRUST_FILE = "trusted.keys"
ADDRESS_KEY = "#curve="
"""What separates an endpoint from the public key in a secure peer's address."""

_HEX_KEY = re.compile(r"[0-9a-fA-F]{64}")
_Z85_KEY = re.compile(r"[0-9a-zA-Z.\-:+=^!/*?&<>()\[\]{}@%$#]{40}")
_TRUST_HEADER = (
    "# Public keys this peer trusts, one per line (`mapctl trust add|remove KEY`),\n"
    "# each optionally followed by the peer id it is bound to (a key's id is\n"
    "# derived from the key otherwise).\n"
    "# A secure peer accepts connections only from these keys and its own, and\n"
    "# connects only to peers whose address names one of them.\n"
)


# -- naming keys ------------------------------------------------------------------------
def parse_key(text: str) -> bytes:
    """The 32-byte public key written as `text` (64 hex digits, or 40 Z85 characters).

    Raises:
        UsageError: `text` is neither.
    """
    text = text.strip()
    if _HEX_KEY.fullmatch(text):
        return bytes.fromhex(text)
    if _Z85_KEY.fullmatch(text):
        from zmq.utils import z85

        return z85.decode(text)
    raise UsageError(f"not a public key: {text!r}; give the 64 hex digits `mapctl key show` prints")


def key_text(key: bytes) -> str:
    """How a key is shown and stored: 64 lowercase hex digits."""
    return key.hex()


def keyed_address(endpoint: str, key: bytes) -> str:
    """The address of a secure peer listening at `endpoint` with public `key`."""
    return f"{endpoint}{ADDRESS_KEY}{key_text(key)}"


def split_address(address: str) -> tuple[str, bytes | None]:
    """(endpoint, public key) of `address`; the key is None for an open peer.

    Raises:
        UsageError: the key part is malformed.
    """
    endpoint, found, key = address.partition(ADDRESS_KEY)
    if not found:
        return address, None
    if not _HEX_KEY.fullmatch(key):
        raise UsageError(f"bad key in the address {address!r}: expected {ADDRESS_KEY}<64 hex>")
    return endpoint, bytes.fromhex(key)


_ID_DOMAIN = b"mapapi peer id v1\x00"  # so the digest means nothing but "the id of this key"


@functools.lru_cache(maxsize=4_096)  # checked on every message of a secure peer
def peer_id_of(key: bytes) -> PeerId:
    """The peer id a public key speaks as: the first 16 bytes of SHA-256 over a
    domain tag and the key. Nobody can choose a key for a given id (that needs a
    second preimage of SHA-256 truncated to 128 bits), so an id names one key."""
    return PeerId.from_bytes(hashlib.sha256(_ID_DOMAIN + key).digest()[:16])


# -- the keypair --------------------------------------------------------------------------
@dataclass(frozen=True, slots=True, repr=False)
class KeyPair:
    """A CurveZMQ keypair, 32 raw bytes each (`repr` never shows the secret)."""

    public: bytes
    secret: bytes

    def __repr__(self) -> str:
        return f"KeyPair(public={key_text(self.public)})"


def key_folder(meta_dir: Path) -> Path:
    """Where a repository's keys live."""
    return meta_dir / KEY_DIR


def create_keys(folder: Path) -> KeyPair:
    """Make a new keypair in `folder` (created 0700) with `zmq.auth`; the secret
    certificate is made 0600. The folder is private before the secret appears in it.

    Raises:
        UsageError: `folder` holds a keypair already.
    """
    import zmq.auth

    secret_file = folder / f"{CERT_NAME}.key_secret"
    if secret_file.exists():
        raise UsageError(f"{folder} holds a keypair already; it is kept")
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    folder.chmod(0o700)
    zmq.auth.create_certificates(folder, CERT_NAME)
    secret_file.chmod(0o600)
    return load_keys(folder)


def load_keys(folder: Path) -> KeyPair:
    """The keypair stored in `folder`.

    Raises:
        CorruptRepoError: it is missing, unreadable, or readable by other users.
    """
    import zmq.auth
    from zmq.utils import z85

    secret_file = folder / f"{CERT_NAME}.key_secret"
    try:
        mode = secret_file.stat().st_mode
        public, secret = zmq.auth.load_certificate(secret_file)
    except (OSError, ValueError) as exc:
        raise CorruptRepoError(
            f"this repository is secure but its secret key {secret_file} cannot be read "
            f"({exc}); restore it from a backup (a new key must be trusted again by every peer)"
        ) from exc
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise CorruptRepoError(
            f"{secret_file} is open to other users (mode {stat.S_IMODE(mode):04o}); "
            f"run `chmod 600 {secret_file}` and consider the key exposed"
        )
    if secret is None:
        raise CorruptRepoError(f"{secret_file} holds no secret key")
    return KeyPair(z85.decode(public), z85.decode(secret))


# -- the trust list -------------------------------------------------------------------------
class TrustList:
    """The public keys a peer trusts, in a text file: one hex key per line, each
    optionally followed by the peer id bound to it (for a peer whose id is not
    derived from its key, see `peer_id_of`).

    Reads go through `current()`, which reloads the file whenever it changed on disk,
    so `mapctl trust add` reaches a running peer at its next handshake. Writes
    replace the file atomically.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self._seen: tuple[int, int, int] | None = None
        self._bound: dict[bytes, PeerId | None] = {}
        self._keys: frozenset[bytes] = frozenset()

    def current(self) -> frozenset[bytes]:
        """The trusted keys (an absent file trusts none).

        Raises:
            CorruptRepoError: a line is not a key (and an optional peer id).
        """
        try:
            info = self.path.stat()
        except FileNotFoundError:
            self._seen, self._bound, self._keys = None, {}, frozenset()
            return self._keys
        seen = (info.st_ino, info.st_mtime_ns, info.st_size)
        if seen != self._seen:
            self._bound = self._read()
            self._keys = frozenset(self._bound)
            self._seen = seen
        return self._keys

    def bound_id(self, key: bytes) -> PeerId | None:
        """The peer id the trust list binds `key` to, if any."""
        self.current()
        return self._bound.get(key)

    def __contains__(self, key: object) -> bool:
        return key in self.current()

    def add(self, key: bytes, peer_id: PeerId | None = None) -> bool:
        """Trust `key` (bound to `peer_id` when given); False if it was trusted
        already with the same binding."""
        self.current()
        if key in self._bound and self._bound[key] == peer_id:
            return False
        self._write({**self._bound, key: peer_id})
        return True

    def remove(self, key: bytes) -> bool:
        """Stop trusting `key`; False if it was not trusted."""
        self.current()
        if key not in self._bound:
            return False
        self._write({k: v for k, v in self._bound.items() if k != key})
        return True

    def create(self) -> None:
        """Write an empty trust list (a new secure repository's)."""
        self._write({})

    def _read(self) -> dict[bytes, PeerId | None]:
        bound: dict[bytes, PeerId | None] = {}
        text = self.path.read_text(encoding="utf-8")
        for number, line in enumerate(text.splitlines(), 1):
            fields = line.split("#", 1)[0].split()
            if not fields:
                continue
            if len(fields) > 2 or not _HEX_KEY.fullmatch(fields[0]):
                raise CorruptRepoError(
                    f"{self.path} line {number} is not a key (and a peer id): {line.strip()!r}"
                )
            try:
                peer_id = PeerId(fields[1]) if len(fields) == 2 else None
            except ValueError as exc:
                raise CorruptRepoError(f"{self.path} line {number}: {exc}") from None
            bound[bytes.fromhex(fields[0])] = peer_id
        return bound

    def _write(self, bound: dict[bytes, PeerId | None]) -> None:
        body = "".join(
            f"{key_text(k)}{'' if bound[k] is None else f' {bound[k]}'}\n" for k in sorted(bound)
        )
        tmp = self.path.with_name(f"{self.path.name}.{os.getpid()}.tmp")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as out:
            out.write(_TRUST_HEADER + body)
        tmp.replace(self.path)


# -- what the transport needs -----------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Security:
    """A secure peer's keypair and trust list, as its transport uses them.

    Attributes:
        keys: the keypair.
        trust: the trust list.
        own_id: the id this peer speaks as when it is not derived from its key
            (a repository made secure before ids were; None: `peer_id_of` the key).
    """

    keys: KeyPair
    trust: TrustList
    own_id: PeerId | None = None

    @property
    def peer_id(self) -> PeerId:
        """The id this peer's key speaks as: every message it sends carries it."""
        return self.own_id if self.own_id is not None else peer_id_of(self.keys.public)

    def trusts(self, key: bytes) -> bool:
        """True for the peer's own key and every key on its trust list."""
        return key == self.keys.public or key in self.trust

    def id_of(self, key: bytes) -> PeerId:
        """The only id a connection authenticated with `key` may send as: this
        peer's for its own key, the id the trust list binds to it, or the one
        derived from it."""
        if key == self.keys.public:
            return self.peer_id
        bound = self.trust.bound_id(key)
        return bound if bound is not None else peer_id_of(key)

    def speaks_as(self, key: bytes, peer_id: PeerId) -> bool:
        """Whether a connection authenticated with `key` may send as `peer_id`:
        the id derived from the key, or the one bound to it (`id_of`)."""
        if peer_id == peer_id_of(key):
            return True  # the common case, without reading the trust list
        return peer_id == self.id_of(key)

    @classmethod
    def create(cls, meta_dir: Path) -> Security:
        """Make the keypair and an empty trust list of the repository at `meta_dir`."""
        folder = key_folder(meta_dir)
        keys = create_keys(folder)
        trust = TrustList(folder / TRUST_FILE)
        trust.create()
        return cls(keys, trust)

    @classmethod
    def load(cls, meta_dir: Path, peer_id: PeerId | None = None) -> Security:
        """The keypair and trust list of the repository at `meta_dir`, whose
        configured id is `peer_id` (None: the one derived from its key).

        Raises:
            CorruptRepoError: the keypair is missing or exposed.
        """
        folder = key_folder(meta_dir)
        keys = load_keys(folder)
        own = peer_id if peer_id is not None and peer_id != peer_id_of(keys.public) else None
        return cls(keys, TrustList(folder / TRUST_FILE), own)


def own_address(address: str, security: Security | None) -> str:
    """`address` as a peer announces it: with its public key when it is secure.

    Raises:
        UsageError: the address names a key that is not this peer's.
    """
    endpoint, key = split_address(address)
    mine = security.keys.public if security is not None else None
    if key is not None and key != mine:
        raise UsageError(f"{address} names a key that is not this peer's; give the endpoint only")
    return endpoint if mine is None else keyed_address(endpoint, mine)
