"""Hostile messages for `mapctl bench fuzz` and the wire fuzz test (DESIGN §11).

The generator walks the protobuf schema of the envelope (every `oneof body`
field, so a message added to wire.proto is fuzzed without a line here) and
fills each field by its name and type, in one of three modes:

- "valid": values a real peer would send, drawn from `Pools` (the target's
  real chunk, item and commit ids, peers, ring keys, addresses), with embedded
  messages (holder entries, spatial entries, subscriptions, item payloads, log
  entries) built the way the core builds them.
- "fields": the same, but each field may take a hostile value instead: ids of
  the wrong length, huge or zero counts and numbers, NaN and infinite floats,
  unknown enum values, long strings, random bytes, long repeated fields.
- "bytes": a valid or field-mutated encoding, then broken: bit flips,
  truncation, inserted, deleted or repeated bytes, pure noise, extra frames.

It reads its randomness from one `random.Random`, so a seed replays a run and
hypothesis can drive it (tests/property/test_fuzz_wire.py passes a Random that
hypothesis controls, and shrinks). The wire schema is read here directly, not
through `mapapi.net.codec`: the codec cannot build the malformed messages a
fuzzer needs.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

from google.protobuf import struct_pb2
from google.protobuf.descriptor import Descriptor, FieldDescriptor
from google.protobuf.message import Message

from mapapi._pb.mapapi.v1 import core_pb2, lookup_pb2, types_pb2, wire_pb2
from mapapi.net.codec import Kind

MODES = ("valid", "fields", "bytes")
Fix = Callable[[Any], None]
"""Adjusts a filled body message before it is encoded."""
BODIES = tuple(f.name for f in wire_pb2.Envelope.DESCRIPTOR.oneofs_by_name["body"].fields)
"""Every body the envelope can carry (the `oneof body` field names)."""

_ID_FIELDS = {"chunk", "item", "commit_id", "id", "author", "sender", "subscriber", "holder"}
_ID_FIELDS |= {"chunk_id", "item_id", "chunks", "subscription"}
_KEY_FIELDS = {"key", "avoid"}
_TIME_FIELDS = {"time", "insert_time", "update_time", "lamport"}
_HUGE_INTS = (0, 1, 2**31 - 1, 2**32 - 1, 10**9, 2**62, 2**62 + 1, 2**63 - 1, 2**63, 2**64 - 1)
_ODD_FLOATS = (math.nan, math.inf, -math.inf, -1.0, 0.0, -0.0, 5e-324, 1e12, 1e308, -1e308)
_ODD_TEXT = ("", "tcp://", "tcp://127.0.0.1:99999", "ipc://", "garbage", "\x00", "é" * 9, "🛰")
_ODD_LENGTHS = (0, 1, 15, 17, 19, 21, 255, 4096, 70_000)
_LONG_LISTS = (50, 500, 3_000)
_MAX_DEPTH = 5


@dataclass
class Pools:
    """Values "valid" fields are drawn from: what the target really holds and knows.

    Ids are raw 16 bytes and ring keys 20 bytes, as they travel.
    """

    chunks: list[bytes]
    items: list[bytes]
    commits: list[bytes]
    peers: list[bytes]
    keys: list[bytes]
    addresses: list[str]
    tables: list[str]
    type_names: list[str]
    index: str = ""  # the target's spatial index fingerprint (a Hello must carry it)
    lamport: int = 1


@dataclass(frozen=True)
class Shot:
    """One message to send: its frames, the body it was made from, and how."""

    frames: list[bytes]
    body: str
    mode: str


class Generator:
    """Makes `Shot`s from one random source (see the module docstring).

    Args:
        rnd: every choice comes from it.
        pools: the "valid" values.
        senders: envelope sender ids to pick from (a stranger, a member).
    """

    def __init__(self, rnd: random.Random, pools: Pools, senders: list[bytes]) -> None:
        self.rnd = rnd
        self.pools = pools
        self.senders = senders
        self._next_id = rnd.randrange(1, 2**40)
        self._hostile = 0.0  # chance that a field takes a hostile value (per `shot`)

    def shot(
        self,
        body: str | None = None,
        mode: str | None = None,
        *,
        sender: bytes | None = None,
        fix: Fix | None = None,
    ) -> Shot:
        """A new message: of `body` (default: any) made in `mode` (default: any).

        Args:
            sender: the envelope's sender (default: one of `senders`).
            fix: makes the filled body coherent (one chunk throughout, a real
                proposal); in "fields" mode it is skipped now and then, so the
                body keeps its hostile values.
        """
        rnd = self.rnd
        body = body or rnd.choice(BODIES)
        mode = mode or rnd.choices(MODES, weights=(4, 4, 2))[0]
        self._hostile = 0.2 if mode == "fields" else 0.0
        env = self._envelope(body, sender)
        if fix is None and body == "hello":  # a Hello is heard only if it names its sender
            fix = partial(_hello, env.sender)
        if fix is not None and rnd.random() >= 2 * self._hostile:
            fix(getattr(env, body))
        data = env.SerializeToString()
        if mode == "bytes":
            return Shot(self._mangle(data), body, mode)
        return Shot([data], body, mode)

    # -- the envelope ------------------------------------------------------------
    def _envelope(self, body: str, sender: bytes | None) -> wire_pb2.Envelope:
        rnd = self.rnd
        self._next_id += 1
        env = wire_pb2.Envelope()
        env.request_id = self._int(self._next_id, 64)
        env.sender = self._bytes(sender or rnd.choice(self.senders))
        env.lamport = self._int(self.pools.lamport + rnd.randrange(3), 64)
        kind = rnd.choices([Kind.REQUEST, Kind.NOTIFY], weights=(9, 1))[0]
        env.kind = self._odd(kind, (0, Kind.REPLY, 7, 2**31 - 1))  # type: ignore[assignment]
        self._fill(getattr(env, body), 0)
        return env

    # -- a commit through the target's log (`mapbench.fuzz` builds the proposal) ------
    def propose(self, chunk: bytes, proposal: bytes, sender: bytes) -> Shot:
        """A `RaftPropose` of the encoded `proposal` to `chunk` (valid or not)."""

        def fix(m: Any) -> None:
            m.chunk, m.proposal = chunk, proposal

        return self.shot("raft_propose", self.rnd.choice(MODES), sender=sender, fix=fix)

    # -- hostile choices -------------------------------------------------------------
    def _odd(self, value: Any, odd: tuple[Any, ...]) -> Any:
        """`value`, or (with the mode's probability) one of `odd`."""
        return self.rnd.choice(odd) if self.rnd.random() < self._hostile else value

    def _int(self, value: int, bits: int) -> int:
        return min(self._odd(value, _HUGE_INTS), 2**bits - 1)

    def _bytes(self, value: bytes) -> bytes:
        if self.rnd.random() >= self._hostile:
            return value
        return self.rnd.randbytes(self.rnd.choice(_ODD_LENGTHS))

    # -- fields, by name and type -------------------------------------------------------
    def _fill(self, message: Message, depth: int) -> None:
        message.SetInParent()
        descriptor: Descriptor = message.DESCRIPTOR
        for f in descriptor.fields:
            if self.rnd.random() < self._hostile / 2:
                continue  # left unset: the default value
            if f.is_repeated:
                if f.message_type is not None and f.message_type.GetOptions().map_entry:
                    self._map(message, f, depth)
                else:
                    self._repeated(message, f, depth)
            elif f.type == FieldDescriptor.TYPE_MESSAGE:
                if depth < _MAX_DEPTH:
                    self._fill(getattr(message, f.name), depth + 1)
            else:
                setattr(message, f.name, self._scalar(f, depth))

    def _repeated(self, message: Message, f: FieldDescriptor, depth: int) -> None:
        rnd = self.rnd
        n = rnd.choice((0, 1, 1, 2, 3)) if depth < _MAX_DEPTH else 0
        long = depth == 0 and rnd.random() < self._hostile / 2
        hostile, self._hostile = self._hostile, 0.0 if long else self._hostile
        target = getattr(message, f.name)
        for _ in range(rnd.choice(_LONG_LISTS) if long else n):  # long lists of plain values
            if f.type == FieldDescriptor.TYPE_MESSAGE:
                self._fill(target.add(), depth + 1)
            else:
                target.append(self._scalar(f, depth))
        self._hostile = hostile

    def _map(self, message: Message, f: FieldDescriptor, depth: int) -> None:
        target = getattr(message, f.name)
        value = f.message_type.fields_by_name["value"]
        for _ in range(self.rnd.randrange(3) if depth < _MAX_DEPTH else 0):
            key = self.rnd.choice(("x", "y", "label", "bbox", ""))
            if value.type == FieldDescriptor.TYPE_MESSAGE:
                self._fill(target[key], depth + 1)
            else:
                target[key] = self._scalar(value, depth)

    def _scalar(self, f: FieldDescriptor, depth: int) -> Any:
        rnd, name, t = self.rnd, f.name, f.type
        if t == FieldDescriptor.TYPE_BOOL:
            return rnd.random() < 0.5
        if t == FieldDescriptor.TYPE_DOUBLE:
            return self._odd(rnd.choice((30.0, 5.0, 1.0, rnd.uniform(-50, 50))), _ODD_FLOATS)
        if t == FieldDescriptor.TYPE_ENUM:
            return self._odd(rnd.choice(f.enum_type.values).number, (7, 2**31 - 1))
        if t in (FieldDescriptor.TYPE_UINT64, FieldDescriptor.TYPE_INT64):
            return self._int(self._plain_int(name), 63 if t == f.TYPE_INT64 else 64)
        if t in (FieldDescriptor.TYPE_UINT32, FieldDescriptor.TYPE_INT32):
            return self._int(self._plain_int(name), 31 if t == f.TYPE_INT32 else 32)
        if t == FieldDescriptor.TYPE_STRING:
            text = self._plain_text(name)
            if rnd.random() < self._hostile:
                return rnd.choice((*_ODD_TEXT, "x" * rnd.choice((257, 1025, 5000, 70_000))))
            return text
        if t == FieldDescriptor.TYPE_BYTES:
            return self._bytes(self._plain_bytes(name, depth))
        raise TypeError(f"no generator for field {f.full_name} of type {t}")

    def _plain_int(self, name: str) -> int:
        rnd, pools = self.rnd, self.pools
        if name in _TIME_FIELDS:
            return max(0, pools.lamport + rnd.randrange(-3, 4))
        return rnd.randrange(100)

    def _plain_text(self, name: str) -> str:
        rnd, pools = self.rnd, self.pools
        if name == "address":
            return rnd.choice(pools.addresses)
        if name in ("table", "name"):
            return rnd.choice([*pools.tables, "fuzz", ""])
        if name == "type_name":
            return rnd.choice(pools.type_names)
        if name == "index":
            return pools.index
        if name == "filter":
            return rnd.choice(("bbox", "region", ""))
        return rnd.choice(("", "a", "fuzz", "door"))

    def _plain_bytes(self, name: str, depth: int) -> bytes:
        rnd, pools = self.rnd, self.pools
        if name in _ID_FIELDS:
            pool = {"chunk": pools.chunks, "chunk_id": pools.chunks, "chunks": pools.chunks}
            pool |= {"item": pools.items, "item_id": pools.items, "commit_id": pools.commits}
            choices = pool.get(name, pools.peers)
            return rnd.choice(choices) if rnd.random() < 0.8 else rnd.randbytes(16)
        if name in _KEY_FIELDS:
            return rnd.choice(pools.keys) if rnd.random() < 0.7 else rnd.randbytes(20)
        embedded = _EMBEDDED.get(name)
        if embedded is not None and depth < _MAX_DEPTH:
            kind = rnd.choice(embedded)
            if kind is None:  # a holder entry: 16 id bytes and an address
                return rnd.choice(pools.peers) + rnd.choice(pools.addresses).encode()
            inner = kind()
            self._fill(inner, depth + 1)
            return bytes(inner.SerializeToString())
        return rnd.randbytes(rnd.choice((0, 4, 16)))

    # -- byte-level damage ------------------------------------------------------------------
    def _mangle(self, data: bytes) -> list[bytes]:
        rnd = self.rnd
        buf = bytearray(data)
        for _ in range(rnd.randrange(1, 4)):
            cut = rnd.randrange(len(buf) + 1)
            how = rnd.randrange(7)
            if how == 0 and buf:  # flip bits
                for _ in range(rnd.randrange(1, 9)):
                    buf[rnd.randrange(len(buf))] ^= 1 << rnd.randrange(8)
            elif how == 1:
                del buf[cut:]  # truncate
            elif how == 2:
                buf[cut:cut] = rnd.randbytes(rnd.randrange(1, 32))
            elif how == 3:
                del buf[cut : cut + rnd.randrange(1, 16)]
            elif how == 4:
                buf[cut:cut] = buf[cut : cut + rnd.randrange(1, 64)] * rnd.randrange(1, 4)
            elif how == 5:
                buf = bytearray(rnd.randbytes(rnd.randrange(0, 256)))  # noise
            else:
                buf += rnd.randbytes(rnd.randrange(1, 16))
        frames = [bytes(buf)]
        if rnd.random() < 0.1:  # a second frame the ROUTER does not expect
            frames.append(rnd.randbytes(rnd.randrange(0, 8)))
        return frames


def _hello(sender: bytes, m: Any) -> None:
    m.member.id = sender


_EMBEDDED: dict[str, tuple[Any, ...]] = {
    # Chord values: a holder entry, a spatial index entry, a subscription
    "member": (None, lookup_pb2.SpatialEntry, lookup_pb2.Subscription),
    "members": (None, lookup_pb2.SpatialEntry),
    "argument": (lookup_pb2.SpatialFilter,),  # a Chord filter's argument
    # An item payload: of the target's table, or a Struct (whose numbers may be
    # NaN or infinite, `_ODD_FLOATS`), which no Counter table accepts: refused by
    # the commit check, never stored (issue 18: one value poisoned a table).
    "data": (types_pb2.Counter, types_pb2.Counter, struct_pb2.Struct),
    # A chunk's log entry (`RaftPropose.proposal`): a proposal, a decision or a floor.
    "proposal": (core_pb2.ChunkLogEntry,),
}
