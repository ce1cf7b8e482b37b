#!/usr/bin/env bash
# Run the examples of the guide, as printed, each page in a fresh temporary folder.
#
#   bash docs/run-examples.sh                 # every page of docs/guide/
#   bash docs/run-examples.sh docs/guide/views.md
#
# A page's ```bash blocks run in order as one script (so `cd` and variables carry
# over from block to block); every ```python block is saved as its own file and run
# with the project's Python at the point where it appears. ```text and ```console
# blocks are output and transcripts: shown, not run; so are ```sh, ```zsh and ```fish
# blocks, for lines the reader runs once by hand (completion.md: editing ~/.bashrc). A command that is meant to
# fail is written `cmd || echo "exit $?"` in the page itself.
#
# A page must stop the peer daemons it starts (`mapctl -C DIR peer stop`). Any
# daemon still running in the page's folder afterwards is stopped here, and the
# page fails; so does a page whose script fails, which leaves its folder for a look.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
export PATH="$here/.venv/bin:$PATH"

# Stop every peer daemon that still runs in a repository under $1 (say which);
# returns 1 if there was one.
stop_peers() {
    local pidfile repo left=0
    while IFS= read -r pidfile; do
        repo=$(dirname "$(dirname "$pidfile")")
        if mapctl -C "$repo" peer status --json 2> /dev/null | grep -q '"running": true'; then
            echo "== a peer daemon was left running in $repo; stopping it" >&2
            mapctl -C "$repo" peer stop > /dev/null || true
            left=1
        fi
    done < <(find "$1" -path '*/.mapapi/peer.pid' 2> /dev/null)
    return $left
}

work=""
trap '[ -z "$work" ] || stop_peers "$work" || true' EXIT
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
    status=0
    (cd "$work" && bash -euo pipefail -x "$script") || status=$?
    if ! stop_peers "$work" && [ "$status" = 0 ]; then
        status=1
    fi
    if [ "$status" != 0 ]; then
        echo "== $page failed (status $status); its folder is kept: $work" >&2
        exit "$status"
    fi
    rm -rf "$work"
    work=""
done
echo "== all examples ran"
