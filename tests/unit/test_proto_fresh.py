"""The checked-in `mapapi/_pb/` is exactly what `make proto` makes from `proto/`.

Fails when someone edits a `.proto` file without regenerating (STYLE §8).
"""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CHECKED_IN = ROOT / "mapapi" / "_pb"


def files_under(folder: Path) -> dict[str, bytes]:
    return {
        str(path.relative_to(folder)): path.read_bytes()
        for path in sorted(folder.rglob("*"))
        if path.is_file() and "__pycache__" not in path.parts
    }


class TestGeneratedProtobuf:
    def test_regenerating_from_proto_changes_nothing(self, tmp_path: Path) -> None:
        out = tmp_path / "pb"
        done = subprocess.run(
            ["bash", "scripts/gen-proto.sh", str(out)],
            cwd=ROOT,
            env={**os.environ, "PY": sys.executable},
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert done.returncode == 0, f"gen-proto.sh failed:\n{done.stdout}{done.stderr}"
        fresh, committed = files_under(out), files_under(CHECKED_IN)
        assert any(name.endswith("_pb2.py") for name in fresh)
        stale = sorted(name for name in fresh if committed.get(name) != fresh[name])
        assert not stale, f"mapapi/_pb is out of date for {stale}; run `make proto`"
        extra = sorted(set(committed) - set(fresh))
        assert not extra, f"mapapi/_pb has files no .proto generates: {extra}"
