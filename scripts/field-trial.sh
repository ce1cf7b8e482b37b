#!/usr/bin/env bash
# The field-scale trial to run before swarm or maps work is called done
# (docs/benchmarks.md, "Field-scale trial"): three daemons on loopback, each
# importing COPIES copies of the 13,631-pose Intel graph made from the raw laser
# log; b and c load the others' missions; then reads on a (`missions`, `export`,
# `plot`, `missions --swarm`) while b imports one more copy and c commits five
# edits to one of a's vertices; then all three stopped and started again with no
# --join, a last edit from c, and every peer.log read for suspicions, deaths,
# removals and errors. Before the restart it prints each daemon's peak memory.
# Ends with one line per check; exit 1 if the histories differ.
#
#   bash scripts/field-trial.sh                       # COPIES=2
#   KEEP=1 bash scripts/field-trial.sh                # keep the repositories
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
MAPCTL=${MAPCTL:-"$ROOT/.venv/bin/mapctl"}
PY=${PY:-"$ROOT/.venv/bin/python"}
COPIES=${COPIES:-2}
LASER_LOG=${LASER_LOG:-"$ROOT/../shared/datasets/radish_laser_logs/intel.clf.bz2"}
DIR=$(mktemp -d)
stop_all() { for r in a b c; do "$MAPCTL" -C "$DIR/$r" peer stop >/dev/null 2>&1 || true; done; }
trap 'stop_all; if [ -z "${KEEP:-}" ]; then rm -rf "$DIR"; else echo "kept $DIR"; fi' EXIT
"$PY" -m mapbench.carmen "$LASER_LOG" "$DIR/intel.g2o" >/dev/null
cd "$DIR"

now() { date +%s.%N; }
since() { python3 -c "print(round($(now) - $1, 2))"; }
field() { python3 -c "import json, sys; d = json.load(sys.stdin); print($1)"; }
timed() {  # timed LABEL COMMAND...: run it quietly, print how long it took
    local label=$1 began
    shift
    began=$(now)
    "$@" >/dev/null
    echo "$label: $(since "$began") s"
}

for r in a b c; do "$MAPCTL" init "$r" --name "$r" >/dev/null; done
join=$("$MAPCTL" -C a peer start --detach --json | field 'd["join"]')
for r in b c; do "$MAPCTL" -C "$r" peer start --detach --join "$join" >/dev/null; done

for r in a b c; do
    for i in $(seq "$COPIES"); do
        began=$(now)
        "$MAPCTL" -C "$r" import intel.g2o --mission "$r$i" --robot "$r" --json > "import-$r$i.json"
        echo "import of $r$i (27,261 rows) on $r: $(since "$began") s"
    done
done
box=(-- -100 -100 -10 100 100 10)
began=$(now)  # a box of 15 x 12.5 m, 5 % of a mission's 66 x 56 m: its tiles only
small=$("$MAPCTL" -C c query-bbox --load --json -- 0 -10 -10 15 2.5 10 | field '"%d chunks, %d rows, %d bytes" % (len(d["loaded"]), d["items"], d["bytes"])')
echo "query-bbox --load of a 5 % box on c: $small in $(since "$began") s"
timed "query-bbox --load on b (the others' missions)" "$MAPCTL" -C b query-bbox --load "${box[@]}"
timed "query-bbox --load on c (the others' missions)" "$MAPCTL" -C c query-bbox --load "${box[@]}"

# One of a's vertices, for c to edit.
vertices=$(field 'd["missions"][0]["tiles"][0]["vertices"]' < import-a1.json)
vertex=$("$MAPCTL" -C c ls vertices --chunk "$vertices" --json | field 'd["items"][0]["id"]')
edit() {  # edit N: c moves the vertex to x = N and commits
    "$MAPCTL" -C c get vertices "$vertex" --json \
        | field "json.dumps({**d, 'pose': {**d['pose'], 'x': $1}})" \
        | "$MAPCTL" -C c set vertices "$vertex" - >/dev/null
    "$MAPCTL" -C c commit -m "x = $1" >/dev/null
}

(
    began=$(now)
    "$MAPCTL" -C b import intel.g2o --mission b-more --robot b >/dev/null
    echo "meanwhile, import of b-more on b: $(since "$began") s"
) &
importing=$!
(
    for n in 1 2 3 4 5; do
        began=$(now)
        edit "$n"
        echo "meanwhile, edit $n of a's vertex on c: $(since "$began") s"
    done
) &
editing=$!
timed "missions on a" "$MAPCTL" -C a missions
timed "export of a1 on a" "$MAPCTL" -C a export a1 -o a1.g2o
timed "plot on a" "$MAPCTL" -C a plot -o a.png
timed "missions --swarm on a" "$MAPCTL" -C a missions --swarm
wait "$importing" "$editing"
"$MAPCTL" -C a peer status --json | field '"loop lag on a over the last minute, ms: %s" % d["loop_lag_ms"]'

for r in a b c; do  # the most each daemon held in memory so far (issue 14 §5: <= 250 MB)
    pid=$("$MAPCTL" -C "$r" peer status --json | field 'd["pid"]')
    echo "peak resident memory of $r's daemon: $(awk '/VmHWM/ {print int($2 / 1024)}' "/proc/$pid/status") MB"
done

stop_all
for r in a b c; do "$MAPCTL" -C "$r" peer start --detach >/dev/null; done
began=$(now)
until edit 6 2>/dev/null; do "$MAPCTL" -C c view abort >/dev/null 2>&1 || true; done
echo "after the restart with no --join, the first edit on c: $(since "$began") s"

heads=""
for r in a b c; do
    x=$("$MAPCTL" -C "$r" get vertices "$vertex" --json | field 'd["pose"]["x"]')
    head=$("$MAPCTL" -C "$r" log vertices --json | field 'd[0]["commit"]')
    echo "$r reads x = $x, newest commit of vertices $head"
    heads="$heads $head:$x"
done
logs=$(cat ./*/.mapapi/peer.log)
for what in suspect "is dead" removed ERROR Traceback; do
    echo "'$what' in the peers' logs: $(grep -c "$what" <<< "$logs" || true)"
done
if [ "$(tr ' ' '\n' <<< "$heads" | sort -u | grep -c .)" != 1 ]; then
    echo "the histories differ:$heads"
    exit 1
fi
echo "one history:$heads"
