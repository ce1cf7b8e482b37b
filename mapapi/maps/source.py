"""Map files by format: which reader a file needs, and reading it as missions.

Formats: `g2o` (one pose graph), `kimera-csv` (a folder of
`robot*/measurements.csv`, one mission per robot, or one robot's CSV file),
`ply` and `pcd` (one point cloud), `carmen` (a laser log, `.clf` or `.clf.bz2`:
a trajectory and its scans). The format follows from the extension (a folder
is a Kimera set) unless given.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from mapapi.core.errors import UsageError
from mapapi.maps.carmen import read_carmen
from mapapi.maps.cloud_file import CLOUD_FORMATS, DEFAULT_VOXEL, read_cloud
from mapapi.maps.errors import MapImportError
from mapapi.maps.g2o import read_g2o
from mapapi.maps.graph import EdgeKind, MissionGraph
from mapapi.maps.importer import MapSource, rename
from mapapi.maps.kimera import KimeraReader, read_kimera

Progress = Callable[[int, int], None]  # (units read, units in all; 0 while unknown)

FORMATS = ("g2o", "kimera-csv", *CLOUD_FORMATS, "carmen")
_BY_SUFFIX = {".g2o": "g2o", ".csv": "kimera-csv", ".ply": "ply", ".pcd": "pcd", ".clf": "carmen"}


def detect_format(path: str | Path) -> str:
    """The format of `path` by its extension (a folder is a Kimera set).

    Raises:
        UsageError: an extension no reader knows.
    """
    path = Path(path)
    if path.is_dir():
        return "kimera-csv"
    if [s.lower() for s in path.suffixes[-2:]] == [".clf", ".bz2"]:
        return "carmen"  # the one reader that takes a compressed file: logs ship so
    fmt = _BY_SUFFIX.get(path.suffix.lower())
    if fmt is None:
        raise UsageError(
            f"cannot tell the format of {path.name!r} from its extension; "
            f"pass --format ({'|'.join(FORMATS)})"
        )
    return fmt


def read_source(
    path: str | Path,
    fmt: str | None = None,
    *,
    mission: str | None = None,
    robot: str | None = None,
    voxel: float | None = None,
    progress: Progress | None = None,
) -> list[MapSource]:
    """Read a map file (or Kimera folder) as the missions it holds.

    Args:
        fmt: one of `FORMATS`; by default from the extension.
        mission: the mission's name (default: the file's); for a Kimera set,
            a prefix of each robot's mission name.
        robot: the robot's name (only for a source of one mission).
        voxel: point clouds only: the voxel side in metres (0 keeps every
            point; default `DEFAULT_VOXEL`).
        progress: called with (units read, units in all or 0 while unknown).

    Raises:
        MapImportError: the file is malformed (the message names the line).
        UsageError: a missing file, an unknown format, or options that do not fit it.
    """
    path = Path(path)
    if not path.exists():
        raise UsageError(f"no file or folder {str(path)!r}")
    fmt = fmt or detect_format(path)
    if fmt not in FORMATS:
        raise UsageError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}")
    if fmt in CLOUD_FORMATS:
        cloud = read_cloud(
            path,
            fmt,
            mission=mission,
            robot=robot or "",
            voxel=DEFAULT_VOXEL if voxel is None else voxel,
            progress=progress,
        )
        return [cloud]
    if voxel is not None:
        raise UsageError("--voxel applies to point clouds (ply, pcd) only")
    if fmt == "g2o":
        return [read_g2o(path, mission, robot or "", progress=progress)]
    if fmt == "carmen":
        return [read_carmen(path, mission, robot or "", progress=progress)]
    graphs = _read_kimera(path, mission or "", progress)
    if robot is not None:
        if len(graphs) != 1:
            raise UsageError(f"{path.name} holds {len(graphs)} robots' missions; drop --robot")
        graphs = [rename(graphs[0], None, robot)]
    return list(graphs)


def _read_kimera(path: Path, prefix: str, progress: Progress | None) -> list[MissionGraph]:
    """A Kimera folder, or one robot's CSV: the robots whose odometry it holds
    (the file also lists edges from other robots, which their own files repeat)."""
    if path.is_dir():
        return read_kimera(path, prefix, progress)
    reader = KimeraReader(prefix, progress)
    with path.open(encoding="utf-8", newline="") as lines:
        reader.read(lines, str(path))
    own = [g for g in reader.graphs() if g.count(EdgeKind.ODOMETRY)]
    if not own:
        raise MapImportError("no odometry rows: no robot's trajectory to import", source=str(path))
    return own
