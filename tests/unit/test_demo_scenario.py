"""The pure parts of `mapctl demo` (mapbench.demo.scenario): which robots each peer imports."""

from pathlib import Path

import pytest

from mapbench.demo import TUNNELS
from mapbench.demo.scenario import DemoFailed, robot_files, share


def test_the_tunnels_robots_are_found_in_number_order(tmp_path: Path) -> None:
    assert [p.parent.name for p in robot_files(TUNNELS)] == [f"robot{i}" for i in range(8)]
    for n in (10, 9, 2):
        (tmp_path / f"robot{n}").mkdir()
        (tmp_path / f"robot{n}" / "measurements.csv").write_text("")
    assert [p.parent.name for p in robot_files(tmp_path)] == ["robot2", "robot9", "robot10"]


def test_a_folder_without_robots_is_refused(tmp_path: Path) -> None:
    with pytest.raises(DemoFailed, match="no robot"):
        robot_files(tmp_path)


@pytest.mark.parametrize(("peers", "sizes"), [(3, [3, 3, 2]), (4, [2, 2, 2, 2])])
def test_every_peer_gets_a_contiguous_share(peers: int, sizes: list[int]) -> None:
    files = [Path(f"robot{i}") for i in range(8)]
    shares = share(files, peers)
    assert [len(s) for s in shares] == sizes
    assert [f for s in shares for f in s] == files
