"""PLY and PCD point-cloud files: read (checked, line by line where text) and write.

open3d reads the binary bodies, downsamples and writes. It is an optional
dependency (the `pointcloud` extra), imported on first use. open3d accepts
malformed text silently (a bad number becomes 0 or garbage), so the text
headers, and ASCII bodies, are parsed here, and any error names its line.
Binary bodies are checked against the point count their header declares.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from mapapi.core.errors import UsageError
from mapapi.maps.cloud import PointCloud, Points, as_points
from mapapi.maps.errors import MapImportError

log = logging.getLogger(__name__)

Progress = Callable[[int, int], None]  # (points read, points declared)

CLOUD_FORMATS = ("ply", "pcd")
DEFAULT_VOXEL = 0.05  # metres: keeps room-scale detail, cuts a dense lidar scan about 4 times
_MAX_HEADER_LINES = 1_000
_PROGRESS_EVERY = 10_000


@dataclass(frozen=True)
class CloudHeader:
    """What a file's text header says about its points.

    Attributes:
        ascii: the body is text, one point per line.
        count: the points the header declares.
        count_line: the header line that declares them.
        columns: where x, y and z stand among the values of a body line.
        width: values per body line.
        skip: body lines to pass over before the points (ASCII PLY elements
            listed before the vertices).
        body_line: the number of the header's last line (the body follows).
    """

    ascii: bool
    count: int
    count_line: int
    columns: tuple[int, int, int]
    width: int
    skip: int
    body_line: int


def open3d() -> Any:
    """The open3d module, quiet below errors.

    Raises:
        UsageError: it is not installed.
    """
    try:
        import open3d as o3d
    except ImportError:
        raise UsageError(
            "point clouds need open3d; install it with `pip install 'mapapi[pointcloud]'`"
        ) from None
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    return o3d


def _header_lines(stream: BinaryIO, source: str) -> Iterator[tuple[int, list[str]]]:
    for number in range(1, _MAX_HEADER_LINES + 1):
        raw = stream.readline(4096)
        if not raw:
            raise MapImportError("the file ends inside its header", source=source, line=number)
        yield number, raw.decode("ascii", errors="replace").split()
    raise MapImportError(
        f"no end of the header in {_MAX_HEADER_LINES} lines", source=source, line=number
    )


def _count(text: str, source: str, line: int) -> int:
    if not text.isdigit():
        raise MapImportError(f"{text!r} is not a point count", source=source, line=line)
    return int(text)


def _xyz(names: list[str], sizes: list[int], source: str, line: int) -> tuple[int, int, int]:
    missing = [a for a in "xyz" if a not in names]
    if missing:
        raise MapImportError(
            f"no field {', '.join(missing)}: a cloud needs x, y and z", source=source, line=line
        )
    starts = np.cumsum([0, *sizes])
    x, y, z = (int(starts[names.index(a)]) for a in "xyz")
    return x, y, z


_PLY_ENCODINGS = ("ascii", "binary_little_endian", "binary_big_endian")


@dataclass
class _PlyHeader:
    """What the lines of a PLY header said so far."""

    source: str
    encoding: str = ""
    element: str = ""
    vertex: tuple[int, int] | None = None  # (count, line)
    skip: int = 0  # instances of the elements before the vertices
    properties: list[str] = field(default_factory=list)

    def read(self, words: list[str], number: int) -> bool:
        """Take one header line; True at its end."""
        key = words[0] if words else ""
        if key == "format" and len(words) == 3 and words[1] in _PLY_ENCODINGS:
            self.encoding = words[1]
        elif key == "element" and len(words) == 3:
            self.element = words[1]
            count = _count(words[2], self.source, number)
            if self.element == "vertex":
                self.vertex = (count, number)
            elif self.vertex is None:
                self.skip += count
        elif key == "property" and len(words) >= 3:
            if self.element == "vertex" and words[1] == "list":
                raise MapImportError(
                    "vertex properties must be scalars", source=self.source, line=number
                )
            if self.element == "vertex":
                self.properties.append(words[-1])
        elif key not in ("comment", "obj_info", "end_header"):
            raise MapImportError(
                f"unexpected header line {' '.join(words)!r}", source=self.source, line=number
            )
        return key == "end_header"


def read_ply_header(stream: BinaryIO, source: str = "") -> CloudHeader:
    """Parse a PLY header (the stream is left at the body).

    Raises:
        MapImportError: not a PLY file, or no vertex element with x, y, z.
    """
    lines = _header_lines(stream, source)
    number, words = next(lines)
    if words != ["ply"]:
        raise MapImportError("not a PLY file: the first line must be 'ply'", source=source, line=1)
    state = _PlyHeader(source)
    for number, words in lines:
        if state.read(words, number):
            break
    if not state.encoding or state.vertex is None:
        raise MapImportError(
            "the header has no format line or no vertex element", source=source, line=number
        )
    count, count_line = state.vertex
    width = len(state.properties)
    columns = _xyz(state.properties, [1] * width, source, count_line)
    return CloudHeader(
        state.encoding == "ascii", count, count_line, columns, width, state.skip, number
    )


_PCD_KEYS = (
    "VERSION",
    "FIELDS",
    "SIZE",
    "TYPE",
    "COUNT",
    "WIDTH",
    "HEIGHT",
    "VIEWPOINT",
    "POINTS",
    "DATA",
)


def read_pcd_header(stream: BinaryIO, source: str = "") -> CloudHeader:
    """Parse a PCD (v0.7) header (the stream is left at the body).

    Raises:
        MapImportError: an unknown key, no x, y, z fields, or no point count.
    """
    found: dict[str, tuple[list[str], int]] = {}
    for number, words in _header_lines(stream, source):
        if not words or words[0].startswith("#"):
            continue
        if words[0] not in _PCD_KEYS:
            raise MapImportError(f"unknown PCD header key {words[0]!r}", source=source, line=number)
        found[words[0]] = (words[1:], number)
        if words[0] == "DATA":
            break
    data, data_line = found["DATA"]
    if data not in (["ascii"], ["binary"], ["binary_compressed"]):
        raise MapImportError(f"unknown DATA {' '.join(data)!r}", source=source, line=data_line)
    if "FIELDS" not in found or "POINTS" not in found:
        raise MapImportError(
            "the header has no FIELDS or no POINTS line", source=source, line=data_line
        )
    names, fields_line = found["FIELDS"]
    counts = (
        [_count(c, source, found["COUNT"][1]) for c in found["COUNT"][0]]
        if "COUNT" in found
        else [1] * len(names)
    )
    if len(counts) != len(names):
        raise MapImportError(
            f"COUNT has {len(counts)} values for {len(names)} fields",
            source=source,
            line=found["COUNT"][1],
        )
    points, points_line = found["POINTS"]
    if len(points) != 1:
        raise MapImportError("POINTS needs one number", source=source, line=points_line)
    return CloudHeader(
        data == ["ascii"],
        _count(points[0], source, points_line),
        points_line,
        _xyz(names, counts, source, fields_line),
        sum(counts),
        0,
        data_line,
    )


def _ascii_points(
    stream: BinaryIO, header: CloudHeader, source: str, progress: Progress | None
) -> Points:
    """The points of a text body, one per line; any malformed line is named."""
    number = header.body_line
    for _ in range(header.skip):
        stream.readline()
        number += 1
    points = np.empty((header.count, 3), dtype=np.float64)
    xyz = list(header.columns)
    for row in range(header.count):
        raw = stream.readline()
        number += 1
        if not raw:
            raise MapImportError(
                f"the file ends after {row} of the {header.count} points declared on "
                f"line {header.count_line}",
                source=source,
                line=number,
            )
        values = raw.split()
        if len(values) != header.width:
            raise MapImportError(
                f"expected {header.width} values, found {len(values)}", source=source, line=number
            )
        try:
            points[row] = [float(values[i]) for i in xyz]
        except ValueError:
            text = b" ".join(values[i] for i in xyz).decode(errors="replace")
            raise MapImportError(
                f"x, y, z {text!r} are not all numbers", source=source, line=number
            ) from None
        if progress is not None and row % _PROGRESS_EVERY == 0:
            progress(row, header.count)
    return as_points(points)


def _binary_points(path: Path, fmt: str, header: CloudHeader) -> Points:
    """The points of a binary body, read by open3d and counted."""
    o3d = open3d()
    cloud = o3d.io.read_point_cloud(
        str(path), format=fmt, remove_nan_points=False, remove_infinite_points=False
    )
    points = np.asarray(cloud.points)
    if len(points) != header.count:
        raise MapImportError(
            f"the body holds {len(points)} readable points, not the {header.count} the header "
            "declares: truncated or corrupt",
            source=str(path),
            line=header.count_line,
        )
    return as_points(points)


def downsample(points: Points, voxel: float) -> Points:
    """One point per occupied voxel of side `voxel` metres (their mean), by open3d;
    `voxel` 0 keeps every point.

    Raises:
        UsageError: a negative voxel size.
    """
    if voxel < 0 or not np.isfinite(voxel):
        raise UsageError(
            f"the voxel size must be 0 (off) or a positive number of metres, not {voxel}"
        )
    if voxel == 0 or len(points) == 0:
        return points
    o3d = open3d()
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points.astype(np.float64)))
    return as_points(np.asarray(cloud.voxel_down_sample(voxel).points))


def read_cloud(
    path: str | Path,
    fmt: str | None = None,
    *,
    mission: str | None = None,
    robot: str = "",
    voxel: float = DEFAULT_VOXEL,
    progress: Progress | None = None,
) -> PointCloud:
    """Read a PLY or PCD file as one mission's cloud (named after the file unless
    `mission`), dropping points with a coordinate that is not finite, then
    voxel-downsampled.

    Args:
        fmt: "ply" or "pcd"; by default the file's extension.
        voxel: the voxel side in metres; 0 keeps every point.
        progress: called with (points read, points declared).

    Raises:
        MapImportError: a malformed header or body (the message names the line).
        UsageError: an unknown format, or open3d is missing for a binary body.
    """
    path = Path(path)
    fmt = fmt or path.suffix.lower().lstrip(".")
    if fmt not in CLOUD_FORMATS:
        raise UsageError(
            f"unknown point-cloud format {fmt!r}; expected one of {', '.join(CLOUD_FORMATS)}"
        )
    source = str(path)
    with path.open("rb") as stream:
        header = (read_ply_header if fmt == "ply" else read_pcd_header)(stream, source)
        if header.ascii:
            points = _ascii_points(stream, header, source, progress)
    if not header.ascii:
        points = _binary_points(path, fmt, header)
    finite = np.isfinite(points).all(axis=1)
    dropped = int(len(points) - finite.sum())
    if dropped:
        log.info("%s: %d points with a coordinate that is not finite left out", source, dropped)
    kept = downsample(points[finite], voxel)
    if progress is not None:
        progress(header.count, header.count)
    name = mission or path.stem
    return PointCloud(name, robot, f"{name}/map", kept, dropped)


def write_cloud(cloud: PointCloud, path: str | Path) -> int:
    """Write a cloud as binary PLY or PCD (by the extension) through open3d;
    returns how many points were written.

    Raises:
        UsageError: another extension, or the file could not be written.
    """
    path = Path(path)
    if path.suffix.lower().lstrip(".") not in CLOUD_FORMATS:
        raise UsageError(f"write a cloud to a .ply or .pcd file, not {path.name!r}")
    o3d = open3d()
    out = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.points.astype(np.float64)))
    if not o3d.io.write_point_cloud(str(path), out):
        raise UsageError(f"could not write {path}; check the folder exists and is writable")
    return len(cloud.points)
