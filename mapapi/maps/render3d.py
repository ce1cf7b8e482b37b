"""An open3d offscreen render of point clouds, seen from above, in a child process.

open3d's renderer needs a working GPU or software (EGL / Vulkan) driver; where
there is none it raises, and on some broken drivers it aborts the process.
So it runs in a child (`python -m mapapi.maps.render3d`): if the child fails,
`render_cloud` returns False, the caller draws with matplotlib instead, and
this process does not try again. `MAPAPI_RENDER3D=0` skips it altogether.
"""

from __future__ import annotations

import argparse
import logging
import os
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from mapapi.lookup.spatial import BBox
from mapapi.maps.cloud import Points
from mapapi.maps.view_axes import UP_CHOICES, Z_UP, Up, choose_up, plane_axes

log = logging.getLogger(__name__)

TIMEOUT_S = 60.0
SIZE = (1200, 900)
_unavailable: list[str] = []  # why the renderer failed in this process, once it did


def render_cloud(
    points: Points, output: str | Path, *, box: BBox | None = None, up: Up = Z_UP
) -> bool:
    """Render `points` seen from above along `up` into the PNG `output`, with `box`
    outlined; False (and nothing written) when no open3d renderer works here."""
    if os.environ.get("MAPAPI_RENDER3D", "1") == "0" or _unavailable:
        return False
    with tempfile.TemporaryDirectory(prefix="mapapi-render-") as tmp:
        data = Path(tmp) / "points.npy"
        np.save(data, np.asarray(points, dtype=np.float32))
        command = [sys.executable, "-m", __name__, str(data), str(output), f"--up={up.name}"]
        if box is not None:
            command += ["--box", *(repr(v) for v in box.as_tuple())]
        try:
            child = subprocess.run(command, capture_output=True, text=True, timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            _unavailable.append(f"no image in {TIMEOUT_S:g} s")
            return False
    if child.returncode != 0 or not Path(output).is_file():
        why = (child.stderr.strip().splitlines() or [f"exit status {child.returncode}"])[-1]
        _unavailable.append(why)
        log.info("no open3d renderer here (%s); drawing with matplotlib", why)
        return False
    return True


def _colours(heights: np.ndarray) -> np.ndarray:
    """RGB per point from its height (matplotlib's viridis, by the same stops)."""
    from matplotlib import colormaps

    span = float(heights.max() - heights.min()) or 1.0
    rgba = colormaps["viridis"]((heights - heights.min()) / span)
    return np.asarray(rgba[:, :3], dtype=np.float64)


def _box_lines(o3d: Any, box: BBox, up: Up, lo: np.ndarray, hi: np.ndarray) -> Any:
    """The box's edges, its top raised to the highest point (`lo`..`hi` bound
    them all) so that no point hides it from above."""
    mins, maxs = np.array(box.mins), np.array(box.maxs)
    if up.sign > 0:
        maxs[up.axis] = max(maxs[up.axis], hi[up.axis])
    else:
        mins[up.axis] = min(mins[up.axis], lo[up.axis])
    lines = o3d.geometry.LineSet.create_from_axis_aligned_bounding_box(
        o3d.geometry.AxisAlignedBoundingBox(mins, maxs)
    )
    lines.paint_uniform_color([1.0, 0.0, 0.0])
    return lines


def _render(points: np.ndarray, output: str, box: BBox | None, up: Up) -> None:
    import open3d as o3d

    rendering = o3d.visualization.rendering
    renderer = rendering.OffscreenRenderer(*SIZE)
    renderer.scene.set_background([1.0, 1.0, 1.0, 1.0])
    renderer.scene.view.set_post_processing(False)  # tone mapping would wash the colours out
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points.astype(np.float64)))
    cloud.colors = o3d.utility.Vector3dVector(_colours(up.height(points)))
    material = rendering.MaterialRecord()
    material.shader = "defaultUnlit"
    material.point_size = 3.0
    renderer.scene.add_geometry("cloud", cloud, material)
    lo, hi = points.min(axis=0), points.max(axis=0)
    if box is not None:
        lo, hi = np.minimum(lo, box.mins), np.maximum(hi, box.maxs)
        lines = rendering.MaterialRecord()
        lines.shader = "unlitLine"
        lines.line_width = 3.0
        renderer.scene.add_geometry("box", _box_lines(o3d, box, up, lo, hi), lines)
    centre, extent = (lo + hi) / 2, (hi - lo) * 1.05 + 1e-3
    u, v = plane_axes(up)
    aspect = SIZE[0] / SIZE[1]
    half_w = max(extent[u], extent[v] * aspect) / 2
    half_h = half_w / aspect
    depth = float(extent[up.axis]) + 10.0
    # look down from above along `up`, the picture's vertical axis pointing up as in `plot`
    eye = centre + np.eye(3)[up.axis] * up.sign * depth
    renderer.setup_camera(60.0, centre, eye, np.eye(3)[v])
    renderer.scene.camera.set_projection(
        rendering.Camera.Projection.Ortho, -half_w, half_w, -half_h, half_h, 0.1, 3 * depth
    )
    o3d.io.write_image(Path(output), renderer.render_to_image())


def main(argv: Sequence[str] | None = None) -> None:
    """The child process: render a saved point array to a PNG."""
    parser = argparse.ArgumentParser(prog="python -m mapapi.maps.render3d")
    parser.add_argument("points", help="an .npy file of (n, 3) float32 points")
    parser.add_argument("output", help="the PNG to write")
    parser.add_argument("--up", default="z", choices=UP_CHOICES[1:])
    parser.add_argument("--box", type=float, nargs=6)
    args = parser.parse_args(argv)
    box = BBox(*args.box) if args.box else None
    _render(np.load(args.points), args.output, box, choose_up([], args.up))


if __name__ == "__main__":
    main()
