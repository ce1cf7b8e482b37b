"""The workload of `mapctl bench triggers` (pure): where the writers' items
start and how each commit moves one, planned from a seed so that every mode of
the bench replays exactly the same commits."""

from __future__ import annotations

import random
from dataclasses import dataclass

from google.protobuf import struct_pb2

from mapapi.lookup.spatial import BBox

AREA = BBox(0.0, 0.0, 0.0, 200.0, 200.0, 10.0)
"""The map: 200 m x 200 m, 10 m high."""

REGION = BBox(90.0, 90.0, 0.0, 110.0, 110.0, 10.0)
"""The subscribers' region: 20 m x 20 m in the middle of the map, across 4 cells."""

INSIDE_SHARE = 0.1
"""The share of a chunk's items inside the region."""

_SIZE = 1.0  # an item's side, in metres
_NUDGE = 0.5  # the largest move of one update along each horizontal axis
_MARGIN = 2.0  # outside items stay this far from the region


@dataclass(frozen=True)
class Update:
    """One planned commit: the writer's item number `item` moves from `before` to `after`."""

    item: int
    before: BBox
    after: BBox

    def inside(self, region: BBox) -> bool:
        """Whether the commit is news for `region`: the item overlaps it before or after."""
        return self.before.overlaps(region) or self.after.overlaps(region)


@dataclass(frozen=True)
class Workload:
    """What the writers commit, the same in every mode.

    Attributes:
        fraction: the share of each writer's commits inside the region.
        region: the subscribers' region.
        items: per writer, the boxes its chunk's items start at.
        rounds: per round, one update per writer.
    """

    fraction: float
    region: BBox
    items: list[list[BBox]]
    rounds: list[list[Update]]

    def inside_commits(self) -> int:
        """The commits a subscriber must learn of."""
        return sum(u.inside(self.region) for updates in self.rounds for u in updates)


def plan_workload(
    writers: int,
    items: int,
    commits: int,
    fraction: float,
    *,
    seed: int = 0,
    area: BBox = AREA,
    region: BBox = REGION,
) -> Workload:
    """A seeded workload: `writers` chunks of `items` items, then `commits`
    rounds in which every writer nudges one of its items; exactly
    ``round(fraction * commits)`` of each writer's updates are to an inside item.

    Two items of each chunk start in opposite corners of `area`, so the chunk's
    box is the whole area from the start and no update grows it: a grown box
    is announced anew in every cell it covers (DESIGN §7), which would bury
    the subscribers' figures under index traffic of the same size in every
    mode (about 24 KB per subscriber for each growth, on 8 peers).

    Raises:
        ValueError: fewer than 1 writer or commit, fewer than 3 items (one
            inside, two in the corners), or a fraction outside [0, 1].
    """
    if writers < 1 or commits < 1 or items < 3:
        raise ValueError(
            f"need at least 1 writer, 3 items and 1 commit, got {writers}, {items}, {commits}"
        )
    if not 0 <= fraction <= 1:
        raise ValueError(f"a fraction is in [0, 1], got {fraction}")
    rng = random.Random(f"{seed}:{fraction}")
    inside = max(1, min(items - 2, round(INSIDE_SHARE * items)))
    far = BBox(*(lo - _MARGIN for lo in region.mins), *(hi + _MARGIN for hi in region.maxs))
    start = [
        [_place(rng, region) for _ in range(inside)]
        + _corners(area)
        + [_place(rng, area, avoid=far) for _ in range(items - inside - 2)]
        for _ in range(writers)
    ]
    flags = [_shuffled(rng, commits, round(fraction * commits)) for _ in range(writers)]
    now = [list(boxes) for boxes in start]
    rounds = []
    for r in range(commits):
        updates = []
        for w in range(writers):
            k = rng.randrange(inside) if flags[w][r] else rng.randrange(inside, items)
            zone, avoid = (region, None) if flags[w][r] else (area, far)
            updates.append(Update(k, now[w][k], _nudge(rng, now[w][k], zone, avoid)))
            now[w][k] = updates[-1].after
        rounds.append(updates)
    return Workload(fraction, region, start, rounds)


def _corners(area: BBox) -> list[BBox]:
    """Item boxes in the lowest and the highest corner of `area`."""
    low, high = area.mins, (area.xmax - _SIZE, area.ymax - _SIZE, area.zmin)
    return [BBox(*p, p[0] + _SIZE, p[1] + _SIZE, p[2] + _SIZE) for p in (low, high)]


def _shuffled(rng: random.Random, count: int, true: int) -> list[bool]:
    """`count` flags, `true` of them set, in random order."""
    flags = [k < true for k in range(count)]
    rng.shuffle(flags)
    return flags


def _place(rng: random.Random, zone: BBox, avoid: BBox | None = None) -> BBox:
    """A random item box inside `zone` that does not overlap `avoid`."""
    while True:
        x = rng.uniform(zone.xmin, zone.xmax - _SIZE)
        y = rng.uniform(zone.ymin, zone.ymax - _SIZE)
        box = BBox(x, y, 0.0, x + _SIZE, y + _SIZE, _SIZE)
        if avoid is None or not box.overlaps(avoid):
            return box


def _nudge(rng: random.Random, box: BBox, zone: BBox, avoid: BBox | None) -> BBox:
    """`box` moved by up to `_NUDGE` along each horizontal axis, kept inside
    `zone`; a move onto `avoid` is not made (the item stays where it was)."""
    x = min(max(box.xmin + rng.uniform(-_NUDGE, _NUDGE), zone.xmin), zone.xmax - _SIZE)
    y = min(max(box.ymin + rng.uniform(-_NUDGE, _NUDGE), zone.ymin), zone.ymax - _SIZE)
    moved = BBox(x, y, box.zmin, x + _SIZE, y + _SIZE, box.zmax)
    return box if avoid is not None and moved.overlaps(avoid) else moved


def item_at(box: BBox, seen: int) -> struct_pb2.Struct:
    """A landmark item at `box`, updated `seen` times."""
    item = struct_pb2.Struct()
    item.update({"bbox": [*box.mins, *box.maxs], "kind": "landmark", "seen": seen})
    return item
