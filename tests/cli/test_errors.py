"""The error boundary in `mapctl.cli.main`: exit codes, one-line messages, `-v`.

Most cases run `main()` in-process; two run the real console entry point
(`python -m mapctl`) in a subprocess to prove the same holds end to end.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from mapapi import NetworkError, Peer, Repository
from mapapi.core.errors import ADVICE_VERBS
from mapapi.core.ids import ChunkId
from mapapi.net.codec import error_from_reply, error_reply
from tests.cli.conftest import STRUCT, InProcessDaemon, Mapctl, run_main


def _console(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """`mapctl ARGS` as the console script runs it."""
    return subprocess.run(
        [sys.executable, "-m", "mapctl", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )


class TestConsoleScript:
    def test_not_a_repo_exits_4_with_a_hint(self, tmp_path: Path) -> None:
        done = _console("status", cwd=tmp_path)
        assert done.returncode == 4
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1, done.stderr
        assert lines[0].startswith("error: not a map repository")
        assert "mapctl init" in lines[0]
        assert "Traceback" not in done.stderr
        assert done.stdout == ""

    def test_verbose_prints_the_traceback(self, tmp_path: Path) -> None:
        done = _console("-v", "status", cwd=tmp_path)
        assert done.returncode == 4
        assert "Traceback (most recent call last)" in done.stderr
        assert "NotARepoError" in done.stderr
        assert done.stderr.strip().splitlines()[-1].startswith("error: not a map repository")


class TestExitCodes:
    def test_not_a_repo(self, tmp_path: Path) -> None:
        for args in (["status"], ["log", "--json"], ["table", "list"]):
            outcome = run_main(["-C", str(tmp_path), *args])
            assert outcome.code == 4
            assert len(outcome.err_lines) == 1
            assert "run `mapctl init` first" in outcome.err

    def test_verbose_in_process(self, tmp_path: Path) -> None:
        outcome = run_main(["-C", str(tmp_path), "--verbose", "status"])
        assert outcome.code == 4
        assert "Traceback" in outcome.err

    def test_click_usage_errors_exit_2(self, mapctl: Mapctl) -> None:
        for args in (["get", "pts"], ["no-such-command"], ["commit", "--bogus"]):
            outcome = mapctl.main(*args)
            assert outcome.code == 2, args
            assert "Error:" in outcome.err

    def test_library_usage_errors_exit_2_in_one_line(self, points: Mapctl) -> None:
        outcome = points.main("table", "create", "t", "--type", "no.Such")
        assert outcome.code == 2
        assert len(outcome.err_lines) == 1
        assert outcome.err_lines[0].startswith("error: 'no.Such' is not a table type")

    def test_set_with_zero_or_two_chunks_names_the_fix(self, points: Mapctl) -> None:
        points("table", "create", "bare", "--type", "google.protobuf.Struct")
        outcome = points.main("set", "bare", "{}")
        assert (outcome.code, len(outcome.err_lines)) == (2, 1)
        assert "run `mapctl chunk create bare`" in outcome.err
        points("chunk", "create", "pts")
        outcome = points.main("set", "pts", "{}")
        assert (outcome.code, len(outcome.err_lines)) == (2, 1)
        assert "pass --chunk ID" in outcome.err

    def test_not_found_exits_1_with_a_hint(self, points: Mapctl) -> None:
        outcome = points.main("get", "pts", "0" * 32)
        assert outcome.code == 1
        assert outcome.err_lines == [
            f"error: no item {'0' * 32} in table 'pts' at time 0; `mapctl ls pts` lists the items"
        ]

    def test_nothing_to_commit_exits_2(self, points: Mapctl) -> None:
        outcome = points.main("commit")
        assert outcome.code == 2
        assert "stage changes with `set`" in outcome.err

    def test_empty_open_view_commits_nothing(self, points: Mapctl) -> None:
        points("view", "open")
        assert points.json("commit") == {"commit": None}
        assert points.json("view", "list") == {"views": []}
        assert points.json("log") == []

    def test_init_twice_names_the_way_out(self, repo: Path) -> None:
        outcome = run_main(["init", str(repo)])
        assert outcome.code == 1
        assert outcome.err_lines == [
            f"error: {repo.resolve()} is already a map repository; "
            "use it as is, or init another folder"
        ]

    def test_corrupt_store_exits_1_in_one_line(self, mapctl: Mapctl) -> None:
        (mapctl.repo / ".mapapi" / "store.sqlite").write_bytes(b"not sqlite at all" * 100)
        outcome = mapctl.main("status")
        assert outcome.code == 1
        assert len(outcome.err_lines) == 1
        assert "is not a mapapi store" in outcome.err

    @pytest.mark.parametrize(
        ("raised", "code", "text"),
        [
            (NetworkError("peer 1.2.3.4 did not answer; check `mapctl peer status`"), 5, "error:"),
            (KeyboardInterrupt(), 130, "aborted"),  # click turns ^C into Abort
            (RuntimeError("boom"), 1, "rerun with -v"),
        ],
    )
    def test_exception_classes_pick_the_exit_code(
        self,
        points: Mapctl,
        monkeypatch: pytest.MonkeyPatch,
        raised: BaseException,
        code: int,
        text: str,
    ) -> None:
        def fail(self: Peer) -> int:
            raise raised

        monkeypatch.setattr(Peer, "now", fail)
        outcome = points.main("status")
        assert outcome.code == code
        assert len(outcome.err_lines) == 1
        assert text in outcome.err
        assert "Traceback" not in outcome.err

    def test_help_and_version_exit_0(self, mapctl: Mapctl) -> None:
        assert mapctl.main("--help").code == 0
        outcome = run_main(["--version"])
        assert outcome.code == 0
        assert "version" in outcome.out


def _network_errors() -> list[type[NetworkError]]:
    """NetworkError and every subclass, however deep."""
    found: list[type[NetworkError]] = [NetworkError]
    for cls in found:
        found.extend(cls.__subclasses__())
    return found


class TestNetworkAdvice:
    """Every network error says whether to retry now, wait or act (issue 15)."""

    @pytest.mark.parametrize("cls", _network_errors(), ids=lambda c: c.__name__)
    def test_every_network_error_ends_with_advice(self, cls: type[NetworkError]) -> None:
        assert cls.advice.startswith(ADVICE_VERBS), cls.advice
        assert str(cls("it failed")) == f"it failed; {cls.advice}"

    @pytest.mark.parametrize("cls", _network_errors(), ids=lambda c: c.__name__)
    def test_advice_survives_an_error_reply_once(self, cls: type[NetworkError]) -> None:
        sent = cls("it failed", advice="act: run `mapctl fix`")
        received = error_from_reply(error_reply(sent))
        assert type(received) is cls
        assert str(received) == "it failed; act: run `mapctl fix`"

    async def test_crashed_voters_are_named_with_what_to_do(
        self, daemon: InProcessDaemon, tmp_path: Path
    ) -> None:
        assert daemon.record is not None
        await daemon.json("table", "create", "pts", "--type", STRUCT)
        chunk = (await daemon.json("chunk", "create", "pts"))["id"]
        others = [Peer.of(Repository.init(tmp_path / n, n)) for n in ("robot2", "robot3")]
        try:
            for other in others:  # three holders: three voters
                await other.start()
                await other.join(daemon.record.join)
                await other.participate(ChunkId(chunk))
            for other in others:
                await _crash(other)
            assert (await daemon("set", "pts", '{"x": 1}')).code == 0
            failed = await daemon("commit", "-m", "while robot2 and robot3 are down")
        finally:
            for other in others:
                await other.close()
        assert failed.code == 5, failed
        assert "no quorum for chunk" in failed.err, failed.err
        assert "robot2 (" in failed.err, failed.err
        assert "robot3 (" in failed.err, failed.err
        assert "act: bring the voters named back" in failed.err, failed.err


async def _crash(peer: Peer) -> None:
    """Close the peer's network side with no goodbye, as after `kill -9`."""
    swarm = peer.swarm
    assert swarm is not None
    peer.swarm = None
    await swarm.close()
