"""The simulator moved to `mapbench.sim` (installed with the project, for `mapctl bench sim`);
these names stay importable here for the tests that use them (`tests/unit/test_raft.py`)."""

from mapbench.sim import TICK, Faults, Sim, SimNode, Violation
from mapbench.sim_world import Checker, Disk, Machine

__all__ = ["TICK", "Checker", "Disk", "Faults", "Machine", "Sim", "SimNode", "Violation"]
