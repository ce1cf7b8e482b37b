"""`mapctl completion` and what TAB offers (issue 15): the shell sets COMP_WORDS and
COMP_CWORD and runs `mapctl` with `_MAPCTL_COMPLETE=bash_complete`; the answers
are read from a real repository found from `-C` or from the cwd."""

from __future__ import annotations

import json
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from mapctl.cli import cli
from mapctl.completion import attach
from tests.cli.conftest import STRUCT, InProcessDaemon, Mapctl

INTEL = Path(__file__).resolve().parents[2] / "sample_maps" / "pose_graphs" / "intel.g2o"


def complete(*words: str, shell: str = "bash") -> list[str]:
    """What `mapctl WORDS<TAB>` offers: the last word is the one being typed.

    Returns the values (bash) or the raw value/help lines (zsh)."""
    line = ["mapctl", *words]
    env = {
        "_MAPCTL_COMPLETE": f"{shell}_complete",
        "COMP_WORDS": " ".join(line),
        "COMP_CWORD": str(len(line) - 1),
    }
    result = CliRunner().invoke(cli, [], env=env, prog_name="mapctl")
    assert result.exit_code == 0, result.output
    assert result.stderr == "", "completion must stay silent"
    lines = [line for line in result.stdout.splitlines() if line]  # none: one empty line
    if shell != "bash":
        return lines
    return [line.split(",", 1)[1] for line in lines]


@pytest.fixture
def filled(mapctl: Mapctl) -> dict[str, str]:
    """A repository with tables `poses` and `doors`, an item, a commit, a view
    `alice` and the mission `intel`; the ids, by kind."""
    mapctl("table", "create", "poses", "--type", STRUCT)
    mapctl("table", "create", "doors", "--type", STRUCT)
    chunk = mapctl.json("chunk", "create", "poses")["id"]
    item = mapctl.insert({"x": 1.0}, table="poses")
    commit = mapctl.commit("first pose")["commit"]
    mapctl("view", "open", view="alice")
    mapctl("import", str(INTEL), "--robot", "hahnel")
    return {"repo": str(mapctl.repo), "chunk": chunk, "item": item, "commit": commit}


class TestRepositoryWords:
    def test_table_names(self, filled: dict[str, str]) -> None:
        assert {"poses", "doors", "missions", "vertices", "edges"} <= set(
            complete("-C", filled["repo"], "ls", "")
        )
        assert complete("-C", filled["repo"], "get", "po") == ["poses"]
        assert complete("-C", filled["repo"], "query-bbox", "--table", "d") == ["doors"]

    def test_view_names_include_main(self, filled: dict[str, str]) -> None:
        assert complete("-C", filled["repo"], "--view", "") == ["alice", "main"]
        assert complete("-C", filled["repo"], "--view", "al") == ["alice"]

    def test_mission_names(self, filled: dict[str, str]) -> None:
        assert complete("-C", filled["repo"], "export", "") == ["intel"]
        assert complete("-C", filled["repo"], "plot", "--mission", "in") == ["intel"]
        assert complete("-C", filled["repo"], "export", "x") == []

    def test_id_prefixes(self, filled: dict[str, str]) -> None:
        repo = filled["repo"]
        commit, chunk, item = filled["commit"], filled["chunk"], filled["item"]
        assert commit in complete("-C", repo, "show", "")
        assert complete("-C", repo, "show", commit[:4]) == [commit]
        assert complete("-C", repo, "chunk", "participate", chunk[:4]) == [chunk]
        assert chunk in complete("-C", repo, "ls", "poses", "--chunk", "")
        assert complete("-C", repo, "get", "poses", item[:4]) == [item]
        assert complete("-C", repo, "get", "doors", item[:4]) == []  # ids of that table only

    def test_the_repository_of_the_cwd(
        self, filled: dict[str, str], monkeypatch: pytest.MonkeyPatch
    ) -> None:
        monkeypatch.chdir(Path(filled["repo"]))
        assert complete("get", "po") == ["poses"]

    async def test_while_the_peer_daemon_runs(self, daemon: InProcessDaemon) -> None:
        # the daemon holds the store open; completion reads it beside the daemon
        assert (await daemon("table", "create", "poses", "--type", STRUCT)).code == 0
        assert complete("-C", str(daemon.repo), "ls", "po") == ["poses"]

    def test_zsh_gets_help_text(self, filled: dict[str, str]) -> None:
        lines = complete("-C", filled["repo"], "show", filled["commit"][:6], shell="zsh")
        assert lines == ["plain", filled["commit"], "first pose"]


class TestNothingToOffer:
    def test_outside_a_repository_offers_nothing_and_says_nothing(self, tmp_path: Path) -> None:
        assert complete("-C", str(tmp_path), "get", "") == []
        assert complete("-C", str(tmp_path), "--view", "") == []

    def test_a_damaged_store_offers_nothing(self, filled: dict[str, str]) -> None:
        (Path(filled["repo"]) / ".mapapi" / "store.sqlite").write_bytes(b"not sqlite")
        assert complete("-C", filled["repo"], "show", "") == []

    def test_commands_still_complete_by_themselves(self, tmp_path: Path) -> None:
        assert "completion" in complete("-C", str(tmp_path), "comp")


class TestScript:
    @pytest.mark.parametrize("shell", ["bash", "zsh", "fish"])
    def test_prints_the_script_of_each_shell(self, shell: str) -> None:
        result = CliRunner().invoke(cli, ["completion", shell])
        assert result.exit_code == 0, result.output
        assert f"_MAPCTL_COMPLETE={shell}_complete" in result.stdout

    def test_an_unknown_shell_is_a_usage_error(self) -> None:
        result = CliRunner().invoke(cli, ["completion", "tcsh"])
        assert result.exit_code == 2
        assert "bash" in result.output


class TestAttach:
    def test_a_renamed_parameter_fails_loudly(self) -> None:
        @click.group()
        def bare() -> None:
            """A group without the parameters completion expects."""

        with pytest.raises(LookupError, match="view_name"):
            attach(bare)

    def test_every_listed_parameter_has_a_callback(self) -> None:
        # json.dumps: a readable failure listing the pairs
        pairs = attach(cli)
        assert ("", "view_name") in pairs, json.dumps(pairs)
        assert ("show", "commit_ref") in pairs, json.dumps(pairs)
