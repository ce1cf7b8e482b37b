"""The `mapctl` click group, its global options and the single error boundary."""

from __future__ import annotations

import sys
import traceback
from pathlib import Path

import click

from mapctl import completion
from mapctl.commands import (
    align,
    bench,
    demo,
    history,
    imports,
    lookup,
    maps,
    peer,
    repo,
    security,
    view,
    watch,
)
from mapctl.session import Session

EXIT_USAGE, EXIT_INTERRUPTED = 2, 130


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option(
    "-C",
    "path",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("."),
    metavar="DIRECTORY",
    help="Run as if started in DIRECTORY (like git -C).",
)
@click.option(
    "--view",
    "view_name",
    default="main",
    show_default=True,
    metavar="NAME",
    help="Work in the view called NAME.",
)
@click.option("-v", "--verbose", is_flag=True, help="Show tracebacks on errors.")
@click.version_option(package_name="mapapi")
@click.pass_context
def cli(ctx: click.Context, path: Path, view_name: str, verbose: bool) -> None:
    """mapctl: a git-like, decentralized map repository for robot swarms."""
    session = Session(path, view_name, verbose)
    ctx.obj = session
    ctx.call_on_close(session.close)


for module in (
    repo,
    view,
    history,
    peer,
    security,
    lookup,
    watch,
    imports,
    maps,
    align,
    bench,
    demo,
):
    module.register(cli)
completion.register(cli)  # last: it attaches TAB completion to the commands above


def main() -> None:
    """Entry point: run the CLI and turn errors into one line and an exit code."""
    verbose = "-v" in sys.argv[1:] or "--verbose" in sys.argv[1:]
    try:
        cli.main(standalone_mode=False)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
    except click.Abort:
        click.echo("aborted", err=True)
        sys.exit(EXIT_INTERRUPTED)
    except KeyboardInterrupt:
        click.echo("interrupted", err=True)
        sys.exit(EXIT_INTERRUPTED)
    except Exception as exc:
        from mapapi import MapError

        if verbose:
            traceback.print_exc()
        if isinstance(exc, MapError):
            click.secho(f"error: {exc}", fg="red", err=True)
            for note in getattr(exc, "__notes__", ()):  # what the library adds on the way up
                click.secho(note, dim=True, err=True)
            sys.exit(exc.exit_code)
        outside = _outside_error(exc)
        if outside is not None:
            click.secho(f"error: {outside}", fg="red", err=True)
            sys.exit(1)
        click.secho(f"internal error: {exc!r}; rerun with -v for the traceback", fg="red", err=True)
        sys.exit(1)


def _outside_error(exc: Exception) -> str | None:
    """One line for a failure of the files around mapctl rather than of mapctl:
    a file it cannot open, or a store SQLite finds damaged while reading it."""
    import sqlite3

    if isinstance(exc, OSError) and exc.filename is not None:
        return (
            f"cannot use {exc.filename}: {exc.strerror or exc}; check that it exists, "
            "its owner and permissions"
        )
    if isinstance(exc, sqlite3.DatabaseError) and not isinstance(exc, sqlite3.IntegrityError):
        return (
            f"the repository's store (.mapapi/store.sqlite) failed: {exc}; if this persists, "
            "restore it from a backup or clone the repository again"
        )
    return None
