"""Peers meeting and leaving the swarm, and the CLI's control calls to its daemon.

Plain frozen dataclasses, each mapping field by field onto the message of the
same name in `proto/mapapi/v1/wire.proto` (see `mapapi.net.messages`).
"""

from __future__ import annotations

from dataclasses import dataclass

from mapapi.core.ids import PeerId


@dataclass(frozen=True, slots=True)
class Member:
    """A peer of the swarm and the address others reach it at."""

    id: PeerId
    address: str
    name: str = ""


@dataclass(frozen=True, slots=True)
class Ack:
    """Success with nothing to return."""


@dataclass(frozen=True, slots=True)
class Hello:
    """A peer introduces itself; answered with `Welcome`. `index` is the
    fingerprint of its spatial index geometry, which must equal the member's."""

    member: Member
    index: str = ""


@dataclass(frozen=True, slots=True)
class Welcome:
    """Every member the answering peer knows, itself included."""

    members: tuple[Member, ...]


@dataclass(frozen=True, slots=True)
class Bye:
    """The sender leaves the swarm gracefully."""


@dataclass(frozen=True, slots=True)
class ControlCall:
    """The CLI asks the running peer to perform one `mapapi.service.ops` operation,
    proving with `token` that it runs as the daemon's owner."""

    op: str
    args_json: str
    token: str = ""


@dataclass(frozen=True, slots=True)
class ControlResult:
    """The JSON result of a `ControlCall`."""

    json: str


BODIES: dict[str, type] = {
    "ack": Ack,
    "hello": Hello,
    "welcome": Welcome,
    "bye": Bye,
    "control_call": ControlCall,
    "control_result": ControlResult,
}
"""Envelope body field -> class, for the messages of this area."""
