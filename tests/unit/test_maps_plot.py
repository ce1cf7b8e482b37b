"""Top-down pictures (mapapi.maps.plot, render3d): the axis looked down, PNGs of
graphs and clouds, and the fall back to matplotlib where open3d cannot render."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mapapi.core.errors import UsageError
from mapapi.lookup.spatial import BBox
from mapapi.maps import PointCloud, read_g2o, read_kimera, render3d
from mapapi.maps.plot import plot_map
from mapapi.maps.view_axes import Up, choose_up, plane_axes, up_from_poses

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
PNG = b"\x89PNG\r\n\x1a\n"


def cloud(n: int = 2_000) -> PointCloud:
    points = np.random.default_rng(5).uniform([-5, -5, 0], [5, 5, 2], size=(n, 3))
    return PointCloud("scan", points=points.astype(np.float32))


@pytest.fixture(autouse=True)
def fresh_renderer(monkeypatch: pytest.MonkeyPatch) -> None:
    """Each test finds out anew whether open3d renders here."""
    monkeypatch.setattr(render3d, "_unavailable", [])


def trajectory(body_forward: int, up_axis: int, up_sign: int, n: int = 40) -> np.ndarray:
    """(n, 7) poses of a robot driving a left-turning arc on the floor of a frame
    whose up is (`up_axis`, `up_sign`), its body moving along `body_forward`
    (0: REP 103, x forward and z up; 2: a camera, z forward and y down)."""
    up = np.eye(3)[up_axis] * up_sign
    ahead = np.eye(3)[(up_axis + 1) % 3]
    left = np.cross(up, ahead)
    poses = []
    for i in range(n):
        heading = 0.05 * i
        forward = np.cos(heading) * ahead + np.sin(heading) * left
        side = np.cross(up, forward)  # the robot's left
        # body x, y, z in the map: REP 103 (x ahead, z up) or a camera (x right, y down)
        rotation = np.column_stack(
            [forward, side, up] if body_forward == 0 else [-side, -up, forward]
        )
        position = 2.0 * (np.sin(heading) * ahead + (1 - np.cos(heading)) * left) * 10
        poses.append([*position, *_quaternion(rotation)])
    return np.array(poses)


def _quaternion(m: np.ndarray) -> list[float]:
    """(x, y, z, w) of a proper rotation matrix with a positive trace or near it."""
    w = np.sqrt(max(0.0, 1.0 + np.trace(m))) / 2
    if w > 1e-3:
        return [
            (m[2, 1] - m[1, 2]) / (4 * w),
            (m[0, 2] - m[2, 0]) / (4 * w),
            (m[1, 0] - m[0, 1]) / (4 * w),
            w,
        ]
    # trace near -1: a half turn; take the largest diagonal's axis
    i = int(np.argmax(np.diag(m)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = np.sqrt(max(0.0, 1.0 + m[i, i] - m[j, j] - m[k, k])) * 2
    q = [0.0, 0.0, 0.0, (m[k, j] - m[j, k]) / s]
    q[i], q[j], q[k] = s / 4, (m[j, i] + m[i, j]) / s, (m[k, i] + m[i, k]) / s
    return q


class TestAxes:
    def test_without_poses_the_thinnest_axis_is_up(self) -> None:
        assert choose_up([BBox(0, 0, 0, 30, 20, 1)]) == Up(2)
        assert choose_up([BBox(0, -1, 0, 30, 2, 40)]) == Up(1)
        assert choose_up([BBox(0, 0, 0, 30, 20, 1)], "x") == Up(0)
        assert choose_up([BBox(0, 0, 0, 30, 20, 1)], "-y") == Up(1, -1)
        with pytest.raises(UsageError, match="auto, x, y, z, -x, -y, -z"):
            choose_up([], "w")

    @pytest.mark.parametrize("body", [0, 2])
    @pytest.mark.parametrize("axis", [0, 1, 2])
    @pytest.mark.parametrize("sign", [1, -1])
    def test_the_poses_tell_the_signed_up(self, body: int, axis: int, sign: int) -> None:
        poses = trajectory(body, axis, sign)
        box = BBox(*poses[:, :3].min(axis=0), *poses[:, :3].max(axis=0))
        assert choose_up([box], "auto", [poses]) == Up(axis, sign)

    def test_real_maps_are_seen_from_above(self) -> None:
        tunnels = read_kimera(SAMPLES / "kimera_multi_tunnels_8robots")
        garage = read_g2o(SAMPLES / "pose_graphs" / "parking-garage.g2o")
        intel = read_g2o(SAMPLES / "pose_graphs" / "intel.g2o")
        for graphs, up in (
            (tunnels, Up(1, -1)),  # cameras: y down, so the map's up is -y
            ([garage], Up(2)),
            ([intel], Up(2)),
        ):
            poses = [np.array([g.vertices[k] for k in sorted(g.vertices)]) for g in graphs]
            assert up_from_poses(poses) == up

    def test_a_trajectory_standing_still_tells_nothing(self) -> None:
        still = np.tile([1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0], (10, 1))
        assert up_from_poses([still]) is None
        assert choose_up([BBox(0, 0, 0, 30, 20, 1)], "auto", [still]) == Up(2)

    @pytest.mark.parametrize("up", [Up(a, s) for a in range(3) for s in (1, -1)])
    def test_the_picture_axes_are_right_handed_about_up(self, up: Up) -> None:
        u, v = plane_axes(up)
        normal = np.cross(np.eye(3)[u], np.eye(3)[v])
        assert normal.tolist() == (np.eye(3)[up.axis] * up.sign).tolist()


class TestPlot:
    def test_graphs_with_a_query_box(self, tmp_path: Path) -> None:
        out = tmp_path / "tunnels.png"
        graphs = read_kimera(SAMPLES / "kimera_multi_tunnels_8robots")

        drawn = plot_map(out, graphs, box=BBox(-50, -10, 0, 0, 10, 50))

        assert (drawn.renderer, drawn.up) == ("matplotlib", "-y")
        assert drawn.missions == [f"robot{i}" for i in range(8)]
        assert out.read_bytes().startswith(PNG)

    def test_a_graph_and_a_cloud_together_use_matplotlib(self, tmp_path: Path) -> None:
        out = tmp_path / "both.png"
        drawn = plot_map(out, [read_g2o(SAMPLES / "pose_graphs" / "intel.g2o")], [cloud()])
        assert (drawn.renderer, drawn.up, drawn.missions) == ("matplotlib", "z", ["intel", "scan"])
        assert out.read_bytes().startswith(PNG)

    def test_without_matplotlib_the_error_says_what_to_install(
        self, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        monkeypatch.setitem(sys.modules, "matplotlib.figure", None)  # import raises ImportError
        graph = read_g2o(SAMPLES / "pose_graphs" / "intel.g2o")
        with pytest.raises(UsageError, match=r"pip install 'mapapi\[plot\]'"):
            plot_map(tmp_path / "x.png", [graph])

    def test_nothing_to_draw_is_a_usage_error(self, tmp_path: Path) -> None:
        with pytest.raises(UsageError, match="nothing to plot"):
            plot_map(tmp_path / "x.png")

    def test_a_cloud_is_drawn_whatever_this_machine_renders(self, tmp_path: Path) -> None:
        out = tmp_path / "cloud.png"
        drawn = plot_map(out, clouds=[cloud()], box=BBox(0, 0, 0, 2, 2, 1))
        assert drawn.renderer in ("open3d", "matplotlib")
        assert out.read_bytes().startswith(PNG)

    def test_a_failing_renderer_falls_back_once_then_is_not_asked_again(
        self, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        calls: list[list[str]] = []

        def crash(command: list[str], **kwargs: Any) -> subprocess.CompletedProcess[str]:
            calls.append(command)
            return subprocess.CompletedProcess(command, -6, "", "Failed to load vulkan library!")

        monkeypatch.setattr(render3d.subprocess, "run", crash)
        first = plot_map(tmp_path / "a.png", clouds=[cloud()])
        second = plot_map(tmp_path / "b.png", clouds=[cloud()])

        assert (first.renderer, second.renderer) == ("matplotlib", "matplotlib")
        assert len(calls) == 1
        assert render3d._unavailable == ["Failed to load vulkan library!"]
        assert (tmp_path / "b.png").read_bytes().startswith(PNG)

    def test_the_renderer_can_be_switched_off(
        self, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        monkeypatch.setenv("MAPAPI_RENDER3D", "0")
        monkeypatch.setattr(render3d.subprocess, "run", None)  # never called
        assert plot_map(tmp_path / "c.png", clouds=[cloud()]).renderer == "matplotlib"


class TestZoomLabelsTitle:
    @pytest.fixture
    def saved(self, monkeypatch: pytest.MonkeyPatch) -> list[Any]:
        """The figures plot_map saves (each also written as usual)."""
        from matplotlib.figure import Figure

        figures: list[Any] = []
        save = Figure.savefig

        def keep(figure: Any, *args: Any, **kwargs: Any) -> None:
            figures.append(figure)
            save(figure, *args, **kwargs)

        monkeypatch.setattr(Figure, "savefig", keep)
        return figures

    def test_zoom_shows_the_box_and_a_margin_only(self, tmp_path: Path, saved: list[Any]) -> None:
        graphs = read_kimera(SAMPLES / "kimera_multi_tunnels_8robots")
        box = BBox(-15, -15, -15, 15, 15, 15)

        plot_map(tmp_path / "zoom.png", graphs, box=box, zoom=True)

        (ax,) = saved[0].axes
        assert ax.get_xlim() == pytest.approx((-22.5, 22.5))  # from above along -y: x across
        assert ax.get_ylim() == pytest.approx((-22.5, 22.5))
        assert "vertices in the box" in ax.get_legend_handles_labels()[1]

    def test_labels_name_the_legend_and_the_title_is_kept(
        self, tmp_path: Path, saved: list[Any]
    ) -> None:
        graphs = read_kimera(SAMPLES / "kimera_multi_tunnels_8robots")[:2]
        labels = {"robot0": "robot0 (from alpha)"}

        plot_map(tmp_path / "labels.png", graphs, labels=labels, title="two robots")

        (ax,) = saved[0].axes
        assert ax.get_title() == "two robots"
        assert ax.get_legend_handles_labels()[1][:2] == ["robot0 (from alpha)", "robot1"]

    def test_axes_are_named_as_seen_from_above(self, tmp_path: Path, saved: list[Any]) -> None:
        plot_map(tmp_path / "t.png", read_kimera(SAMPLES / "kimera_multi_tunnels_8robots"))
        plot_map(tmp_path / "i.png", [read_g2o(SAMPLES / "pose_graphs" / "intel.g2o")])

        tunnels, intel = (figure.axes[0] for figure in saved)
        assert (tunnels.get_xlabel(), tunnels.get_ylabel()) == ("x [m] (map x)", "y [m] (map z)")
        assert tunnels.get_title() == "top-down view (up: the map's -y)"
        assert (intel.get_xlabel(), intel.get_ylabel()) == ("x [m]", "y [m]")

    def test_the_legend_hides_no_part_of_the_map(self, tmp_path: Path, saved: list[Any]) -> None:
        plot_map(tmp_path / "t.png", read_kimera(SAMPLES / "kimera_multi_tunnels_8robots"))

        (ax,) = saved[0].axes
        legend, bar = ax.get_legend(), next(a for a in ax.artists if "m" in a.txt_label.get_text())
        assert not legend.get_window_extent().overlaps(ax.get_window_extent())
        assert ax.get_window_extent().contains(*bar.get_window_extent().p0)

    def test_zoom_needs_a_box(self, tmp_path: Path) -> None:
        with pytest.raises(UsageError, match="zoom needs a box"):
            plot_map(
                tmp_path / "x.png", [read_g2o(SAMPLES / "pose_graphs" / "intel.g2o")], zoom=True
            )

    def test_a_zoomed_cloud_is_drawn_with_matplotlib(self, tmp_path: Path) -> None:
        drawn = plot_map(
            tmp_path / "c.png", clouds=[cloud()], box=BBox(0, 0, 0, 2, 2, 1), zoom=True
        )
        assert drawn.renderer == "matplotlib"
