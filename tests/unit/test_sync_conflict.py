"""The blocking facade keeps conflicts usable: `err.merge()` blocks like the rest."""

import pytest

from mapapi import ConflictError, Peer
from mapapi.core.table import message_class
from mapapi.sync import Blocking, wrap

Counter = message_class("mapapi.v1.Counter")


def test_merge_of_a_blocking_conflict_returns_a_blocking_transaction() -> None:
    with wrap(Peer.in_memory()) as peer:
        peer.create_table("c", Counter)
        chunk = peer.create_chunk("c")
        seed = peer.begin()
        item = seed.insert("c", Counter(name="x", value=0), chunk)
        seed.commit("seed")
        first, second = peer.begin(), peer.begin()
        first.update("c", item, Counter(name="x", value=1))
        second.update("c", item, Counter(name="x", value=2))
        other = second.insert("c", Counter(name="y", value=5), chunk)
        first.commit("first")
        with pytest.raises(ConflictError) as caught:
            second.commit("second")

        retry = caught.value.merge()

        assert isinstance(retry, Blocking)
        assert retry.commit("only the insert") is not None
        assert peer.begin().get("c", other).value == 5
        assert peer.begin().get("c", item).value == 1
