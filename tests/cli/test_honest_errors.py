"""Errors that say what happened and what to do, and lose nothing (issue 18, part 6).

The probe found advice that causes loss: a full disk read as a store to
restore from a backup, `peer start` pointing at an empty log, `init` over a
store whose config was lost making a new peer id, and a corrupt payload
reported as a usage error without its file. Every case here runs on real
files; the full disk is a small tmpfs mounted for the test (root only).
"""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from mapapi.core.ids import PeerId
from mapapi.service.repo import CONFIG, REPO_DIR, STORE
from mapapi.store.sqlite import SqliteStore
from tests.cli.conftest import STRUCT, Mapctl, run_main


def _one_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "internal error" not in lines[0]
    assert "Traceback" not in err
    return lines[0]


def _store(repo: Path) -> Path:
    return repo / REPO_DIR / STORE


class TestCorruptPayload:
    def test_reading_it_exits_1_naming_the_file_and_the_item(self, points: Mapctl) -> None:
        item = points.insert({"x": 1})
        commit = points.commit("one")["commit"]
        with sqlite3.connect(_store(points.repo)) as con:
            key = bytes.fromhex(item)  # the store keys an item by its 16 bytes
            (data,) = con.execute("SELECT data FROM revisions WHERE item_id = ?", (key,)).fetchone()
            flipped = b"\xff" + bytes(data)[1:]  # field 31, wire type 7: no protobuf parses it
            con.execute("UPDATE revisions SET data = ? WHERE item_id = ?", (flipped, key))
        for args in (("ls", "pts"), ("get", "pts", item), ("show", commit), ("log", "pts", item)):
            done = points.main(*args)
            assert done.code == 1, (args, done)
            line = _one_line(done.err)
            assert str(_store(points.repo)) in line, line
            assert item in line
            assert "backup" in line


def _lose_config(repo: Path) -> None:
    (repo / REPO_DIR / CONFIG).unlink()


class TestInitOverAStoreWithoutConfig:
    def test_init_refuses_and_recover_finds_the_old_id(self, points: Mapctl) -> None:
        for n in range(3):
            points.insert({"n": n})
            points.commit(f"c{n}")
        old = (points.repo / REPO_DIR / CONFIG).read_text()
        log = points.json("log")
        _lose_config(points.repo)

        done = run_main(["init", str(points.repo)])
        assert done.code == 2
        line = _one_line(done.err)
        assert "3 commit(s)" in line, line
        assert "mapctl init --recover" in line
        assert not (points.repo / REPO_DIR / CONFIG).exists()  # nothing was made

        done = run_main(["init", str(points.repo), "--recover"])
        assert done.code == 0, done
        assert (points.repo / REPO_DIR / CONFIG).read_text() == old  # same id, name, grid
        assert "the one holder of all 1 chunk(s)" in done.out
        assert points.json("log") == log
        points.insert({"n": 3})
        points.commit("after")  # its own chunk, written as before

    def test_when_several_peers_hold_every_chunk_it_says_it_cannot_tell(
        self, points: Mapctl
    ) -> None:
        points.insert({"n": 0})
        points.commit("c")
        own = PeerId((points.repo / REPO_DIR / CONFIG).read_text().split('"')[3])
        other = PeerId.new()
        store = SqliteStore(_store(points.repo))
        try:
            (chunk,) = store.chunks()
            store.set_holders(chunk.id, [own, other])
        finally:
            store.close()
        _lose_config(points.repo)
        done = run_main(["init", str(points.repo), "--recover"])
        assert done.code == 2
        line = _one_line(done.err)
        assert "cannot recover the peer id" in line, line
        assert own in line
        assert other in line
        assert "--peer-id" in line
        assert run_main(["init", str(points.repo), "--recover", "--peer-id", other]).code == 0
        assert other in (points.repo / REPO_DIR / CONFIG).read_text()

    def test_an_empty_store_is_taken_over(self, mapctl: Mapctl) -> None:
        # What an `init` stopped between the store and the config leaves.
        _lose_config(mapctl.repo)
        done = run_main(["init", str(mapctl.repo)])
        assert done.code == 0, done
        assert "Initialised empty map repository" in done.out


# -- a full disk ---------------------------------------------------------------------------
DISK_BYTES = 4 * 1024 * 1024


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A tmpfs of `DISK_BYTES` mounted on a folder of `tmp_path` (root only)."""
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs to fill needs root")
    mount = tmp_path / "disk"
    mount.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={DISK_BYTES}", "tmpfs", str(mount)],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        pytest.skip(f"mounting a tmpfs is not permitted here: {done.stderr.strip()}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=True)


def _fill(disk: Path, leave: int = 0) -> Path:
    """Fill `disk` with one file until `leave` bytes (rounded to 4 KiB) are free."""
    filler = disk / "filler"
    with filler.open("wb") as f:
        while True:
            st = os.statvfs(disk)
            free = st.f_bavail * st.f_frsize
            if free <= leave:
                break
            try:
                f.write(b"\0" * min(free - leave, 1 << 20))
                f.flush()
            except OSError:
                break
    return filler


def _full_disk_repo(disk: Path) -> Mapctl:
    repo = disk / "repo"
    assert run_main(["init", str(repo), "--name", "full"]).code == 0
    mapctl = Mapctl(repo)
    mapctl("table", "create", "pts", "--type", STRUCT)
    mapctl("chunk", "create", "pts")
    for n in range(3):
        mapctl.insert({"n": n})
        mapctl.commit(f"c{n}")
    return mapctl


class TestFullDisk:
    def test_every_command_says_no_space_and_nothing_is_lost(self, small_disk: Path) -> None:
        mapctl = _full_disk_repo(small_disk)
        log = mapctl.json("log")
        filler = _fill(small_disk)
        for args in (("log",), ("ls", "pts"), ("set", "pts", '{"n": 9}'), ("status",)):
            done = mapctl.main(*args)
            assert done.code == 1, (args, done)
            line = _one_line(done.err)
            assert f"no space left on the disk of {small_disk / 'repo' / REPO_DIR}" in line, line
            assert "backup" not in line
            assert "not a mapapi store" not in line
        filler.unlink()
        assert mapctl.json("log") == log
        assert len(mapctl.json("ls", "pts")["items"]) == 3

    def test_a_commit_that_does_not_fit_is_refused_whole(self, small_disk: Path) -> None:
        mapctl = _full_disk_repo(small_disk)
        log = mapctl.json("log")
        mapctl.insert({"big": "x" * 600_000})
        filler = _fill(small_disk, leave=256 * 1024)
        done = mapctl.main("commit", "-m", "too big")
        assert done.code == 1, done
        assert "no space left on the disk of" in _one_line(done.err)
        filler.unlink()
        assert mapctl.json("log") == log  # the failed commit is not half there
        assert mapctl.json("commit", "-m", "now")["commit"]  # the staged change was kept

    def test_peer_start_reports_the_childs_error(self, small_disk: Path) -> None:
        mapctl = _full_disk_repo(small_disk)
        _fill(small_disk)
        done = subprocess.run(
            [sys.executable, "-m", "mapctl", "-C", str(mapctl.repo), "peer", "start", "--detach"],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert done.returncode != 0, done
        line = _one_line(done.stderr)
        assert "the peer exited" in line, line
        assert "no space left on the disk of" in line
        assert "peer.log could not be written: No space left on device" in line
