"""A 5-peer swarm split by a network partition, then healed (issues 7 §4 and 13).

Each peer daemon runs in a network namespace of its own (`netns.Lan`), all on
one switch. The chunk's holders are its Raft group: three voters (the founder,
p0, and the next two to join) and two learners. The partition puts p0, the
leader, and a learner on a second bridge: both sides go on talking inside
themselves and cannot reach the other. Then

- the majority side (two of the three voters) elects a new leader and commits;
- a commit on the minority side, at the old leader itself, cannot reach a
  majority of the voters: it fails with a clear, retriable error (exit 5) naming
  the voters it misses, and changes nothing (no split brain);
- once healed, the minority peers catch up from the new leader, and every peer
  ends with the same history: no acknowledged commit is lost and none is
  applied twice.

Skipped where the kernel or the user cannot make network namespaces.
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from mapapi.testing import wait_until

from .conftest import (
    COMMAND_TIMEOUT,
    MAPCTL,
    Daemons,
    holders_of,
    mapctl,
    mapctl_json,
    run_mapctl,
)
from .netns import Lan

# Five daemons, a split, commits on both sides and a heal: 63-77 s on 2 cores beside another
# test, near the default 120 s cap, which only guards against a hang.
pytestmark = [pytest.mark.slow, pytest.mark.timeout(240)]

PEERS, MINORITY = 5, (0, 4)
PORT = 7000
EXIT_NETWORK = 5
HEAL_TIMEOUT = 60.0


@pytest.fixture
def lan() -> Iterator[Lan]:
    why = Lan.available()
    if why is not None:
        pytest.skip(why)
    network = Lan(PEERS)
    try:
        yield network
    finally:
        network.close()


def start(lan: Lan, daemons: Daemons, host: int, join: str | None) -> Path:
    """A repository whose daemon listens inside `host`'s namespace."""
    repo = daemons.root / f"p{host}"
    subprocess.run([MAPCTL, "init", str(repo), "--name", f"p{host}"], check=True, timeout=30)
    daemons.adopt(repo)
    argv = [MAPCTL, "-C", str(repo), "peer", "start", "--detach", "--json"]
    argv += ["--listen", lan.address(host, PORT), *(["--join", join] if join else [])]
    done = subprocess.run(
        lan.command(host, *argv), capture_output=True, text=True, timeout=COMMAND_TIMEOUT
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["address"] == lan.address(host, PORT)
    return repo


def value(repo: Path, item: str) -> int:
    return int(mapctl_json(repo, "get", "counters", item).get("value", 0))


def history(repo: Path) -> list[str]:
    return [c["commit"] for c in mapctl_json(repo, "log")]


def settle(predicate: Callable[[], bool], repos: list[Path]) -> None:
    """`wait_until(predicate)` after the heal, failing with the peers' log tails."""
    try:
        wait_until(predicate, timeout=HEAL_TIMEOUT)
    except AssertionError as exc:
        tails = {r.name: r.joinpath(".mapapi", "peer.log").read_text()[-3000:] for r in repos}
        raise AssertionError(f"{exc}; peer logs: {json.dumps(tails, indent=1)}") from None


def increment(repo: Path, item: str) -> None:
    """Add 1 to the counter through `repo`'s daemon, retrying while the chunk's
    group elects a leader (exit 5)."""
    mapctl(repo, "set", "counters", item, json.dumps({"name": "c", "value": value(repo, item) + 1}))
    while run_mapctl(repo, "commit", "-m", "+1", ok=(0, EXIT_NETWORK)).returncode:
        pass


def test_a_split_swarm_heals_with_nothing_lost(lan: Lan, daemons: Daemons) -> None:
    repos = [start(lan, daemons, 0, None)]
    repos += [start(lan, daemons, i, lan.address(0, PORT)) for i in range(1, PEERS)]
    mapctl(repos[0], "table", "create", "counters", "--type", "mapapi.v1.Counter")
    chunk = mapctl(repos[0], "chunk", "create", "counters").strip()
    item = mapctl_json(repos[0], "set", "counters", '{"name": "c", "value": 0}')["id"]
    mapctl(repos[0], "commit", "-m", "c = 0")
    for repo in repos[1:]:
        mapctl(repo, "chunk", "participate", chunk)

    lan.split(MINORITY)
    majority = [r for i, r in enumerate(repos) if i not in MINORITY]
    minority = [repos[i] for i in MINORITY]
    before = history(minority[0])
    for turn in range(3):
        increment(majority[turn % len(majority)], item)
    assert len(holders_of(majority[0], chunk)) == PEERS  # members until removed (30 s)

    # the minority cannot commit: a clear, retriable error, and nothing changes
    mapctl(minority[0], "set", "counters", item, '{"name": "c", "value": 100}')
    failed = run_mapctl(minority[0], "commit", "-m", "cut off", ok=(EXIT_NETWORK,))
    assert "no quorum for chunk" in failed.stderr, failed.stderr
    mapctl(minority[0], "view", "abort")
    assert history(minority[0]) == before

    lan.heal()
    agreed = history(majority[0])
    settle(lambda: all(history(r) == agreed for r in repos), repos)
    assert len(agreed) == len(before) + 3
    assert [value(r, item) for r in repos] == [3] * PEERS

    increment(minority[1], item)  # a peer that was cut off commits for everyone again
    settle(lambda: len({tuple(history(r)) for r in repos}) == 1, repos)
    assert [value(r, item) for r in repos] == [4] * PEERS
