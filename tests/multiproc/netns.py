"""Test hosts in network namespaces this test creates itself, for partitions.

`Lan(n)` makes n host namespaces, each with one veth link (10.213.0.i/24) into
a switch namespace that holds two bridges. Every host starts on bridge A;
`split(hosts)` moves those hosts' ports to bridge B, so the two groups cannot
reach each other while each group still talks inside itself, and `heal()` moves
them back. Everything is removed by `close()`. Needs root and `ip` (iproute2);
`Lan.available()` says whether this kernel and user allow it.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import uuid
from collections.abc import Sequence

SUBNET = "10.213.0"


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, timeout=10)


class Lan:
    """n hosts on a switch that can be split in two (see the module docstring)."""

    def __init__(self, n: int) -> None:
        self.tag = uuid.uuid4().hex[:6]
        self.switch = f"mapi-{self.tag}-sw"
        self.hosts = [f"mapi-{self.tag}-h{i}" for i in range(n)]
        self._made: list[str] = []
        try:
            self._build()
        except BaseException:
            self.close()
            raise

    @staticmethod
    def available() -> str | None:
        """None if namespaces can be made here, else why not."""
        if os.geteuid() != 0:
            return "network namespaces need root"
        if shutil.which("ip") is None:
            return "no `ip` command (iproute2)"
        probe = f"mapi-probe-{uuid.uuid4().hex[:6]}"
        try:
            _ip("netns", "add", probe)
        except (subprocess.CalledProcessError, OSError) as exc:
            return f"this kernel or container forbids `ip netns add`: {exc}"
        _ip("netns", "del", probe)
        return None

    def address(self, host: int, port: int) -> str:
        """A zmq endpoint on `host`."""
        return f"tcp://{SUBNET}.{host + 1}:{port}"

    def command(self, host: int, *argv: str) -> list[str]:
        """`argv` run inside `host`'s namespace."""
        return ["ip", "netns", "exec", self.hosts[host], *argv]

    def _build(self) -> None:
        _ip("netns", "add", self.switch)
        self._made.append(self.switch)
        for bridge in ("bra", "brb"):
            _ip("-n", self.switch, "link", "add", bridge, "type", "bridge")
            _ip("-n", self.switch, "link", "set", bridge, "up")
        for i, host in enumerate(self.hosts):
            _ip("netns", "add", host)
            self._made.append(host)
            inside, port = f"mh{self.tag}{i}", f"ms{self.tag}{i}"
            _ip("link", "add", inside, "type", "veth", "peer", "name", port)
            _ip("link", "set", inside, "netns", host)
            _ip("link", "set", port, "netns", self.switch)
            _ip("-n", host, "addr", "add", f"{SUBNET}.{i + 1}/24", "dev", inside)
            _ip("-n", host, "link", "set", inside, "up")
            _ip("-n", host, "link", "set", "lo", "up")
            _ip("-n", self.switch, "link", "set", port, "master", "bra", "up")

    def split(self, hosts: Sequence[int]) -> None:
        """Cut `hosts` off from the others (they still reach each other)."""
        for i in hosts:
            _ip("-n", self.switch, "link", "set", f"ms{self.tag}{i}", "master", "brb")

    def heal(self) -> None:
        """Put every host on one bridge again."""
        for i in range(len(self.hosts)):
            _ip("-n", self.switch, "link", "set", f"ms{self.tag}{i}", "master", "bra")

    def close(self) -> None:
        """Delete every namespace (and with them the links). Idempotent."""
        for name in reversed(self._made):
            subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=10)
        self._made.clear()
