"""The steps of `mapctl demo` (issue 5 §5): a swarm of peer processes builds
the tunnels map together, finds and loads it by region, and settles a conflict.

1. start: 3 or 4 peer daemons in a temporary folder; each joins the first.
2. import: each peer imports a few robots' missions of the Kimera-Multi
   tunnels set (`sample_maps/`), all peers at once.
3. query: the last peer asks the spatial index for the box around the spot
   where every robot's trajectory starts and loads what lies in it: each
   mission's row and its spatial tiles in the box, with their edges
   (`load_bbox`, what `query-bbox --load` runs).
4. conflict: the first and the last peer edit the same vertex in views begun
   before either commits; the first commits, the last one's commit conflicts,
   it resolves with the mean of both edits and commits again; both peers read
   the vertex back.
5. align: every peer watches the `frames` table (`mapctl watch`); the last
   peer, which holds every mission now, places them in one world frame from
   their inter-robot edges (`mapctl align`: gtsam) and commits each one's
   place; every peer's watch then receives the eight places (a place lies at
   its mission's box in the world frame, where the watches listen).
6. plot: the last peer draws the merged map in the world frame, and the
   query box over the missions as stored, as PNGs.

Every step is timed, with the bytes the swarm's transports sent meanwhile; the
summary adds each peer's chunks, commits and traffic (`mapapi.net.stats`).
"""

from __future__ import annotations

import asyncio
import json
import math
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any, TypeVar

from mapapi.core.errors import ConflictError
from mapapi.lookup.spatial import BBox
from mapbench.demo.aligning import align_missions
from mapbench.demo.errors import DemoFailed
from mapbench.demo.swarm import LocalSwarm, SwarmPeer

Json = Any
T = TypeVar("T")
Progress = Callable[[str, str], None]
"""Called with (kind, text): kind "step" when a step begins, "done" when it
ended, "info" for what happened within it."""

PREFIX = "tunnels-"
QUERY_BOX = (-15.0, -15.0, -15.0, 15.0, 15.0, 15.0)
"""Metres around the origin of the map frame, where every robot's trajectory begins."""
VIEW = "demo"
MAP_PNG, QUERY_PNG = "tunnels-map.png", "tunnels-query.png"
EDITS = ((0.5, 0.0, 0.0), (0.0, 0.0, 0.3))
"""How the first and the last peer move the vertex (metres in x, y, z)."""


def _tiles_in_box(mission: Json) -> list[Json]:
    """The spatial tiles of a mission (as `missions` or `import_map` list them)
    whose box overlaps `QUERY_BOX`."""
    box = BBox.from_tuple(QUERY_BOX)
    return [t for t in mission["tiles"] if BBox.from_tuple(t["bbox"]).overlaps(box)]


def _held_in_box(name: str, held: Json | None, imported: Json, own: bool) -> Json:
    """What the querying peer holds of a mission: complete when it holds the
    mission's row and every tile of it in the box (as the importer listed them),
    and nothing of the others; or, when it imported the mission (`own`), all of it."""
    wanted = imported["tiles"] if own else _tiles_in_box(imported)
    vertices = sum(t["vertex_count"] for t in wanted)
    edges = sum(t["edge_count"] for t in wanted)
    counts = (held["vertices"], held["edges"]) if held is not None else (0, 0)
    return {
        "name": name,
        "vertices": counts[0],
        "edges": counts[1],
        "tiles": len(wanted),
        "of_tiles": len(imported["tiles"]),
        "holders": [h["name"] for h in held["holders"]] if held is not None else [],
        "complete": held is not None and counts == (vertices, edges),
    }


def robot_files(tunnels: Path) -> list[Path]:
    """Each robot's `measurements.csv` of the tunnels set, by robot number.

    Raises:
        DemoFailed: the folder holds none.
    """
    files = sorted(
        tunnels.glob("robot*/measurements.csv"), key=lambda p: int(p.parent.name[5:] or 0)
    )
    if not files:
        raise DemoFailed(f"no robot*/measurements.csv in {tunnels}")
    return files


def share(files: list[Path], peers: int) -> list[list[Path]]:
    """The files in `peers` contiguous runs of (nearly) equal length."""
    size = math.ceil(len(files) / peers)
    return [files[i * size : (i + 1) * size] for i in range(peers)]


def _position(fields: Json) -> list[float]:
    pose = fields.get("pose", {})
    return [float(pose.get(axis, 0.0)) for axis in "xyz"]


def _moved(fields: Json, position: list[float]) -> Json:
    moved = json.loads(json.dumps(fields))
    moved.setdefault("pose", {}).update(dict(zip("xyz", position, strict=True)))
    return moved


