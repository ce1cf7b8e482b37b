"""`bench fuzz|flood|soak|sim`: how the peer holds up under hostile input,
floods, crashes and simulated faults (measurements, never assertions)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from mapctl.commands.bench_options import DIR_OPTION, measures
from mapctl.session import json_option


@click.command("fuzz")
@click.option(
    "--messages",
    "-n",
    "messages_n",
    default=10_000,
    show_default=True,
    type=click.IntRange(1),
    help="Hostile messages to send.",
)
@click.option("--seed", default=0, show_default=True, help="Seeds the generator (a run replays).")
@DIR_OPTION
@json_option
def bench_fuzz(messages_n: int, seed: int, directory: str | None, as_json: bool) -> None:
    """Send N hostile messages to a real peer and check it survives (DESIGN §11).

    Three peer processes hold chunks with history; generated and mutated
    messages of every body type (valid, with hostile fields, or broken bytes)
    go to one of them as strangers and as a member. Every request must get an
    error reply or a valid reply (or be counted as dropped when its request id
    cannot be read); afterwards the peer must answer a Ping and a commit
    through it, and its store must be intact and changed only by acknowledged
    commits. Fails (exit 1) otherwise.
    """
    from mapbench.fuzz import check_fuzz, run_fuzz

    report = run_fuzz(messages_n, seed, directory)
    measures(f"bench fuzz: {messages_n} messages, seed {seed}", report, as_json)
    check_fuzz(report)


@click.command("flood")
@click.option(
    "--senders", "-n", default=20, show_default=True, type=click.IntRange(1, 200),
    help="Sender processes.",
)  # fmt: skip
@click.option(
    "--megabytes", "-m", default=120, show_default=True, type=click.IntRange(1, 4096),
    help="MB each sender sends.",
)  # fmt: skip
@click.option(
    "--mode", type=click.Choice(["frame", "parts", "both"]), default="both", show_default=True,
    help="One frame per sender (the probe), or parts as a mapapi peer sends a large message.",
)  # fmt: skip
@json_option
def bench_flood(senders: int, megabytes: int, mode: str, as_json: bool) -> None:
    """Flood a real peer process with large messages from N sender processes and
    report the peak of its resident memory and its ping latency (issue 18 §5)."""
    from mapbench.flood import MODES, asdict, run_flood

    modes = MODES if mode == "both" else (mode,)
    for each in modes:
        report = asdict(run_flood(senders, megabytes, each))
        measures(f"bench flood: {senders} x {megabytes} MB, {each}", report, as_json)


@click.command("soak")
@click.option(
    "--minutes",
    default=10.0,
    show_default=True,
    type=click.FloatRange(0.1),
    help="How long the peers commit while the chaos runs.",
)
@click.option(
    "--peers", "-p", default=4, show_default=True, type=click.IntRange(3, 16), help="Processes."
)
@click.option("--seed", default=0, show_default=True, help="Seeds the workload and the chaos.")
@DIR_OPTION
@json_option
def bench_soak(minutes: float, peers: int, seed: int, directory: str | None, as_json: bool) -> None:
    """Peer daemons commit increments and bank transfers while they crash
    (kill -9), stop, stall for seconds (SIGSTOP) and come back at random, half of
    them on a new port; then check that no acknowledged commit was lost, the bank
    total held and every history agrees (issue 7, issue 13).

    Exits 1 if an invariant broke. Progress goes to stderr after each crash,
    stop, pause or restart.
    """
    import asyncio
    import shutil
    import tempfile

    from mapbench.soak import measure_soak
    from mapctl import render

    def progress(tally: dict[str, Any]) -> None:
        render.note(
            f"soak: {tally['increments']} increments, {tally['transfers']} transfers, "
            f"{tally['crashes']} crashes, {tally['stops']} stops, {tally['restarts']} restarts"
        )

    root = Path(tempfile.mkdtemp(prefix="mapapi-soak-", dir=directory))
    try:
        result = asyncio.run(measure_soak(root, peers, minutes * 60, seed, progress))
    except BaseException:
        render.note(f"soak: the peers' repositories and logs are kept in {root}")
        raise
    measures("bench soak", result, as_json)
    if not result["invariants_ok"] or result["errors"]:
        render.note(f"soak: the peers' repositories and logs are kept in {root}")
    else:
        shutil.rmtree(root, ignore_errors=True)
    if not result["invariants_ok"]:
        raise SystemExit(1)


@click.command("sim")
@click.option(
    "--seeds", "-n", default=100, show_default=True, type=click.IntRange(1), help="Seeds to run."
)
@click.option("--first", default=0, show_default=True, type=click.IntRange(0), help="First seed.")
@click.option(
    "--mode",
    type=click.Choice(["core", "commits", "tx", "all"]),
    default="all",
    show_default=True,
    help="The pure Raft core's counter, the commit path on stores, transactions over "
    "two chunks (two-phase commit), or all three.",
)
@json_option
def bench_sim(seeds: int, first: int, mode: str, as_json: bool) -> None:
    """Deterministic simulation of chunks' Raft groups under faults (DESIGN §13):
    seeds FIRST .. FIRST+SEEDS-1, each in one thread with a simulated network and clock.

    Reports violations (each with the command that replays its seed) and what
    the runs did. Exits 1 if any seed broke an invariant.
    """
    from mapbench.sim import run_seeds
    from mapctl import render

    modes = ("core", "commits", "tx") if mode == "all" else (mode,)
    result = run_seeds(first, seeds, modes)
    if as_json:
        render.emit_json(result)
    else:
        flat = {f"{m} {k}": v for m in modes for k, v in result[m].items()}
        rows = {k: v for k, v in result.items() if k not in modes and k != "violations"}
        measures(f"bench sim: seeds {first}..{first + seeds - 1}", {**rows, **flat}, False)
        for bad in result["violations"]:
            render.note(f"{bad['mode']} seed {bad['seed']}: {bad['error']}\n  {bad['replay']}")
    if result["violations"]:
        raise SystemExit(1)


COMMANDS = (bench_fuzz, bench_flood, bench_soak, bench_sim)
"""The commands of this module, which the `bench` group adds."""
