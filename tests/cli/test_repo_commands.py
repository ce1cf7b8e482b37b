"""`init`, `table create/list` and `chunk create/list`."""

from __future__ import annotations

import json
import re
import sqlite3
from pathlib import Path

from click.testing import CliRunner

from mapapi import AlreadyInitialisedError, Repository, UsageError
from mapctl.cli import cli
from tests.cli.conftest import STRUCT, Mapctl, run_main

HEX32 = re.compile(r"[0-9a-f]{32}")


class TestInit:
    def test_init_creates_a_repository(self, tmp_path: Path) -> None:
        path = tmp_path / "fresh"
        result = CliRunner().invoke(cli, ["init", str(path), "--name", "robot1"])
        assert result.exit_code == 0, result.output
        assert "Initialised empty map repository" in result.stdout
        repository = Repository.find(path)
        assert repository.config.name == "robot1"
        assert (path / ".mapapi" / "config.toml").is_file()

    def test_init_json_and_default_name(self, tmp_path: Path) -> None:
        path = tmp_path / "scout"
        result = CliRunner().invoke(cli, ["init", str(path), "--json"])
        assert result.exit_code == 0, result.output
        info = json.loads(result.stdout)
        assert info["name"] == "scout"
        assert info["path"] == str(path.resolve())
        assert HEX32.fullmatch(info["peer_id"])

    def test_init_twice_is_an_error(self, repo: Path) -> None:
        result = CliRunner().invoke(cli, ["init", str(repo)])
        assert isinstance(result.exception, AlreadyInitialisedError)
        outcome = run_main(["init", str(repo)])
        assert outcome.code == 1
        assert len(outcome.err_lines) == 1
        assert "already a map repository" in outcome.err

    def test_commands_find_the_repository_from_a_subfolder(self, repo: Path) -> None:
        sub = repo / "deep" / "er"
        sub.mkdir(parents=True)
        Mapctl(sub)("table", "create", "pts", "--type", STRUCT)
        assert Mapctl(repo).json("table", "list")["tables"][0]["name"] == "pts"


class TestTables:
    def test_create_and_list_json(self, mapctl: Mapctl) -> None:
        created = mapctl.json("table", "create", "pts", "--type", STRUCT)
        assert created == {"name": "pts", "type": STRUCT, "replication": 3}
        mapctl("table", "create", "counts", "--type", "mapapi.v1.Counter")
        mapctl("chunk", "create", "pts")
        listing = mapctl.json("table", "list")
        assert listing == {
            "tables": [
                {"name": "counts", "type": "mapapi.v1.Counter", "chunks": 0, "items": 0},
                {"name": "pts", "type": STRUCT, "chunks": 1, "items": 0},
            ]
        }

    def test_list_counts_committed_items(self, points: Mapctl) -> None:
        points.insert({"x": 1})
        points.insert({"x": 2})
        assert points.json("table", "list")["tables"][0]["items"] == 0  # staged only
        points.commit()
        assert points.json("table", "list")["tables"][0]["items"] == 2

    def test_list_empty(self, mapctl: Mapctl) -> None:
        assert mapctl.json("table", "list") == {"tables": []}
        assert "no tables" in mapctl("table", "list")

    def test_unknown_type_is_a_usage_error(self, mapctl: Mapctl) -> None:
        result = mapctl.invoke("table", "create", "pts", "--type", "no.such.Message")
        assert isinstance(result.exception, UsageError)
        assert "'no.such.Message' is not a table type" in str(result.exception)
        assert STRUCT in str(result.exception)  # names the table types
        assert mapctl.json("table", "list") == {"tables": []}

    def test_duplicate_table_is_a_usage_error(self, points: Mapctl) -> None:
        result = points.invoke("table", "create", "pts", "--type", STRUCT)
        assert isinstance(result.exception, UsageError)
        assert "already exists" in str(result.exception)

    def test_type_is_required(self, mapctl: Mapctl) -> None:
        result = mapctl.invoke("table", "create", "pts")
        assert result.exit_code == 2
        assert "--type" in result.output

    def test_a_replication_factor_for_its_chunks(self, mapctl: Mapctl) -> None:
        made = mapctl.json("table", "create", "wide", "--type", STRUCT, "--replication", "5")
        assert made["replication"] == 5
        assert "replication 3" in mapctl("table", "create", "plain", "--type", STRUCT)
        result = mapctl.invoke("table", "create", "bad", "--type", STRUCT, "--replication", "-1")
        assert result.exit_code == 2  # refused before anything is created
        assert [t["name"] for t in mapctl.json("table", "list")["tables"]] == ["plain", "wide"]


class TestChunks:
    def test_a_chunks_replication_factor_is_its_own_or_its_tables(self, mapctl: Mapctl) -> None:
        mapctl("table", "create", "wide", "--type", STRUCT, "--replication", "5")
        inherits = mapctl.json("chunk", "create", "wide")
        own = mapctl.json("chunk", "create", "wide", "--replication", "1")
        assert (inherits["replication"], own["replication"]) == (5, 1)
        listed = {c["id"]: c["replication"] for c in mapctl.json("chunk", "list")["chunks"]}
        assert listed == {inherits["id"]: 5, own["id"]: 1}
        assert "replication" in mapctl("chunk", "list")

    def test_a_store_from_before_factors_has_the_default(self, points: Mapctl) -> None:
        store = points.repo / ".mapapi" / "store.sqlite"
        with sqlite3.connect(store) as con:  # as a store of an earlier format was
            con.execute("ALTER TABLE chunks DROP COLUMN replication")
            con.execute("ALTER TABLE tables DROP COLUMN replication")
        created = points.json("chunk", "create", "pts")
        assert created["replication"] == 3
        assert {c["replication"] for c in points.json("chunk", "list")["chunks"]} == {3}

    def test_create_json_prints_the_id(self, points: Mapctl) -> None:
        created = points.json("chunk", "create", "pts")
        assert HEX32.fullmatch(created["id"])
        assert created["table"] == "pts"

    def test_create_plain_prints_the_id(self, points: Mapctl) -> None:
        assert HEX32.fullmatch(points("chunk", "create", "pts").strip())

    def test_list_json(self, mapctl: Mapctl) -> None:
        mapctl("table", "create", "pts", "--type", STRUCT)
        mapctl("table", "create", "other", "--type", STRUCT)
        first = mapctl.json("chunk", "create", "pts")["id"]
        second = mapctl.json("chunk", "create", "other")["id"]
        mapctl.json("set", "pts", "--chunk", first, '{"a": 1}')
        mapctl.commit()
        chunks = mapctl.json("chunk", "list")["chunks"]
        holders = [str(Repository.find(mapctl.repo).config.peer_id)]  # this peer alone
        common = {"holders": holders, "roles": {}, "replication": 3}  # no group runs offline
        assert sorted(chunks, key=lambda c: c["id"]) == sorted(
            [
                {"id": first, "table": "pts", "items": 1, **common},
                {"id": second, "table": "other", "items": 0, **common},
            ],
            key=lambda c: c["id"],
        )
        only = mapctl.json("chunk", "list", "--table", "other")["chunks"]
        assert [c["id"] for c in only] == [second]

    def test_chunk_of_unknown_table(self, mapctl: Mapctl) -> None:
        result = mapctl.invoke("chunk", "create", "nope")
        assert isinstance(result.exception, UsageError)
        assert "mapctl table create" in str(result.exception)
