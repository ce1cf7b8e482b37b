#!/usr/bin/env bash
# Run the examples of the guide, as printed, each page in a fresh temporary folder.
#
#   bash docs/run-examples.sh                 # every page of docs/guide/
#   bash docs/run-examples.sh docs/guide/views.md
#
# A page's ```bash blocks run in order as one script (so `cd` and variables carry
# over from block to block); every ```python block is saved as its own file and run
# with the project's Python at the point where it appears. ```text and ```console
# blocks are output and transcripts: shown, not run. A command that is meant to
# fail is written `cmd || echo "exit $?"` in the page itself.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
export PATH="$here/.venv/bin:$PATH"
pages=("$@")
[ ${#pages[@]} -gt 0 ] || pages=("$here"/docs/guide/*.md)
for page in "${pages[@]}"; do
    page=$(cd "$(dirname "$page")" && pwd)/$(basename "$page")
    work=$(mktemp -d)
    script="$work/.page.sh"
    awk -v dir="$work" '
        /^```bash$/   { mode = "bash"; next }
        /^```python$/ { mode = "python"; n++; file = dir "/.snippet" n ".py"; next }
        /^```/        { if (mode == "python") print "python " file; mode = ""; next }
        mode == "bash"   { print }
        mode == "python" { print > file }
    ' "$page" > "$script"
    echo "== $page (in $work)"
    (cd "$work" && bash -euo pipefail -x "$script")
    rm -rf "$work"
done
echo "== all examples ran"
