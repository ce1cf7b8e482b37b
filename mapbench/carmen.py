"""A large real 2D pose graph for `bench scale`, made from a raw CARMEN laser log.

The field test of issue 14 used a 15,115-pose 2D g2o graph that the shared
datasets do not hold; the largest 2D g2o graph there has 1,728 poses. The
Intel Research Lab log (`radish_laser_logs/intel.clf.bz2`, CC-BY-3.0) has
13,631 laser scans, each taken at an odometry pose: one vertex per scan at
that pose and one odometry edge between consecutive scans (their relative
pose) make a real 2D graph of the same order, 13,631 poses and 13,630 edges.
It has no loop closures, which a read of the stored graph does not care
about. The information matrix of every edge is the same
(`mapapi.maps.carmen.INFORMATION`). `mapctl import LOG.clf.bz2` stores the same
trajectory with its scans; this writes the graph alone, as a g2o file.

    python -m mapbench.carmen LOG.clf.bz2 OUT.g2o
"""

from __future__ import annotations

import sys
from pathlib import Path

from mapapi.maps.carmen import INFORMATION, Scan, open_log, read_records, relative_se2


def scan_poses(path: Path) -> list[tuple[float, float, float]]:
    """The odometry pose (x, y, theta) of every FLASER scan of a CARMEN log
    (plain or bzip2), in order (`mapapi.maps.carmen` reads it)."""
    with open_log(path) as log:
        return [r.odometry for r in read_records(log, str(path)) if isinstance(r, Scan)]


def write_graph(poses: list[tuple[float, float, float]], out: Path) -> None:
    """Write `poses` as g2o VERTEX_SE2 lines with an EDGE_SE2 between neighbours."""
    information = " ".join(f"{v:g}" for v in INFORMATION)
    with out.open("w", encoding="ascii") as g2o:
        for i, (x, y, theta) in enumerate(poses):
            g2o.write(f"VERTEX_SE2 {i} {x:.6f} {y:.6f} {theta:.6f}\n")
        for i in range(len(poses) - 1):
            dx, dy, dt = relative_se2(poses[i], poses[i + 1])
            g2o.write(f"EDGE_SE2 {i} {i + 1} {dx:.6f} {dy:.6f} {dt:.6f} {information}\n")


def main(argv: list[str]) -> int:
    """`python -m mapbench.carmen LOG OUT`: convert; prints the counts."""
    if len(argv) != 2:
        print(__doc__.strip().splitlines()[-1].strip(), file=sys.stderr)
        return 2
    poses = scan_poses(Path(argv[0]))
    write_graph(poses, Path(argv[1]))
    print(f"{len(poses)} poses, {max(len(poses) - 1, 0)} edges -> {argv[1]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
