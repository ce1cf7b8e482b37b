#!/usr/bin/env bash
# How soon a whole swarm commits again after every peer was stopped and started
# with no --join (issue 13 §3; docs/benchmarks.md, "A whole swarm restarted"):
# three daemons hold one chunk; each round stops all three, starts all three
# (`peer start --detach` returns once a daemon serves), then times `set` and
# `commit` on the third, retried while they fail. Prints one line per round and
# the count of suspicions, deaths and removals in the peers' logs.
#
#   bash scripts/swarm-restart.sh            # ROUNDS=3
set -euo pipefail
cd "$(dirname "$0")/.."
MAPCTL=${MAPCTL:-"$PWD/.venv/bin/mapctl"}
ROUNDS=${ROUNDS:-3}
DIR=$(mktemp -d)
trap 'for r in a b c; do "$MAPCTL" -C "$DIR/$r" peer stop >/dev/null 2>&1 || true; done; rm -rf "$DIR"' EXIT
cd "$DIR"

for r in a b c; do "$MAPCTL" init "$r" --name "$r" >/dev/null; done
join=$("$MAPCTL" -C a peer start --detach --json | python3 -c 'import json, sys; print(json.load(sys.stdin)["join"])')
for r in b c; do "$MAPCTL" -C "$r" peer start --detach --join "$join" >/dev/null; done
"$MAPCTL" -C a table create pts --type google.protobuf.Struct >/dev/null
chunk=$("$MAPCTL" -C a chunk create pts)
item=$("$MAPCTL" -C a set pts '{"n": 0}' --json | python3 -c 'import json, sys; print(json.load(sys.stdin)["id"])')
"$MAPCTL" -C a commit -m zero >/dev/null
for r in b c; do "$MAPCTL" -C "$r" chunk participate "$chunk" >/dev/null; done

for round in $(seq "$ROUNDS"); do
    for r in a b c; do "$MAPCTL" -C "$r" peer stop >/dev/null; done
    for r in a b c; do "$MAPCTL" -C "$r" peer start --detach >/dev/null; done
    began=$(date +%s.%N)
    failed=0
    until "$MAPCTL" -C c set pts "$item" "{\"n\": $round}" >/dev/null 2>&1 \
        && "$MAPCTL" -C c commit -m "round $round" >/dev/null 2>&1; do
        failed=$((failed + 1))
        "$MAPCTL" -C c view abort >/dev/null 2>&1 || true
        if [ "$failed" -gt 150 ]; then echo "round $round: no commit after 150 attempts"; exit 1; fi
    done
    ended=$(date +%s.%N)
    echo "round $round: first commit $(python3 -c "print(round($ended - $began, 2))") s after the last start, $failed failed attempts"
done
echo "suspicions, deaths and removals in the peers' logs: $(cat ./*/.mapapi/peer.log | grep -c 'suspect\|is dead\|removed' || true)"
