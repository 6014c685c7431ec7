"""Shared pieces of the command-line interface: consoles, errors, option parsing, tables.

Numbers are formatted by :mod:`stiffmap.textfmt`. Every table printed on :data:`out` or
:data:`err` is fitted to the terminal's width by :func:`fit_table` (the consoles' render
hook): it wraps cells at spaces, splits wide tables into column groups, or stacks each
row, but never cuts a number. Exit statuses are the ``EXIT_*`` constants below
(CONTRIBUTING.md, "Exit statuses").
"""

from __future__ import annotations

import copy
import math
import os
import sys
import time
from collections.abc import Mapping, Sequence
from contextlib import contextmanager

import typer
from rich.console import Console, ConsoleRenderable, Group, RenderableType, RenderHook
from rich.markup import escape
from rich.measure import Measurement
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table
from rich.text import Text

from ..errors import FieldError, InputError
from ..io import dumps_json, parse_number

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


#: A column whose cells may be folded (file names, reasons: ``overflow="fold"``) takes at
#: least this many characters when the table has to shrink; other columns keep their
#: longest word, so that a number is never cut.
FOLD_MIN_WIDTH = 12


def _column_widths(table: Table, console: Console) -> list[tuple[int, int]]:
    """Per column, the (minimum, maximum) width of its content (header and cells, no padding)."""
    opts = console.options.update_width(10_000)
    widths = []
    for col in table.columns:
        cells = list(col.cells) + ([col.header] if table.show_header else [])
        lo, hi = 1, 1
        for cell in cells:
            m = Measurement.get(console, opts, cell)
            lo, hi = max(lo, m.minimum), max(hi, m.maximum)
        if col.overflow == "fold":
            head = Measurement.get(console, opts, col.header).minimum if table.show_header else 1
            lo = min(lo, max(FOLD_MIN_WIDTH, head))
        widths.append((lo, hi))
    return widths


def _rebuild(table: Table, columns: Sequence[int], widths: Sequence[int] | None = None, title=None) -> Table:
    """A copy of ``table`` with only ``columns`` (indices), each of a fixed width when given."""
    new = copy.copy(table)
    new.columns, new.rows = [], []
    if title is not None:
        new.title = title
    for k, i in enumerate(columns):
        col = copy.copy(table.columns[i])
        col._cells = []
        if widths is not None:
            col.width, col.min_width, col.max_width, col.no_wrap = widths[k], None, None, False
        col._index = k
        new.columns.append(col)
    cells = [list(table.columns[i].cells) for i in columns]
    for r, row in enumerate(table.rows):
        new.add_row(*(c[r] for c in cells), style=row.style, end_section=row.end_section)
    return new


def _overhead(table: Table, console: Console, content: int) -> int:
    """Width taken by the borders and padding of ``table`` (its content being ``content`` wide)."""
    return console.measure(table, options=console.options.update_width(10_000)).maximum - content


def _wrapped(table: Table, console: Console, width: int) -> Table | None:
    """``table`` with column widths that fit ``width``, every number whole; None if none do."""
    ranges = _column_widths(table, console)
    lo = sum(r[0] for r in ranges)
    hi = sum(r[1] for r in ranges)
    room = width - _overhead(table, console, hi)
    if hi <= room:
        return table
    if lo > room:
        return None

    # Water filling: every column as wide as it wants up to a common cap (never below its
    # longest word), the cap as high as the room allows: narrow columns (numbers, short
    # headers) stay whole, the widest text shares what is left.
    def widths_at(cap: int) -> list[int]:
        return [min(b, max(a, cap)) for a, b in ranges]

    cap = max(b for _, b in ranges)
    while sum(widths_at(cap)) > room:
        cap -= 1
    widths = widths_at(cap)
    for i in range(len(widths)):
        if sum(widths) < room and widths[i] < ranges[i][1]:
            widths[i] += 1
    return _rebuild(table, range(len(ranges)), widths)


