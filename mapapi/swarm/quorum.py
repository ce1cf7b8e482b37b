"""Which subsets of a chunk's holders may decide for all of them (pure).

A *quorum* of a holder set H is a strict majority of H, or exactly half of H
if that half contains the lowest holder (the arbiter of DESIGN §6). Any two
quorums of the same H share a holder, so two sides of a partition can never
both act on a chunk: only one of them evicts the other side's holders and
goes on committing, and a commit confirmed by a quorum is seen by every later
quorum (docs/design.md, "Failures").
"""

from __future__ import annotations

from collections.abc import Collection, Iterable

from mapapi.core.ids import PeerId


def is_quorum(subset: Iterable[PeerId], holders: Collection[PeerId]) -> bool:
    """True if the holders of `subset` form a quorum of `holders`.

    Members of `subset` that are not holders do not count. An empty holder set
    has no quorum.
    """
    everyone = set(holders)
    if not everyone:
        return False
    present = everyone.intersection(subset)
    twice = 2 * len(present)
    return twice > len(everyone) or (twice == len(everyone) and min(everyone) in present)
