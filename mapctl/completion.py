"""Shell completion: `mapctl completion bash|zsh|fish` and what TAB offers.

click completes commands and options by itself (`_MAPCTL_COMPLETE=bash_source
mapctl` prints the script). This module adds the repository's own words: table
names, view names, mission names, and chunk, commit and item ids, read from the
store of the repository found from the cwd or `-C`. Each TAB runs `mapctl`
again, so the callbacks only read the SQLite store (no peer, no daemon, no
network) and return nothing on any failure: a completion must never print an
error into the user's command line.

`register` attaches the callbacks centrally, by command path and parameter name
(`_COMPLETERS`), so the command modules stay free of completion code.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import click
from click.shell_completion import CompletionItem, get_completion_class

if TYPE_CHECKING:
    from mapapi import Store

SHELLS = ("bash", "zsh", "fish")
PROG, COMPLETE_VAR = "mapctl", "_MAPCTL_COMPLETE"
MAX_IDS = 200  # more ids than a terminal shows are noise; type more of the prefix
MAIN_VIEW = "main"  # the default of `--view`: always a valid answer, even before any edit

Completer = Callable[[click.Context, click.Parameter, str], list[CompletionItem]]


@contextlib.contextmanager
def _store(ctx: click.Context) -> Iterator[Store]:
    """The store of the repository the command line names (`-C`, else the cwd)."""
    from mapapi import Repository

    start = ctx.find_root().params.get("path") or Path(".")
    store = Repository.find(start).open_store()
    try:
        yield store
    finally:
        store.close()


def _quiet(complete: Callable[[click.Context, str], list[CompletionItem]]) -> Completer:
    """`complete` as a click callback that returns nothing instead of raising:
    outside a repository, on a damaged or locked store, TAB just offers nothing."""

    def callback(
        ctx: click.Context, param: click.Parameter, incomplete: str
    ) -> list[CompletionItem]:
        try:
            return complete(ctx, incomplete)
        except Exception:  # any failure means "no suggestions", by design
            return []

    callback.__doc__ = complete.__doc__
    return callback


def tables(ctx: click.Context, incomplete: str) -> list[CompletionItem]:
    """Table names, with their type as help."""
    with _store(ctx) as store:
        found = store.tables()
    return [CompletionItem(n, help=t) for n, t in sorted(found.items()) if n.startswith(incomplete)]


def views(ctx: click.Context, incomplete: str) -> list[CompletionItem]:
    """View names: the saved ones and `main`."""
    with _store(ctx) as store:
        names = set(store.views()) | {MAIN_VIEW}
    return [CompletionItem(n) for n in sorted(names) if n.startswith(incomplete)]


def missions(ctx: click.Context, incomplete: str) -> list[CompletionItem]:
    """Mission names held here, with their robot as help."""
    from mapapi import MISSIONS, Mission

    with _store(ctx) as store:
        if MISSIONS not in store.tables():
            return []
        rows = [Mission.FromString(r.data) for r in store.scan(store.clock(), table=MISSIONS)]
    return [
        CompletionItem(m.name, help=m.robot)
        for m in sorted(rows, key=lambda m: m.name)
        if m.name.startswith(incomplete)
    ]


def chunks(ctx: click.Context, incomplete: str) -> list[CompletionItem]:
    """Chunk ids starting with what was typed, with their table as help."""
    with _store(ctx) as store:
        found = store.chunks()
    hits = [CompletionItem(c.id, help=c.table) for c in found if c.id.startswith(incomplete)]
    return hits[:MAX_IDS]


def commits(ctx: click.Context, incomplete: str) -> list[CompletionItem]:
    """Commit ids starting with what was typed, newest first, with their message as help."""
    with _store(ctx) as store:
        found = store.commits()
    hits = [CompletionItem(c.id, help=c.message) for c in found if c.id.startswith(incomplete)]
    return hits[:MAX_IDS]


def items(ctx: click.Context, incomplete: str) -> list[CompletionItem]:
    """Ids of the items of the table named earlier on the line (`get TABLE <TAB>`)."""
    table = ctx.params.get("table_name")
    if not table:
        return []
    with _store(ctx) as store:
        found = store.scan(store.clock(), table=table)
    return [CompletionItem(r.item_id) for r in found if r.item_id.startswith(incomplete)][:MAX_IDS]


# (command path below `mapctl`, parameter name) -> what completes it; "" is `mapctl` itself.
# By path and not by parameter name alone: `import --mission` names a new mission.
_COMPLETERS: dict[tuple[str, str], Callable[[click.Context, str], list[CompletionItem]]] = {
    ("", "view_name"): views,
    ("chunk create", "table_name"): tables,
    ("chunk list", "table_name"): tables,
    ("chunk participate", "chunk_id"): chunks,
    ("chunk leave", "chunk_id"): chunks,
    ("set", "table_name"): tables,
    ("set", "chunk"): chunks,
    ("get", "table_name"): tables,
    ("get", "item"): items,
    ("ls", "table_name"): tables,
    ("ls", "chunk"): chunks,
    ("rm", "table_name"): tables,
    ("rm", "item"): items,
    ("log", "table_name"): tables,
    ("log", "item"): items,
    ("show", "commit_ref"): commits,
    ("query-bbox", "table"): tables,
    ("watch", "table"): tables,
    ("export", "mission"): missions,
    ("plot", "names"): missions,
}


def _commands(group: click.Group, path: str = "") -> Iterator[tuple[str, click.Command]]:
    """Every command below `group` (and `group` itself), with its path."""
    yield path, group
    for name, command in group.commands.items():
        below = f"{path} {name}".strip()
        if isinstance(command, click.Group):
            yield from _commands(command, below)
        else:
            yield below, command


def attach(cli: click.Group) -> list[tuple[str, str]]:
    """Give the parameters listed in `_COMPLETERS` their completion callback.

    Returns:
        The (command path, parameter) pairs that got one.

    Raises:
        LookupError: a listed parameter is missing, so a rename cannot silently
            turn completion off.
    """
    found = {
        (path, param.name): param for path, command in _commands(cli) for param in command.params
    }
    missing = sorted(set(_COMPLETERS) - set(found))
    if missing:
        raise LookupError(f"completion for unknown parameters {missing}; update _COMPLETERS")
    for key, complete in _COMPLETERS.items():
        # click keeps a `shell_complete=` callback here; the commands are built by
        # decorators elsewhere, so it is set once, at start-up, before any parsing.
        found[key]._custom_shell_complete = _quiet(complete)
    return sorted(_COMPLETERS)


@click.command("completion")
@click.argument("shell", type=click.Choice(SHELLS))
@click.pass_context
def completion(ctx: click.Context, shell: str) -> None:
    """Print the completion script for SHELL (bash, zsh or fish).

    It completes commands and options, and table, view and mission names and
    chunk, commit and item ids of the repository you are in (or of -C). Load it
    from your shell's start-up file; see docs/guide/completion.md, e.g. for bash:
    eval "$(mapctl completion bash)" in ~/.bashrc.
    """
    script_class = get_completion_class(shell)
    assert script_class is not None  # click ships all of SHELLS
    script = script_class(ctx.find_root().command, {}, PROG, COMPLETE_VAR)
    click.echo(script.source())


def register(cli: click.Group) -> None:
    """Add `completion` to `cli` and attach the completion callbacks."""
    cli.add_command(completion)
    attach(cli)
