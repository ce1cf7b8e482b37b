"""Report what the property tests measured (e.g. how many hostile messages the wire
fuzz tried) at the end of the run: tests record it with `record_property`."""

from __future__ import annotations

import pytest

REPORTED = ("fuzz_messages", "fuzz_error_replies", "fuzz_valid_replies", "fuzz_dropped")


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    """One line per test that recorded a fuzz figure."""
    for report in terminalreporter.stats.get("passed", []) + terminalreporter.stats.get(
        "failed", []
    ):
        if report.when != "call":
            continue
        figures = {k: v for k, v in report.user_properties if k in REPORTED}
        if figures:
            shown = ", ".join(f"{k.removeprefix('fuzz_')}={v}" for k, v in figures.items())
            terminalreporter.write_line(f"{report.nodeid}: {shown}")