class Demo:
    """One run of the demo over a started-to-be `LocalSwarm`.

    Args:
        swarm: the swarm (its daemons are started by `run`).
        tunnels: the tunnels set's folder.
        out: where the PNGs go (it exists).
        progress: told of each step (see `Progress`).
    """

    def __init__(self, swarm: LocalSwarm, tunnels: Path, out: Path, progress: Progress) -> None:
        self.swarm = swarm
        self.tunnels = tunnels
        self.out = out
        self.progress = progress
        self.timings: dict[str, float] = {}
        self.bytes_by_step: dict[str, int] = {}

    @property
    def peers(self) -> list[SwarmPeer]:
        """The running peers, in start order."""
        return self.swarm.peers

    async def run(self) -> Json:
        """Run every step; the summary (without the final stop)."""
        files = robot_files(self.tunnels)
        try:
            await self._step("start", f"starting {len(self.swarm.repos)} peers", self._start)
            missions = await self._step("import", "importing the tunnels set", self._import, files)
            query = await self._step("query", "querying a box and loading", self._query, missions)
            conflict = await self._step("conflict", "editing one vertex twice", self._conflict)
            aligned = await self._step("align", "aligning the missions", self._align, missions)
            pngs = await self._step("plot", "drawing the map and the query", self._plot, missions)
            return await self._summary(missions, query, conflict, pngs, aligned)
        finally:
            await self.swarm.disconnect()

    async def _step(
        self, name: str, title: str, work: Callable[..., Awaitable[T]], *args: Any
    ) -> T:
        self.progress("step", title)
        before = await self._sent()
        started = time.perf_counter()
        result = await work(*args)
        seconds = time.perf_counter() - started
        self.timings[name] = round(seconds, 3)
        self.bytes_by_step[name] = await self._sent() - before
        self.progress("done", f"{title}: {seconds:.1f} s, {self.bytes_by_step[name]:,} bytes sent")
        return result

    async def _sent(self) -> int:
        """Bytes every peer's swarm transport sent so far."""
        answers = await asyncio.gather(*(p.call("traffic") for p in self.peers))
        return sum(a["sent"]["bytes"] for a in answers)

    # -- the steps ---------------------------------------------------------------------
    async def _start(self) -> None:
        def started(peer: SwarmPeer) -> None:
            record = peer.record
            self.progress("info", f"peer {peer.name} serves {record.address} (pid {record.pid})")

        await self.swarm.start(started)

    async def _import(self, files: list[Path]) -> list[Json]:
        async def one_peer(peer: SwarmPeer, mine: list[Path]) -> list[Json]:
            done = []
            for path in mine:
                info = await peer.call(
                    "import_map", path=str(path), fmt="kimera-csv", mission=PREFIX
                )
                for m in info["missions"]:
                    self.progress(
                        "info",
                        f"{peer.name} imported {m['name']}: "
                        f"{m['vertices']} vertices, {m['edges']} edges",
                    )
                    done.append({**m, "peer": peer.name})
            return done

        shares = share(files, len(self.peers))
        runs = await asyncio.gather(*map(one_peer, self.peers, shares))
        return [m for run in runs for m in run]

    async def _query(self, missions: list[Json]) -> Json:
        asker = self.peers[-1]
        before = (await asker.call("traffic"))["received"]["bytes"]
        started = time.perf_counter()
        loaded = await asker.call("load_bbox", bbox=list(QUERY_BOX))
        seconds = time.perf_counter() - started
        found = sorted({name for r in loaded["results"] for name in r["missions"]})
        self.progress(
            "info",
            f"{asker.name} found {len(found)} missions in the box and loaded "
            f"{len(loaded['loaded'])} chunks from the others",
        )
        held = {m["name"]: m for m in (await asker.call("missions"))["missions"]}
        imported = {m["name"]: m for m in missions}
        rows = [
            _held_in_box(name, held.get(name), m, own=m["peer"] == asker.name)
            for name, m in sorted(imported.items())
        ]
        missing = [r["name"] for r in rows if not r["complete"]]
        if missing:
            raise DemoFailed(f"{asker.name} lacks what lies in the box of: {', '.join(missing)}")
        received = (await asker.call("traffic"))["received"]["bytes"] - before
        return {
            "peer": asker.name,
            "bbox": list(QUERY_BOX),
            "found": found,
            "loaded_chunks": len(loaded["loaded"]),
            "bytes_received": received,
            "seconds": round(seconds, 3),
            "missions": rows,
            "complete": all(r["complete"] for r in rows),
        }

    async def _conflict(self) -> Json:
        first, second = self.peers[0], self.peers[-1]
        own = (await first.call("missions"))["missions"][0]  # by name: its first import
        # a tile in the query box: the last peer loaded it
        mission, chunk = own["name"], _tiles_in_box(own)[0]["vertices"]
        items = (await first.call("ls", view=VIEW, table="vertices", chunk=chunk))["items"]
        target = min(items, key=lambda i: abs(int(i["data"].get("index", 0)) - 10))
        item, base = target["id"], target["data"]
        self.progress(
            "info",
            f"{first.name} and {second.name} both move vertex {base.get('index', 0)} of {mission}",
        )
        for peer in (first, second):
            await peer.call("view_open", view=VIEW)
        for peer, edit in zip((first, second), EDITS, strict=True):
            moved = [a + d for a, d in zip(_position(base), edit, strict=True)]
            await peer.call(
                "set", view=VIEW, table="vertices", data=json.dumps(_moved(base, moved)), item=item
            )
        await first.call("commit", view=VIEW, message=f"{first.name} moves a vertex")
        try:
            await second.call("commit", view=VIEW, message=f"{second.name} moves a vertex")
        except ConflictError as exc:
            message = str(exc)
        else:
            raise DemoFailed(f"{second.name}'s commit went through: the conflict was missed")
        self.progress("info", f"{second.name}'s commit conflicts: {message}")
        (clash,) = (await second.call("diff", view=VIEW))["conflicts"]
        ours, theirs = _position(clash["ours"]), _position(clash["theirs"])
        mean = [(a + b) / 2 for a, b in zip(ours, theirs, strict=True)]
        resolved = _moved(clash["ours"], mean)
        await second.call("resolve", view=VIEW, side="ours", edited={item: resolved})
        record = await second.call("commit", view=VIEW, message="the mean of both edits")
        seen = {
            p.name: _position((await p.call("get", view=VIEW, table="vertices", item=item))["data"])
            for p in (first, second)
        }
        if any(v != mean for v in seen.values()):
            raise DemoFailed(f"the peers read different values after the resolution: {seen}")
        self.progress("info", f"{second.name} resolved it with the mean of both edits")
        return {
            "mission": mission,
            "vertex": item,
            "index": int(base.get("index", 0)),
            "chunk": chunk,
            "peers": [first.name, second.name],
            "detected": True,
            "message": message,
            "base": _position(clash["base"]),
            "first": theirs,
            "second": ours,
            "resolved": mean,
            "commit": record["commit"],
            "seen": seen,
            "agree": all(v == mean for v in seen.values()),
        }

    async def _align(self, missions: list[Json]) -> Json:
        return await align_missions(self.peers, f"{PREFIX}*", list(QUERY_BOX), self.progress)

    async def _plot(self, missions: list[Json]) -> dict[str, str]:
        drawer = self.peers[-1]
        count = len(self.swarm.repos)
        labels = {m["name"]: f"{m['robot']} (imported by {m['peer']})" for m in missions}
        whole = await drawer.call(
            "plot_map",
            path=str(self.out / MAP_PNG),
            missions=[f"{PREFIX}*"],
            labels=labels,
            title=f"the merged tunnels map on {drawer.name}, imported by {count} peers",
            frame="world",
        )
        query = await drawer.call(
            "plot_map",
            path=str(self.out / QUERY_PNG),
            bbox=list(QUERY_BOX),
            zoom=True,
            labels=labels,
            title=f"{drawer.name}'s query box and the missions it loaded",
        )
        for drawn in (whole, query):
            self.progress("info", f"wrote {drawn['path']}")
        return {"map": whole["path"], "query": query["path"]}

    # -- the summary -------------------------------------------------------------------
    async def _summary(
        self, missions: list[Json], query: Json, conflict: Json, pngs: dict[str, str], align: Json
    ) -> Json:
        rows, chunks, commits = [], set(), set()
        for peer in self.peers:
            held = (await peer.call("chunk_list"))["chunks"]
            log = await peer.call("log")
            traffic = await peer.call("traffic")
            chunks |= {c["id"] for c in held}
            commits |= {c["commit"] for c in log}
            rows.append(
                {
                    "name": peer.name,
                    "id": peer.record.id,
                    "pid": peer.record.pid,
                    "address": peer.record.address,
                    "imported": [m["name"] for m in missions if m["peer"] == peer.name],
                    "chunks": len(held),
                    "commits": len(log),
                    "sent": traffic["sent"],
                    "received": traffic["received"],
                }
            )
        return {
            "peers": rows,
            "missions": [
                {k: m[k] for k in ("name", "robot", "peer", "vertices", "edges")} for m in missions
            ],
            "chunks": len(chunks),
            "commits": len(commits),
            "bytes_moved": sum(r["sent"]["bytes"] for r in rows),
            "query": query,
            "conflict": conflict,
            "align": align,
            "pngs": pngs,
            "bytes_by_step": self.bytes_by_step,
            "timings": self.timings,
        }
