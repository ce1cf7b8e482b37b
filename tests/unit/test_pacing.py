"""The daemon's interpreter settings (mapapi.service.pacing): set while it serves,
what it holds frozen out of the collector's passes, all put back when it stops."""

from __future__ import annotations

import gc
import sys

from mapapi.service.pacing import FULL_AFTER, SWITCH_INTERVAL, Pacing


async def test_the_settings_hold_while_serving_and_are_put_back() -> None:
    before = (gc.get_threshold(), sys.getswitchinterval())
    pacing = Pacing(full_every=3600.0)
    pacing.start()
    try:
        assert sys.getswitchinterval() == SWITCH_INTERVAL
        assert gc.get_threshold() == (before[0][0], before[0][1], FULL_AFTER)
        pacing.settle()
        assert gc.get_freeze_count() > 0
    finally:
        await pacing.close()
    assert (gc.get_threshold(), sys.getswitchinterval()) == before
    assert gc.get_freeze_count() == 0
