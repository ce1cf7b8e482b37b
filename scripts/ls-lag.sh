#!/usr/bin/env bash
# How late a daemon's loop runs while `mapctl ls` lists two big tables (docs/benchmarks.md,
# "`mapctl ls` of a big table"): a fresh repository with a random walk of POSES poses (2·POSES
# rows), its daemon started, then `ls edges` and `ls vertices` while `peer status` is polled.
#   bash scripts/ls-lag.sh            # 25,000 poses
#   bash scripts/ls-lag.sh 5000
set -euo pipefail
cd "$(dirname "$0")/.."
poses=${1:-25000}
py=${PY:-.venv/bin/python}
tmp=$(mktemp -d)
trap 'PYTHONPATH=. "$py" -m mapctl -C "$tmp/r" peer stop >/dev/null 2>&1 || true; rm -rf "$tmp"' EXIT
m() { PYTHONPATH=. "$py" -m mapctl -C "$tmp/r" "$@"; }
lag() { m peer status --json | "$py" -c "import json,sys; print(json.load(sys.stdin)['loop_lag_ms'])"; }
PYTHONPATH=. "$py" -c "from mapbench.stall import write_walk; from pathlib import Path; write_walk(Path('$tmp/walk.g2o'), $poses, (0.0, 0.0))"
PYTHONPATH=. "$py" -m mapctl init "$tmp/r" --name r >/dev/null
m import "$tmp/walk.g2o" >/dev/null
m peer start --detach --json >/dev/null
echo "before: $(lag)"
started=$(date +%s.%N)
(m ls edges --json >/dev/null; m ls vertices --json >/dev/null) &
while kill -0 $! 2>/dev/null; do sleep 0.5; lag >/dev/null; done
echo "ls took $(echo "$(date +%s.%N) - $started" | bc) s; lag over the last minute: $(lag)"
