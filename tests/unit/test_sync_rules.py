"""A blocking script's peer keeps the map tables' rules, as mapctl's does."""

from __future__ import annotations

from pathlib import Path

from mapapi import Repository
from mapapi.maps.rules import MissionRules
from mapapi.sync import open_peer


def test_a_blocking_peer_checks_the_mission_rules(tmp_path: Path) -> None:
    Repository.init(tmp_path / "r")
    with open_peer(tmp_path / "r") as peer:
        assert any(isinstance(rule, MissionRules) for rule in peer.rules)
