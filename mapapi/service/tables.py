"""The tables of a peer's repository: their descriptors (decoded once, cached) and
the auto-merge policy each may have (DESIGN §5), consulted when a commit meets a
conflicting revision."""

from __future__ import annotations

from typing import TYPE_CHECKING

from mapapi.core.errors import UsageError
from mapapi.core.table import TableDescriptor

if TYPE_CHECKING:
    from google.protobuf.message import Message

    from mapapi.core.change import Change
    from mapapi.core.history import Revision
    from mapapi.core.merge import MergePolicy
    from mapapi.store.base import ReplicaStore


class Tables:
    """The tables of `store` (`Peer.create_table`, `Peer.table`, `Peer.set_merge_policy`)."""

    def __init__(self, store: ReplicaStore) -> None:
        self.store = store
        self._descriptors: dict[str, TableDescriptor] = {}
        self._policies: dict[str, MergePolicy] = {}

    def create(
        self, name: str, message_type: str | type[Message], replication: int = 0
    ) -> TableDescriptor:
        """Create a table of `message_type` (a class or a full protobuf name), whose
        chunks have the replication factor `replication` (0: the swarm's default)."""
        check_replication(replication)
        if not name or not name.replace("_", "").replace("-", "").replace(".", "").isalnum():
            raise UsageError(f"bad table name {name!r}: use letters, digits, '_', '-', '.'")
        if isinstance(message_type, str):
            descriptor = TableDescriptor.named(name, message_type)
        else:
            descriptor = TableDescriptor(name, message_type)
        self.store.add_table(name, descriptor.type_name, replication)
        self._descriptors[name] = descriptor
        return descriptor

    def get(self, name: str) -> TableDescriptor:
        """One table's descriptor.

        Raises:
            UsageError: there is no such table.
        """
        descriptor = self._descriptors.get(name)
        if descriptor is None:
            type_name = self.store.tables().get(name)
            if type_name is None:
                raise UsageError(f"no table {name!r}; create it with `mapctl table create`")
            descriptor = self._descriptors[name] = TableDescriptor.named(name, type_name)
        return descriptor

    def set_merge_policy(self, table: str, policy: MergePolicy | None) -> None:
        """Install (or with None, remove) the auto-merge policy of a table."""
        self.get(table)
        if policy is None:
            self._policies.pop(table, None)
        else:
            self._policies[table] = policy

    def try_merge(self, ours: Change, theirs: Revision, base: Revision | None) -> bytes | None:
        """The merged value of a conflicting change by its table's policy, or None
        (no policy, or the policy gave up)."""
        policy = self._policies.get(ours.table)
        if policy is None:
            return None
        descriptor = self.get(ours.table)
        merged = policy(
            None if base is None or base.removed else descriptor.decode(base.data),
            descriptor.decode(ours.data),
            descriptor.decode(theirs.data),
        )
        return None if merged is None else descriptor.encode(merged)


def check_replication(factor: int) -> None:
    """Refuse a replication factor that cannot be one (0 stands for the default).

    Raises:
        UsageError: `factor` is negative.
    """
    if factor < 0:
        raise UsageError(
            f"bad replication factor {factor}: the most voters a chunk's group has, at "
            "least 1 (0: the default)"
        )
