#!/usr/bin/env bash
# Run the README's CLI tour, exactly as printed, in a fresh temporary folder.
# The tour is the bash block between the `tour:begin` and `tour:end` markers.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
export PATH="$here/.venv/bin:$PATH"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
tour=$(sed -n '/<!-- tour:begin -->/,/<!-- tour:end -->/p' "$here/README.md" | sed '/^<!--/d; /^```/d')
cd "$work"
echo "== the README tour, in $work"
bash -euo pipefail -x -c "$tour"
echo "== tour finished"