def _column_groups(table: Table, console: Console, width: int) -> list[Table] | None:
    """Tables of the first column (the rows' key) and as many others as fit; None if one does not."""
    groups: list[list[int]] = []
    current = [0]
    for i in range(1, len(table.columns)):
        if _wrapped(_rebuild(table, [*current, i]), console, width) is not None:
            current.append(i)
        elif len(current) > 1 and _wrapped(_rebuild(table, [0, i]), console, width) is not None:
            groups.append(current)
            current = [0, i]
        else:
            return None
    groups.append(current)
    groups = _balanced(table, console, width, groups)
    title = table.title
    return [
        _wrapped(
            _rebuild(table, g, title=title if k == 0 or not title else f"{title} (continued)"), console, width
        )
        for k, g in enumerate(groups)
    ]


def _balanced(table: Table, console: Console, width: int, groups: list[list[int]]) -> list[list[int]]:
    """The same number of groups as the greedy ``groups``, with their columns shared evenly if that fits."""
    n, rest = len(groups), list(range(1, len(table.columns)))
    sizes = [len(rest) // n + (k < len(rest) % n) for k in range(n)]
    even, start = [], 0
    for size in sizes:
        even.append([0, *rest[start : start + size]])
        start += size
    if all(_wrapped(_rebuild(table, g), console, width) is not None for g in even):
        return even
    return groups


def _stacked(table: Table, console: Console, width: int) -> Table:
    """Each row as a block of (column, value) lines (of values alone when the table has no
    header): the last resort of a narrow terminal."""
    named = table.show_header
    t = Table(title=table.title, show_header=False, box=table.box, show_lines=False)
    for _ in range(1 + named):
        t.add_column(overflow="fold")
    cells = [list(c.cells) for c in table.columns]
    for r in range(len(table.rows)):
        for i, col in enumerate(table.columns):
            t.add_row(*([col.header] if named else []), cells[i][r], end_section=i == len(cells) - 1)
    return _wrapped(t, console, width) or t


def fit_table(table: Table, console: Console, width: int | None = None) -> RenderableType:
    """``table`` made to fit ``width`` columns (default the console's) without cutting a number.

    In order: the table as it is, if it fits; its cells wrapped at spaces (each column at
    least as wide as its longest word, so ``-0.88549 ± 0.0012`` may wrap at the ``±`` but a
    number is never cut); the table split into groups of columns, each repeating the
    first column (the rows' key); each row stacked as (column, value) lines. Columns
    declared ``overflow="fold"`` (file names, reasons) may be folded to
    :data:`FOLD_MIN_WIDTH`.
    """
    width = console.width if width is None else width
    if not table.columns or not table.rows:
        return table
    fitted = _wrapped(table, console, width)
    if fitted is None:
        keyed = table.show_header and len(table.columns) > 2
        groups = _column_groups(table, console, width) if keyed else None
        if groups is not None:
            return Group(*(_wrapping_title(g, console) for g in groups))
        fitted = _stacked(table, console, width)
    return _wrapping_title(fitted, console)


def _wrapping_title(table: Table, console: Console) -> Table:
    """``table`` whose title wraps at its width (the consoles print with ``soft_wrap``, which
    would otherwise leave a title longer than its table running past the terminal's edge)."""
    if not isinstance(table.title, str):
        return table
    new = copy.copy(table)
    title = console.render_str(table.title, style=table.title_style or "table.title", highlight=False)
    title.no_wrap, title.overflow = False, "fold"
    new.title = title
    return new


class _FitTables(RenderHook):
    """The consoles' render hook: every :class:`~rich.table.Table` printed goes through :func:`fit_table`."""

    def __init__(self, console: Console) -> None:
        self.console = console

    def process_renderables(self, renderables: list[ConsoleRenderable]) -> list[ConsoleRenderable]:
        return [fit_table(r, self.console) if isinstance(r, Table) else r for r in renderables]


def _console(**kwargs) -> Console:
    console = Console(highlight=False, soft_wrap=True, emoji=False, **kwargs)
    console.push_render_hook(_FitTables(console))
    return console


#: Results go to stdout (so ``--json`` output can be piped); messages to stderr.
out = _console(width=_piped_width())
err = _console(stderr=True)

# Exit statuses, the same for every command (CONTRIBUTING.md, "Exit statuses"; README):
#: Done; nothing to look at.
EXIT_OK = 0
#: Done, with warnings: some items left out (each named), or results flagged (a K that is
#: not positive definite, an implausible camera). Every ``warning:`` line means this status:
#: :func:`stiffmap.cli.main.main` returns it when a command that printed one ends with 0.
EXIT_WARNINGS = 1
#: The older name of :data:`EXIT_WARNINGS` (some items failed, the others were processed).
EXIT_PARTIAL = EXIT_WARNINGS
#: The user's input is wrong (a file, an option value): one ``error:`` line naming the file
#: and the field; nothing or only what was safe was written.
EXIT_INPUT = 2
#: A bug in stiffmap: one line that says so (the traceback with ``--debug``).
EXIT_BUG = 3
#: Interrupted by the user (Ctrl-C), as shells report SIGINT.
EXIT_INTERRUPTED = 130

#: ``warning:`` lines printed since :func:`reset_warnings` (the command line's exit status).
_warnings_printed = 0


def fail(message: str, code: int = EXIT_INPUT) -> typer.Exit:
    """Print ``error: message`` on stderr and return an Exit to raise."""
    err.print(f"[bold red]error:[/] {escape(message)}", markup=True, highlight=False)
    return typer.Exit(code)


def warn(message: str) -> None:
    """Print ``warning: message`` on stderr: something the user should look at.

    The command then exits with :data:`EXIT_WARNINGS` (1) even if it ends normally; what
    needs no action (a view left out of a good calibration, a backup kept) is a :func:`note`.
    """
    global _warnings_printed
    _warnings_printed += 1
    err.print(f"[yellow]warning:[/] {escape(message)}", markup=True, highlight=False)


def note(message: str) -> None:
    """Print ``note: message`` on stderr: information that needs no action (exit status unchanged)."""
    err.print(f"[cyan]note:[/] {escape(message)}", markup=True, highlight=False)


def reset_warnings() -> None:
    """Forget the warnings printed so far (a new command line starts)."""
    global _warnings_printed
    _warnings_printed = 0


def warnings_printed() -> int:
    """How many ``warning:`` lines were printed since :func:`reset_warnings`."""
    return _warnings_printed


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
        v = tuple(parse_number(x.strip()) for x in text.split(","))
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

    Yields None (no bar) when ``show`` is false. The bar starts at the first update: a command
    that stops before (a bad campaign.toml, a missing camera file) prints its one error line
    with no empty bar above it.
    """
    if not show:
        yield None
        return
    prog = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        _Rate(),
        TimeRemainingColumn(),
        console=err,
        transient=transient,
    )
    task = prog.add_task(description, total=None, measured=0)  # its clock starts now
    shown = []

    def update(done: int, total: int, measured: int | None = None) -> None:
        if not shown:
            prog.start()
            shown.append(True)
        prog.update(task, completed=done, total=total, measured=done if measured is None else measured)

    try:
        yield update
    finally:
        if shown:
            prog.stop()


#: Seconds between two progress lines when stderr is no terminal (a log, a test harness).
PROGRESS_LINE_S = 10.0


@contextmanager
def work_progress(what: str, total: int):
    """Progress over ``total`` items on stderr; yields its hook ``update(done, total)``.

    On a terminal, a rich progress bar (gone when done); otherwise (a log file, a pipe, a
    test harness, where a bar draws nothing until the end) one line every
    :data:`PROGRESS_LINE_S` seconds: ``poses: 24000 of 1000000 (2 %), 30 s, about 20 min left``.
    """
    if err.is_terminal:
        with Progress(
            TextColumn(what),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=err,
            transient=True,
        ) as prog:
            task = prog.add_task(what, total=total)
            yield lambda done, n: prog.update(task, completed=done, total=n)
        return
    t0 = time.monotonic()
    last = [t0]

    def line(done: int, n: int) -> None:
        now = time.monotonic()
        if now - last[0] < PROGRESS_LINE_S or not 0 < done < n:
            return
        last[0] = now
        left = (now - t0) * (n - done) / max(done, 1)
        err.print(
            f"{what}: {done} of {n} ({100 * done / n:.0f} %), {now - t0:.0f} s, about {_duration(left)} left",
            markup=False,
            highlight=False,
        )

    yield line


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


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
