"""Shared pieces of the command-line interface: consoles, errors, option parsing.

Numbers are formatted by :mod:`stiffmap.textfmt`.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Mapping, Sequence
from contextlib import contextmanager

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    TextColumn,
    TimeRemainingColumn,
)
from rich.table import Table
from rich.text import Text

from ..errors import FieldError, InputError
from ..io import dumps_json

# Re-exported for the commands that import it from here; its home is stiffmap.textfmt.
from ..textfmt import fmt as fmt


def _piped_width() -> int | None:
    """Width for tables written to a pipe or a log file.

    rich falls back to 80 columns when stdout is not a terminal, which folds
    file paths and matrices over several lines in a saved log; a file has no
    width, so use a generous one (``COLUMNS`` still wins when set).
    """
    if sys.stdout.isatty() or os.environ.get("COLUMNS"):
        return None
    return 160


#: Results go to stdout (so ``--json`` output can be piped); messages to stderr.
out = Console(highlight=False, soft_wrap=True, emoji=False, width=_piped_width())
err = Console(stderr=True, highlight=False, soft_wrap=True, emoji=False)

#: Exit status for a user mistake (bad file, bad option value).
EXIT_INPUT = 2
#: Exit status when some items failed but others were processed.
EXIT_PARTIAL = 1


def fail(message: str, code: int = EXIT_INPUT) -> typer.Exit:
    """Print ``error: message`` on stderr and return an Exit to raise."""
    err.print(f"[bold red]error:[/] {escape(message)}", markup=True, highlight=False)
    return typer.Exit(code)


def warn(message: str) -> None:
    """Print ``warning: message`` on stderr."""
    err.print(f"[yellow]warning:[/] {escape(message)}", markup=True, highlight=False)


def print_json(obj) -> None:
    """Print ``obj`` as JSON on stdout (numpy converted, NaN as null)."""
    sys.stdout.write(dumps_json(obj) + "\n")
    sys.stdout.flush()


def input_error(e: InputError) -> typer.Exit:
    """Report a user input error as one line and return the Exit to raise."""
    return fail(str(e))


def parse_key_values(items: Sequence[str], what: str) -> dict[str, str]:
    """Parse ``a=1,b=2`` or repeated ``a=1`` options into a dict (clear error otherwise)."""
    outd: dict[str, str] = {}
    for item in items:
        for part in item.split(","):
            part = part.strip()
            if not part:
                continue
            if "=" not in part:
                raise InputError(f"{what}: {part!r} should look like NAME=VALUE")
            k, v = part.split("=", 1)
            outd[k.strip()] = v.strip()
    return outd


def float_values(given: dict[str, str], what: str) -> dict[str, float]:
    """The values of parsed ``NAME=VALUE`` options as numbers (InputError naming one that is not)."""
    values = {}
    for k, v in given.items():
        try:
            values[k] = float(v)
        except ValueError:
            raise InputError(f"{what} {k}={v}: {v!r} is not a number") from None
    return values


@contextmanager
def options_named(names: Mapping[str, str]):
    """Word a library's :class:`~stiffmap.errors.FieldError` in the command line's terms.

    ``names`` maps the library's fields (``"params"``, ``"load_unit"``) to this command's
    options (``"--param"``, ``"--load-unit"``); the error is raised again with its fields
    named so (:meth:`~stiffmap.errors.FieldError.worded`).
    """
    try:
        yield
    except FieldError as e:
        raise e.worded(names) from None


def from_option(option: str, parse, *args):
    """``parse(*args)``, its ValueError as an InputError that starts with ``option``.

    The library's parsers say what was wrong with the text without the option's name
    (``'1,2': expected ...``); an :class:`InputError` (which names its file) passes as it is.
    """
    try:
        return parse(*args)
    except InputError:
        raise
    except ValueError as e:
        raise InputError(f"{option} {e}") from None


def three_numbers(text: str) -> tuple[float, ...] | None:
    """The three finite numbers of ``x,y,z``, or None when ``text`` is anything else."""
    try:
        v = tuple(float(x) for x in text.split(","))
    except ValueError:
        return None
    return v if len(v) == 3 and all(math.isfinite(x) for x in v) else None


def print_summary(title: str, rows: Sequence[tuple[str, str]]) -> None:
    """Print a two-column table (what, value) without header on stdout."""
    t = Table(title=title, show_header=False)
    for row in rows:
        t.add_row(*row)
    out.print(t)


class _Rate(ProgressColumn):
    """Images measured (or rendered) per second."""

    def render(self, task) -> Text:
        measured = task.fields.get("measured", 0)
        elapsed = task.elapsed or 0.0
        if not measured or elapsed <= 0:
            return Text("-- images/s")
        return Text(f"{measured / elapsed:.1f} images/s")


@contextmanager
def images_progress(description: str, show: bool = True, *, transient: bool = False):
    """A progress bar over images on stderr; yields its hook ``update(done, total, measured=done)``.

    Yields None (no bar) when ``show`` is false.
    """
    if not show:
        yield None
        return
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        _Rate(),
        TimeRemainingColumn(),
        console=err,
        transient=transient,
    ) as prog:
        task = prog.add_task(description, total=None, measured=0)

        def update(done: int, total: int, measured: int | None = None) -> None:
            prog.update(task, completed=done, total=total, measured=done if measured is None else measured)

        yield update


def dask_option(work: str):
    """The ``--dask SCHEDULER`` option of a command whose heavy ``work`` can run on a Dask cluster."""
    return typer.Option(
        None,
        "--dask",
        metavar="SCHEDULER",
        help=f"{work} on a Dask cluster: 'local' (a cluster of --workers processes on this machine) "
        "or a running scheduler's address (tcp://HOST:8786). Needs pip install 'stiffmap[dask]'; "
        "see docs/scaling.md.",
    )
