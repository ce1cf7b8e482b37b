"""The repository on disk (mapapi.service.repo, DESIGN §9)."""

from collections.abc import Callable
from pathlib import Path

import pytest

from mapapi import AlreadyInitialisedError, CorruptRepoError, NotARepoError, Repository
from mapapi.core.ids import PeerId
from mapapi.store import SqliteStore


class TestInit:
    def test_creates_config_and_store(self, tmp_path: Path) -> None:
        repo = Repository.init(tmp_path / "robot", "rover-1")
        assert repo.root == (tmp_path / "robot").resolve()
        assert repo.meta_dir == repo.root / ".mapapi"
        assert (repo.meta_dir / "config.toml").is_file()
        assert repo.config.name == "rover-1"
        assert isinstance(repo.config.peer_id, PeerId)
        store = repo.open_store()
        try:
            assert isinstance(store, SqliteStore)
            assert store.clock() == 0
        finally:
            store.close()
        assert not (repo.meta_dir / "config.toml.tmp").exists()

    def test_name_defaults_to_the_folder_name(self, tmp_path: Path) -> None:
        assert Repository.init(tmp_path / "scout").config.name == "scout"

    def test_each_repository_gets_its_own_peer_id(
        self, make_repo: Callable[..., Repository]
    ) -> None:
        assert make_repo().config.peer_id != make_repo().config.peer_id

    def test_twice_is_refused(self, tmp_path: Path) -> None:
        first = Repository.init(tmp_path, "one")
        with pytest.raises(AlreadyInitialisedError, match="already a map repository"):
            Repository.init(tmp_path, "two")
        assert Repository.find(tmp_path).config == first.config

    def test_init_in_a_subfolder_of_a_repository_is_allowed(self, tmp_path: Path) -> None:
        Repository.init(tmp_path, "outer")
        inner = Repository.init(tmp_path / "sub", "inner")
        assert Repository.find(tmp_path / "sub" / "deeper" / "..").config == inner.config


class TestFind:
    def test_finds_the_repository_at_its_root(self, tmp_path: Path) -> None:
        made = Repository.init(tmp_path, "r")
        found = Repository.find(tmp_path)
        assert found.root == made.root
        assert found.config == made.config

    def test_walks_up_from_a_subfolder(self, tmp_path: Path) -> None:
        made = Repository.init(tmp_path / "repo", "r")
        deep = tmp_path / "repo" / "maps" / "2024" / "run1"
        deep.mkdir(parents=True)
        found = Repository.find(deep)
        assert found.root == made.root
        assert found.config.peer_id == made.config.peer_id

    def test_outside_any_repository(self, tmp_path: Path) -> None:
        Repository.init(tmp_path / "repo", "r")
        (tmp_path / "elsewhere").mkdir()
        with pytest.raises(NotARepoError, match="mapctl init"):
            Repository.find(tmp_path / "elsewhere")

    def test_a_half_initialised_folder_is_not_a_repository(self, tmp_path: Path) -> None:
        (tmp_path / ".mapapi").mkdir()
        with pytest.raises(NotARepoError):
            Repository.find(tmp_path)

    @pytest.mark.parametrize(
        "name", ["rover 🤖", "café", 'quote " and \\ backslash', "tab\tnew\nline", "del\x7f"]
    )
    def test_any_peer_name_survives_the_config_file(self, tmp_path: Path, name: str) -> None:
        Repository.init(tmp_path, name)
        assert Repository.find(tmp_path).config.name == name


class TestDamagedConfig:
    @pytest.mark.parametrize(
        "text",
        [
            "this is [not toml",
            'name = "r"\n',  # no peer id
            'peer_id = "0123456789abcdef0123456789abcdef"\n',  # no name
            'name = "r"\npeer_id = "not-an-id"\n',
            "\x00\x01\x02",
        ],
    )
    def test_is_corrupt(self, tmp_path: Path, text: str) -> None:
        repo = Repository.init(tmp_path, "r")
        config = repo.meta_dir / "config.toml"
        config.write_text(text, encoding="utf-8")
        with pytest.raises(CorruptRepoError, match=r"config\.toml is damaged"):
            Repository.find(tmp_path)

    def test_config_that_is_not_utf8_is_corrupt(self, tmp_path: Path) -> None:
        repo = Repository.init(tmp_path, "r")
        (repo.meta_dir / "config.toml").write_bytes(b'name = "\xff\xfe"\n')
        with pytest.raises(CorruptRepoError, match=r"config\.toml is damaged"):
            Repository.find(tmp_path)

    def test_damaged_store_is_corrupt(self, tmp_path: Path) -> None:
        repo = Repository.init(tmp_path, "r")
        repo.store_path.write_bytes(b"garbage" * 100)
        with pytest.raises(CorruptRepoError):
            Repository.find(tmp_path).open_store()
