"""Paper Algorithm 1 against central servers, beside `mapctl bench viewtest`
(DESIGN §12): `scripts/kv-compare.sh` runs this module.

    python -m mapbench.kv_compare [-n N] [--procs 1,2,4] [--only redis,etcd,viewtest]

For each system and each P, P client processes each make N increments of one
counter, optimistically, beginning again after an abort, all started at once:
Redis (WATCH/MULTI/EXEC), a 3-member etcd cluster (txn comparing the key's
mod_revision), both on 127.0.0.1 (`mapbench.central`), then the swarm
(`mapbench.swarm.viewtest`: P peer processes, the counter's chunk held by all).
Afterwards the counter must read P*N. Prints one table: commits/s, aborts per
commit, p50 and p99 of one increment (first attempt to success) in ms, on
stdout; each row as a JSON line on stderr as soon as it is measured.

Each server is started in a scratch folder before its runs and stopped after
them, so none runs beside another system's; nothing is left running.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import multiprocessing
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from multiprocessing.synchronize import Barrier
from pathlib import Path
from typing import Any, Protocol

from mapbench.central import EtcdClient, RedisClient, ServerFailed, etcd_cluster, redis_server
from mapbench.swarm import check_viewtest, percentile, viewtest

SYSTEMS = ("redis", "etcd", "viewtest")
START_TIMEOUT = 30.0
RUN_TIMEOUT = 600.0


class Client(Protocol):
    """What Algorithm 1 needs of a central server's client."""

    def increment(self) -> bool: ...

    def value(self) -> int: ...

    def reset(self) -> None: ...

    def close(self) -> None: ...


Connect = Callable[[int], Client]
CLIENTS: dict[str, tuple[Connect, Callable[[Path], contextlib.AbstractContextManager[list[int]]]]]
CLIENTS = {"redis": (RedisClient, redis_server), "etcd": (EtcdClient, etcd_cluster)}


def _client_process(connect: Connect, port: int, n: int, barrier: Barrier, results: Any) -> None:
    """One client of Algorithm 1: `n` increments, each retried until it commits."""
    client = connect(port)
    latencies, aborts = [], 0
    try:
        barrier.wait(START_TIMEOUT)
        started = time.monotonic()
        for _ in range(n):
            first = time.monotonic()
            while not client.increment():
                aborts += 1
            latencies.append((time.monotonic() - first) * 1e3)
        results.put({"ms": latencies, "aborts": aborts, "start": started, "end": time.monotonic()})
    finally:
        client.close()


def algorithm1(system: str, ports: list[int], procs: int, n: int) -> dict[str, Any]:
    """Algorithm 1 with `procs` client processes (client i talks to ports[i % len]).

    Raises:
        ServerFailed: a client failed, or the counter does not read procs * n.
    """
    connect, _ = CLIENTS[system]
    admin = connect(ports[0])
    admin.reset()
    context = multiprocessing.get_context("fork")
    barrier, results = context.Barrier(procs), context.Queue()
    workers = [
        context.Process(
            target=_client_process, args=(connect, ports[i % len(ports)], n, barrier, results)
        )
        for i in range(procs)
    ]
    for worker in workers:
        worker.start()
    try:
        reports = [results.get(timeout=RUN_TIMEOUT) for _ in workers]
    except Exception as exc:
        raise ServerFailed(f"a {system} client did not report: {exc!r}") from exc
    finally:
        for worker in workers:
            worker.join(START_TIMEOUT)
            if worker.is_alive():
                worker.kill()
                worker.join()
    final = admin.value()
    admin.close()
    if final != procs * n:
        raise ServerFailed(f"{system}: the counter reads {final}, expected {procs * n}")
    seconds = max(r["end"] for r in reports) - min(r["start"] for r in reports)
    return _row(system, procs, n, [x for r in reports for x in r["ms"]], reports, seconds)


def _row(
    system: str,
    procs: int,
    n: int,
    latencies: list[float],
    reports: list[dict[str, Any]],
    seconds: float,
) -> dict[str, Any]:
    return {
        "system": system,
        "procs": procs,
        "n": n,
        "commits_per_s": round(procs * n / seconds, 1),
        "aborts_per_commit": round(sum(r["aborts"] for r in reports) / (procs * n), 3),
        "p50_ms": round(percentile(latencies, 0.5), 3),
        "p99_ms": round(percentile(latencies, 0.99), 3),
    }


def swarm_rows(procs: list[int], n: int) -> Iterator[dict[str, Any]]:
    """`bench viewtest --peers P -n N` for each P (checked: every peer reads P*N)."""
    for p in procs:
        result = viewtest(p, n)
        check_viewtest(result)
        keys = ("commits_per_s", "aborts_per_commit", "p50_ms", "p99_ms")
        yield {"system": "mapapi viewtest", "procs": p, "n": n, **{k: result[k] for k in keys}}


def rows(systems: list[str], procs: list[int], n: int) -> Iterator[dict[str, Any]]:
    """Every measurement, one system after the other, each server stopped after its runs."""
    for system in systems:
        if system == "viewtest":
            yield from swarm_rows(procs, n)
            continue
        _, serve = CLIENTS[system]
        with tempfile.TemporaryDirectory(prefix=f"kv-{system}-") as tmp, serve(Path(tmp)) as ports:
            for p in procs:
                yield algorithm1(system, ports, p, n)


def table(found: list[dict[str, Any]]) -> str:
    """The rows as a Markdown table."""
    lines = [
        "| system | P | commits/s | aborts / commit | p50 ms | p99 ms |",
        "|---|---|---|---|---|---|",
    ]
    for r in found:
        lines.append(
            f"| {r['system']} | {r['procs']} | {r['commits_per_s']:,.0f} | "
            f"{r['aborts_per_commit']:.2f} | {r['p50_ms']:.2f} | {r['p99_ms']:.1f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Command line: see the module docstring."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=300, help="increments per process")
    parser.add_argument("--procs", default="1,2,4", help="client counts, comma-separated")
    parser.add_argument("--only", default=",".join(SYSTEMS), help="systems, comma-separated")
    args = parser.parse_args(argv)
    systems = [s for s in args.only.split(",") if s]
    unknown = set(systems) - set(SYSTEMS)
    if unknown:
        parser.error(f"unknown systems {sorted(unknown)}; choose from {', '.join(SYSTEMS)}")
    procs = [int(p) for p in args.procs.split(",")]
    load = os.getloadavg()[0]
    found = []
    for row in rows(systems, procs, args.n):
        found.append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
    print(f"load average before: {load:.2f}; after: {os.getloadavg()[0]:.2f}; n = {args.n}")
    print(table(found))


if __name__ == "__main__":
    main()
