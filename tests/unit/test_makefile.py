"""The Makefile's promises (issue 15): `make demo` installs only the demo's set,
`make test` the full one and runs the whole suite (what CI runs), `make check`
the quick folders; a venv made by `make demo` is completed by `make test`."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MAKEFILE = (ROOT / "Makefile").read_text(encoding="utf-8")
SLOW_FOLDERS = {"multiproc", "swarm", "net"}  # processes, swarms and sockets: minutes, not seconds


def variable(name: str) -> str:
    """The value of `NAME := value`."""
    match = re.search(rf"^{name}\s*:?=\s*(.*)$", MAKEFILE, re.MULTILINE)
    assert match, f"{name} is not set in the Makefile"
    return match.group(1).strip()


def rule(target: str) -> tuple[str, list[str]]:
    """A rule's prerequisites and its recipe lines (without the leading tab and `@`)."""
    match = re.search(rf"^{re.escape(target)}:(.*)\n((?:\t.*\n)*)", MAKEFILE, re.MULTILINE)
    assert match, f"no rule for {target}"
    recipe = [line.lstrip("\t").lstrip("@") for line in match.group(2).splitlines()]
    return match.group(1).strip(), recipe


def install(target: str) -> tuple[str, list[str]]:
    """The install stamp `target` depends on first, and that stamp's recipe."""
    stamp = rule(target)[0].split()[0]
    return stamp, rule(stamp)[1]


def pip_line(recipe: list[str]) -> str:
    """The one `pip install` line of a recipe."""
    (line,) = [line for line in recipe if "pip install" in line]
    return line


class TestCheck:
    def test_check_runs_the_quick_folders_and_they_exist(self) -> None:
        folders = variable("CHECK_TESTS").split()
        assert folders == ["tests/unit", "tests/property", "tests/cli", "tests/sim"]
        assert all((ROOT / f).is_dir() for f in folders)
        assert not {Path(f).name for f in folders} & SLOW_FOLDERS
        _, recipe = rule("check")
        # the tests that start peer processes stay in `make test` only
        assert any('pytest $(CHECK_TESTS) -m "not slow"' in line for line in recipe)

    def test_every_test_folder_is_in_check_or_known_to_be_slow(self) -> None:
        quick = {Path(f).name for f in variable("CHECK_TESTS").split()}
        folders = {p.name for p in (ROOT / "tests").iterdir() if any(p.glob("test_*.py"))}
        assert folders <= quick | SLOW_FOLDERS, "a new test folder: put it in check or SLOW"

    def test_test_runs_the_whole_suite_which_ci_runs(self) -> None:
        _, recipe = rule("test")
        together, alone = [line for line in recipe if "pytest" in line]
        for line in (together, alone):
            assert "tests/" not in line  # no folder: pyproject's testpaths, all of them
        # every test runs in one of the two: the timing tests by themselves, after the rest
        assert '-m "not alone"' in together
        assert "-n 2" in together
        assert "-m alone" in alone
        assert "-n " not in alone
        assert "make test" in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


class TestInstallSets:
    def test_demo_installs_the_plot_and_registration_extras_only(self) -> None:
        stamp, recipe = install("demo")
        assert stamp == "$(DEMO_STAMP)"
        assert "'.[plot,registration]'" in pip_line(recipe)  # PNGs, and gtsam for `align`
        assert not any("ensure-syslibs" in line for line in recipe)  # no apt-get for the demo

    def test_test_installs_everything_and_marks_the_demo_set_done(self) -> None:
        stamp, recipe = install("test")
        assert stamp == "$(TEST_STAMP)"
        assert "'.[dev,plot,pointcloud,registration,rosbag]'" in pip_line(recipe)
        assert any("ensure-syslibs" in line for line in recipe)
        assert any(line.startswith("touch") and "$(DEMO_STAMP)" in line for line in recipe)

    def test_test_and_demo_run_on_compiled_modules(self) -> None:
        # where PYTHONDONTWRITEBYTECODE is set, no process would write them itself
        for target in ("test", "demo"):
            assert "bytecode" in rule(target)[0].split()
        _, recipe = rule("bytecode")
        assert any("-m compileall" in line and "mapapi mapctl" in line for line in recipe)

    def test_each_install_step_says_what_it_installs(self) -> None:
        for stamp in ("$(PY)", "$(DEMO_STAMP)", "$(TEST_STAMP)"):
            _, recipe = rule(stamp)
            assert recipe[0].startswith('echo "==> '), f"{stamp} does not say what it does"
