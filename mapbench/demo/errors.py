"""The demo's own error."""

from __future__ import annotations

from mapapi.core.errors import MapError


class DemoFailed(MapError):
    """The swarm did not do what the demo shows (a bug: see the peers' logs)."""
