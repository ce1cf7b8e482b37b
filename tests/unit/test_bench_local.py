"""`run_local` returns every figure `mapctl bench local` promises (no speed thresholds)."""

import json
import math
import subprocess
import sys

import pytest

from mapbench.local import run_local

RATES = (
    "commits_per_s_1_item",
    "commits_per_s_1_item_update",
    "commits_per_s_100_items",
    "items_per_s_100_items",
    "commits_per_s_100_items_update",
    "items_per_s_100_items_update",
    "reads_per_s_past",
)
STARTUP = ("startup_help_s", "startup_get_s")


@pytest.mark.slow
def test_run_local_reports_positive_figures(tmp_path) -> None:
    result = run_local(3, tmp_path)

    for key in (*RATES, *STARTUP):
        assert isinstance(result[key], float), key
        assert result[key] > 0, key
        assert math.isfinite(result[key]), key
    assert result["commits"] == 3
    assert result["reads"] == 30
    assert result["python"]
    assert result["machine"]
    json.dumps(result)  # the --json output must serialise as is
    assert list(tmp_path.iterdir()) == []  # the scratch repository is gone


def test_run_local_refuses_zero_commits() -> None:
    with pytest.raises(ValueError, match="at least 1"):
        run_local(0)


@pytest.mark.slow
def test_help_loads_no_library_protobuf_rich_or_asyncio() -> None:
    """`mapctl --help` stays fast because commands import their dependencies lazily."""
    probe = (
        "import sys\n"
        "sys.argv = ['mapctl', '--help']\n"
        "from mapctl.cli import main\n"
        "try:\n"
        "    main()\n"
        "except SystemExit:\n"
        "    pass\n"
        "print(' '.join(sorted(sys.modules)), file=sys.stderr)\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    loaded = done.stderr.split()
    heavy = ("mapapi", "google.protobuf", "rich", "asyncio", "zmq")
    assert [m for m in loaded if m.split(".")[0] in heavy or m.startswith(heavy)] == []
    assert "Usage: mapctl" in done.stdout
