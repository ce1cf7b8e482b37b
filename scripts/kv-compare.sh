#!/usr/bin/env bash
# Paper Algorithm 1 (P processes x N optimistic increments of one counter) against
# Redis WATCH/MULTI/EXEC and a 3-member etcd cluster (txn comparing mod_revision),
# both on 127.0.0.1, then `mapctl bench viewtest` for the same P and N, on this
# machine; prints a Markdown table (commits/s, aborts per commit, p50, p99).
# The servers run from a scratch folder on ports picked at start, and are
# stopped afterwards (each also dies with the script). Needs the Debian packages
# redis-server and etcd-server (`apt-get install -y redis-server etcd-server`).
#
#   bash scripts/kv-compare.sh                        # N=300, P = 1, 2, 4
#   bash scripts/kv-compare.sh -n 1000 --only redis,etcd
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" exec "$PY" -m mapbench.kv_compare "$@"
