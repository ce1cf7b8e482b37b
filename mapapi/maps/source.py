"""Map files by format: which reader a file needs, and reading it as missions.

Formats: `g2o` (one pose graph, or one per robot when its ids are GTSAM
`Symbol` keys, as in a DGS folder of `<n>.g2o` files: `mapapi.maps.dgs`),
`kimera-csv` (a folder of `robot*/measurements.csv`, one mission per robot, or
one robot's CSV file), `gtsam-landmarks` (GTSAM's ODOMETRY/LANDMARK text),
`ply` and `pcd` (one point cloud), `carmen` (a laser log, `.clf` or `.clf.bz2`:
a trajectory and its scans), `rosbag` (a ROS 1 `.bag` or a ROS 2 bag's folder:
a mission per pose or point cloud topic, `mapapi.maps.rosbag`). The format
follows from the extension (a folder is a ROS 2 bag when it holds
`metadata.yaml`, a DGS set when it holds `<n>.g2o` files, else a Kimera set; a
`.txt` file is GTSAM landmark text when its first record says so) unless given.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from mapapi.core.errors import UsageError
from mapapi.maps import gtsam_text
from mapapi.maps.carmen import read_carmen
from mapapi.maps.cloud_file import CLOUD_FORMATS, DEFAULT_VOXEL, read_cloud
from mapapi.maps.dgs import read_g2o_source, robot_files
from mapapi.maps.errors import MapImportError
from mapapi.maps.graph import EdgeKind, MissionGraph
from mapapi.maps.importer import MapSource, rename
from mapapi.maps.kimera import KimeraReader, read_kimera
from mapapi.maps.rosbag import FORMAT as ROSBAG
from mapapi.maps.rosbag import is_bag, read_bag
from mapapi.maps.text_file import read_text

Progress = Callable[[int, int], None]  # (units read, units in all; 0 while unknown)

FORMATS = ("g2o", "kimera-csv", gtsam_text.FORMAT, *CLOUD_FORMATS, "carmen", ROSBAG)
_BY_SUFFIX = {".g2o": "g2o", ".csv": "kimera-csv", ".ply": "ply", ".pcd": "pcd", ".clf": "carmen"}


def detect_format(path: str | Path) -> str:
    """The format of `path` by its extension (a folder is a ROS 2 bag, a DGS or
    a Kimera set; a `.txt` file GTSAM landmark text if its first record says so).

    Raises:
        UsageError: an extension no reader knows.
    """
    path = Path(path)
    if is_bag(path):
        return ROSBAG
    if path.is_dir():
        return "g2o" if robot_files(path) else "kimera-csv"
    if [s.lower() for s in path.suffixes[-2:]] == [".clf", ".bz2"]:
        return "carmen"  # the one reader that takes a compressed file: logs ship so
    fmt = _BY_SUFFIX.get(path.suffix.lower())
    if fmt is None and path.suffix.lower() == ".txt" and gtsam_text.looks_like(path):
        fmt = gtsam_text.FORMAT
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
    topics: Sequence[str] = (),
    tf_frame: str | None = None,
    scan_match: bool = False,
    progress: Progress | None = None,
) -> list[MapSource]:
    """Read a map file (or Kimera folder) as the missions it holds.

    Args:
        fmt: one of `FORMATS`; by default from the extension.
        mission: the mission's name (default: the file's); for a Kimera set,
            a prefix of each robot's mission name.
        robot: the robot's name (only for a source of one mission).
        voxel: point clouds only: the voxel side in metres (0 keeps every
            point; default `DEFAULT_VOXEL`, and for a bag's clouds 0).
        topics: ROS bags only: the topics to read (default: every supported one).
        tf_frame: ROS bags only: the frame its point clouds are placed in.
        scan_match: laser logs only: correct the odometry by the scans
            (`mapapi.maps.scan_match`).
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
    if fmt == ROSBAG:
        bag_voxel = voxel or 0.0  # a bag's clouds keep every point unless told
        return read_bag(
            path,
            topics,
            mission,
            robot or "",
            voxel=bag_voxel,
            tf_frame=tf_frame,
            progress=progress,
        )
    if topics:
        raise UsageError("--topics applies to ROS bags only")
    if tf_frame is not None:
        raise UsageError("--tf-frame applies to ROS bags only")
    if scan_match and fmt != "carmen":
        raise UsageError("--scan-match applies to laser logs (carmen) only")
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
        return list(read_g2o_source(path, mission, robot, progress))
    if fmt == "carmen":
        laser = read_carmen(path, mission, robot or "", progress=progress)
        if scan_match:
            from mapapi.maps.scan_match import match_mission

            match_mission(laser, progress)
        return [laser]
    if fmt == gtsam_text.FORMAT:
        parse = gtsam_text.parse_gtsam_landmarks
        return [read_text(parse, path, mission, robot or "", progress)]
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
