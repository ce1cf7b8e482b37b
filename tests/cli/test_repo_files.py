"""A corrupt, foreign or unreadable repository file gives one clear line (issue 7 §5).

Each case damages a real repository the way a bad copy, a bad disk, another
application or a wrong user would, then runs `mapctl` through its console
entry point: one error line that names the file and what to do, exit status 1,
never a traceback.
"""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from mapapi import Peer
from tests.cli.conftest import Mapctl

STORE = Path(".mapapi") / "store.sqlite"
CONFIG = Path(".mapapi") / "config.toml"
NOBODY = 65534
ROOT = os.geteuid() == 0


def _sql(path: Path, *statements: str) -> None:
    con = sqlite3.connect(path)
    try:
        for statement in statements:
            con.execute(statement)
        con.commit()
    finally:
        con.close()


def _truncate(repo: Path) -> None:
    _sql(repo / STORE, "PRAGMA wal_checkpoint(TRUNCATE)")  # the data into the main file
    data = (repo / STORE).read_bytes()
    (repo / STORE).write_bytes(data[: len(data) // 2])


def _foreign(repo: Path) -> None:
    (repo / STORE).unlink()
    _sql(repo / STORE, "CREATE TABLE songs (title TEXT)")


def _folder(repo: Path) -> None:
    (repo / STORE).unlink()
    (repo / STORE).mkdir()


DAMAGE: dict[str, tuple[Callable[[Path], None], str]] = {
    "truncated": (_truncate, "is not a mapapi store (database disk image is malformed)"),
    "random bytes": (
        lambda r: (r / STORE).write_bytes(os.urandom(8192)),
        "is not a mapapi store: not even a SQLite database",
    ),
    "empty": (lambda r: (r / STORE).write_bytes(b""), "is not a mapapi store: the file is empty"),
    "another application's SQLite file": (
        _foreign,
        "is not a mapapi store: a SQLite database of another application",
    ),
    "a dropped table": (
        lambda r: _sql(r / STORE, "DROP TABLE revisions"),
        "is damaged: its table 'revisions' is missing",
    ),
    "a damaged row": (
        lambda r: _sql(r / STORE, "UPDATE revisions SET item_id = 'not hex'"),
        "a revision in",
    ),
    "a newer format": (
        lambda r: _sql(r / STORE, "UPDATE meta SET value = '99' WHERE key = 'version'"),
        "was written in store format 99; this mapapi reads formats up to 2: upgrade mapapi",
    ),
    "an unknown format": (
        lambda r: _sql(r / STORE, "UPDATE meta SET value = 'x' WHERE key = 'version'"),
        "was written in an unknown store format",
    ),
    "a folder in its place": (_folder, "cannot read"),
    "a config that does not parse": (
        lambda r: (r / CONFIG).write_text('name = "unterminated\n'),
        "config.toml is damaged",
    ),
    "a config that is not UTF-8": (
        lambda r: (r / CONFIG).write_bytes(b"name = \xff\xfe\n"),
        "config.toml is damaged",
    ),
}


@pytest.fixture
def filled(points: Mapctl) -> Mapctl:
    """A repository with one committed item."""
    points.insert({"x": 1.0})
    points.commit("one")
    return points


class TestDamagedFiles:
    @pytest.mark.parametrize("case", list(DAMAGE))
    def test_one_line_naming_the_file(self, filled: Mapctl, case: str) -> None:
        damage, text = DAMAGE[case]
        damage(filled.repo)
        outcome = filled.main("ls", "pts")
        assert outcome.code == 1, outcome
        assert len(outcome.err_lines) == 1, outcome.err
        assert text in outcome.err
        assert str(filled.repo / ".mapapi") in outcome.err
        assert "Traceback" not in outcome.err
        assert "internal error" not in outcome.err

    @pytest.mark.parametrize(
        "case", ["truncated", "a newer format", "a config that does not parse"]
    )
    def test_the_console_script_prints_no_traceback(self, filled: Mapctl, case: str) -> None:
        DAMAGE[case][0](filled.repo)
        done = subprocess.run(
            [sys.executable, "-m", "mapctl", "log"],
            cwd=filled.repo,
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert done.returncode == 1
        assert done.stderr.startswith("error: ")
        assert "Traceback" not in done.stderr
        assert DAMAGE[case][1] in done.stderr

    def test_sqlite_failing_later_is_one_line_too(
        self, filled: Mapctl, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        def fail(self: Peer) -> int:
            raise sqlite3.DatabaseError("database disk image is malformed")

        monkeypatch.setattr(Peer, "now", fail)
        outcome = filled.main("status")
        assert outcome.code == 1
        assert outcome.err_lines == [
            "error: the repository's store (.mapapi/store.sqlite) failed: database disk image "
            "is malformed; if this persists, restore it from a backup or clone the repository "
            "again"
        ]


@pytest.fixture
def shared_repo() -> Iterator[Path]:
    """A repository in a folder every user may enter (tmp_path is root's only)."""
    folder = Path(tempfile.mkdtemp(prefix="mapapi-perm-"))
    folder.chmod(0o755)
    try:
        subprocess.run(
            [sys.executable, "-m", "mapctl", "init", str(folder / "repo")], check=True, timeout=60
        )
        yield folder / "repo"
    finally:
        subprocess.run(["rm", "-rf", str(folder)], check=True, timeout=60)


def _as_another_user(repo: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """`mapctl ARGS` in `repo`: as nobody when we are root (root may read anything).

    util-linux's setpriv switches the user (Python's own `user=` cannot run this
    interpreter, which lives under root's home).
    """
    demote = ["setpriv", f"--reuid={NOBODY}", f"--regid={NOBODY}", "--clear-groups"]
    return subprocess.run(
        [*(demote if ROOT else []), sys.executable, "-m", "mapctl", *args],
        cwd=repo,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )


class TestPermissions:
    @pytest.mark.parametrize(
        ("path", "mode", "text"),
        [
            # as root another user tries; otherwise we do, on files we took rights from
            (STORE, 0o600 if ROOT else 0o000, "cannot read"),
            (CONFIG, 0o600 if ROOT else 0o000, "cannot read"),
            (STORE, 0o644 if ROOT else 0o444, "cannot write"),  # SQLite's log needs writing
        ],
    )
    def test_a_file_mapctl_may_not_use(
        self, shared_repo: Path, path: Path, mode: int, text: str
    ) -> None:
        for entry in [shared_repo, shared_repo / ".mapapi", *(shared_repo / ".mapapi").iterdir()]:
            entry.chmod(0o755 if entry.is_dir() else 0o644)
        (shared_repo / path).chmod(mode)
        done = _as_another_user(shared_repo, "log")
        assert done.returncode == 1, done.stderr
        assert done.stderr.startswith(f"error: {text} {shared_repo / path}")
        assert "check" in done.stderr
        assert "permissions" in done.stderr
        assert "Traceback" not in done.stderr
