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
from mapapi.maps.view_axes import choose_up, plane_axes

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
PNG = b"\x89PNG\r\n\x1a\n"


def cloud(n: int = 2_000) -> PointCloud:
    points = np.random.default_rng(5).uniform([-5, -5, 0], [5, 5, 2], size=(n, 3))
    return PointCloud("scan", points=points.astype(np.float32))


@pytest.fixture(autouse=True)
def fresh_renderer(monkeypatch: pytest.MonkeyPatch) -> None:
    """Each test finds out anew whether open3d renders here."""
    monkeypatch.setattr(render3d, "_unavailable", [])


class TestAxes:
    def test_the_thinnest_axis_is_up(self) -> None:
        assert choose_up([BBox(0, 0, 0, 30, 20, 1)]) == 2
        assert choose_up([BBox(0, -1, 0, 30, 2, 40)]) == 1  # the tunnels: camera axes
        assert choose_up([BBox(0, 0, 0, 30, 20, 1)], "x") == 0
        with pytest.raises(UsageError, match="auto, x, y or z"):
            choose_up([], "w")

    def test_the_picture_axes_are_right_handed(self) -> None:
        for up in range(3):
            u, v = plane_axes(up)
            assert np.cross(np.eye(3)[u], np.eye(3)[v]).tolist() == np.eye(3)[up].tolist()


class TestPlot:
    def test_graphs_with_a_query_box(self, tmp_path: Path) -> None:
        out = tmp_path / "tunnels.png"
        graphs = read_kimera(SAMPLES / "kimera_multi_tunnels_8robots")

        drawn = plot_map(out, graphs, box=BBox(-50, -10, 0, 0, 10, 50))

        assert (drawn.renderer, drawn.up) == ("matplotlib", "y")
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
        assert ax.get_xlim() == pytest.approx((-22.5, 22.5))  # looking down y: z across
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
