"""The public API imports and exposes what the docs promise."""

import mapapi


def test_public_api_exports_peer_and_errors() -> None:
    assert mapapi.Peer is not None
    assert issubclass(mapapi.ConflictError, mapapi.MapError)
    assert mapapi.ConflictError.retriable
