#!/usr/bin/env bash
# The swarm figures of docs/benchmarks.md: the transport's round trip, then
# `mapctl bench viewtest` for P = 1, 2, 4 and `mapctl bench commit` for
# K = 1..8 (the writer a follower, and the leader), RUNS times each, as JSON lines under OUT,
# and the two PNG plots made from them. Takes about 10 minutes; run it on an
# otherwise idle machine (every JSON line records the load average it saw).
#
#   bash scripts/bench-swarm.sh                 # RUNS=3 N=300 COMMITS=500 OUT=docs/img
#   RUNS=1 N=100 OUT=/tmp/swarm bash scripts/bench-swarm.sh
set -euo pipefail
cd "$(dirname "$0")/.."

PY=${PY:-.venv/bin/python}
MAPCTL=${MAPCTL:-.venv/bin/mapctl}
RUNS=${RUNS:-3}
N=${N:-300}
COMMITS=${COMMITS:-500}
OUT=${OUT:-docs/img}
mkdir -p "$OUT"

echo "== transport round trip" >&2
"$PY" -m mapbench.net -n 10000 --json > "$OUT/swarm-roundtrip.json"
cat "$OUT/swarm-roundtrip.json" >&2

: > "$OUT/swarm-viewtest.jsonl"
: > "$OUT/swarm-commit.jsonl"
for run in $(seq "$RUNS"); do
    for p in 1 2 4; do
        echo "== run $run: viewtest --peers $p -n $N" >&2
        "$MAPCTL" bench viewtest --peers "$p" -n "$N" --json >> "$OUT/swarm-viewtest.jsonl"
    done
    for k in 1 2 3 4 5 6 7 8; do
        for writer in follower leader; do
            if [ "$k" = 1 ] && [ "$writer" = follower ]; then
                continue  # one holder: the writer leads its group
            fi
            echo "== run $run: commit --holders $k --writer $writer -n $COMMITS" >&2
            "$MAPCTL" bench commit --holders "$k" --writer "$writer" -n "$COMMITS" --json \
                >> "$OUT/swarm-commit.jsonl"
        done
    done
done

"$MAPCTL" bench plot viewtest "$OUT/swarm-viewtest.jsonl" -o "$OUT/swarm-viewtest.png"
"$MAPCTL" bench plot commit "$OUT/swarm-commit.jsonl" -o "$OUT/swarm-commit.png"
echo "wrote $OUT/swarm-viewtest.png and $OUT/swarm-commit.png" >&2
