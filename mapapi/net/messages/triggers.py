"""What a committing peer pushes to a subscriber (DESIGN §8).

Plain frozen dataclasses, each mapping field by field onto the message of the
same name in `proto/mapapi/v1/wire.proto` (see `mapapi.net.messages`).
"""

from __future__ import annotations

from dataclasses import dataclass

from mapapi.core.history import CommitRecord, Revision
from mapapi.net.messages.holding import TableInfo


@dataclass(frozen=True, slots=True)
class TriggerPush:
    """The revisions of one commit that match a subscription, for its subscriber."""

    subscription: bytes
    record: CommitRecord
    revisions: tuple[Revision, ...]
    tables: tuple[TableInfo, ...] = ()


BODIES: dict[str, type] = {
    "trigger_push": TriggerPush,
}
"""Envelope body field -> class, for the messages of this area."""
