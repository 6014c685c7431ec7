"""Entry point of the ``stiffmap`` command.

Each command lives in a module of :mod:`stiffmap.cli` that defines ``register(app)``.
The modules are imported only when their command runs (the one lazy import of the CLI,
in :meth:`_LazyCommands.resolve_command`): a command module imports the library layers it
needs at its top (OpenCV, SciPy, matplotlib... about 2 s for all of them), and neither
``stiffmap --help`` nor one command should pay for every other command's imports. The
command list below gives each command's module and one-line summary for the help page;
``tests/test_cli_main.py`` checks that each summary is its command's docstring.
"""

from __future__ import annotations

import functools
import importlib
import inspect
import os
import shlex
import sys
import traceback
import warnings
from collections.abc import Sequence
from typing import NamedTuple

import click
import typer
import typer.rich_utils
from rich.markup import escape
from rich.panel import Panel
from rich.table import Table
from rich.text import Text
from typer.core import TyperGroup
from typer.exceptions import TyperException
from typer.models import ParameterInfo

from .. import __version__
from ..errors import InputError
from .common import (
    EXIT_BUG,
    EXIT_INPUT,
    EXIT_INTERRUPTED,
    EXIT_WARNINGS,
    fail,
    reset_warnings,
    warn,
    warnings_printed,
)


class CommandEntry(NamedTuple):
    """Where a command is defined and what ``stiffmap --help`` says of it."""

    module: str
    summary: str


#: Every command, in the order of ``stiffmap --help``: its module and summary.
COMMANDS: dict[str, CommandEntry] = {
    "identify": CommandEntry(
        "identify", "Identify the stiffness matrix K (N/mm) from load cases, with standard errors and checks."
    ),
    "calibrate": CommandEntry(
        "vision",
        "Calibrate a camera from images of a board (Zhang's method): intrinsics, distortion, 1-sigma.",
    ),
    "calibrate-rig": CommandEntry(
        "vision",
        "Calibrate a rig of cameras from views of a board seen at once: intrinsics, poses, covariance.",
    ),
    "pose": CommandEntry(
        "pose", "Pose of the board in each image: board2cam (4x4, mm), its 6x6 covariance and the RMS."
    ),
    "displacement": CommandEntry(
        "displacement", "Displacement of the target in each image relative to the reference image(s)."
    ),
    "validate": CommandEntry(
        "validate", "Validate against known stage displacements: measured vs nominal, mean +/- std per step."
    ),
    "model": CommandEntry(
        "model", "A model's stiffness K (N/mm) and static error u = K^-1 F (mm) at each position."
    ),
    "fit": CommandEntry(
        "model", "Fit model parameters to measured static errors or stiffness matrices (least squares)."
    ),
    "sensor": CommandEntry(
        "sensor", "Plateaus, load-displacement fit, stiffness and static error of stepped-load recordings."
    ),
    "simulate": CommandEntry(
        "simulate", "Simulate a vision campaign of a robot with known stiffness, seen by a known camera."
    ),
    "capture": CommandEntry(
        "capture",
        "Take a campaign's images from a live camera, one step at a time, once the platform has settled.",
    ),
    "init": CommandEntry("campaign", "Write a commented example campaign.toml to start a campaign from."),
    "run": CommandEntry(
        "campaign",
        "Measure, identify, fit and export a campaign (resumable: a re-run does only what changed).",
    ),
    "report": CommandEntry("report", "Write a self-contained HTML report (works offline) and PNG figures."),
    "demo": CommandEntry("demo", "Simulate the reference experiment and measure it with the whole chain."),
    "compensate": CommandEntry(
        "compensate", "Correct a machining program for the robot's deflection under the cutting force."
    ),
}

_TYPER_SETTINGS = dict(add_completion=False, pretty_exceptions_enable=False, rich_markup_mode="rich")


class _CommandStub(click.Command):
    """A command not loaded yet: its name and summary, enough for the help page."""


@functools.cache
def load_commands(module: str) -> tuple[click.Command, ...]:
    """Import ``stiffmap.cli.<module>`` and return its commands as click commands.

    Once per module and process: the help texts are escaped in place (see
    :func:`_literal_brackets`), which must not happen twice.
    """
    sub = typer.Typer(**_TYPER_SETTINGS)
    importlib.import_module(f"{__package__}.{module}").register(sub)
    _literal_brackets(sub)
    commands = tuple(
        typer.main.get_command_from_info(info, pretty_exceptions_short=True, rich_markup_mode="rich")
        for info in sub.registered_commands
    )
    for cmd in commands:
        cmd.callback = _interruptible(cmd.name, cmd.callback)
    return commands


class Interrupted(Exception):
    """Ctrl-C during a command, seen before typer turns it into a silent exit 130.

    ``command`` is the command's name, ``params`` its parameters (for :func:`interrupted_line`).
    """

    def __init__(self, command: str, params: dict) -> None:
        super().__init__(command)
        self.command = command
        self.params = params


def _interruptible(name: str, callback):
    """``callback`` with Ctrl-C (KeyboardInterrupt) raised as :class:`Interrupted`."""

    @functools.wraps(callback)
    def call(*args, **kwargs):
        try:
            return callback(*args, **kwargs)
        except KeyboardInterrupt:
            raise Interrupted(name, kwargs) from None

    return call


#: What an interrupted command has kept and how to go on; ``{...}`` are its parameters.
INTERRUPTED_NOTES = {
    "run": (
        "what was finished before is kept in {campaign}/stiffmap.db (each position and recording "
        "is written whole or not at all); run the same command again to resume: it does only what "
        "is missing"
    ),
    "capture": (
        "the images saved before are kept in {campaign} (capture_log.jsonl lists them); run the same "
        "command again to go on at the first missing image"
    ),
    "simulate": (
        "{out_dir} holds an unfinished simulation; run the same command with --force to make it again"
    ),
}
_DEFAULT_NOTE = (
    "no file was left half-written (stiffmap writes each file whole, or not at all); run the "
    "command again to start over"
)


def interrupted_line(e: Interrupted, args: Sequence[str]) -> str:
    """The one line said of a command interrupted by Ctrl-C: what it kept, how to go on."""
    if not e.command:
        return f"interrupted (Ctrl-C) before 'stiffmap {shlex.join(args)[:200]}' began: nothing was done"
    note = INTERRUPTED_NOTES.get(e.command, _DEFAULT_NOTE)
    try:
        note = note.format(**{k: v for k, v in e.params.items() if v is not None})
    except (KeyError, IndexError, ValueError):
        note = _DEFAULT_NOTE
    return f"interrupted (Ctrl-C) during 'stiffmap {shlex.join(args)[:200]}': {note}"


class _LazyCommands(TyperGroup):
    """The top-level group: every command listed from :data:`COMMANDS`, loaded when run."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        for name, entry in COMMANDS.items():
            self.commands[name] = _CommandStub(name, help=escape(entry.summary))

    def resolve_command(self, ctx: click.Context, args: list[str]):
        if args and isinstance(self.commands.get(args[0]), _CommandStub):
            try:
                for cmd in load_commands(COMMANDS[args[0]].module):
                    self.commands[cmd.name] = cmd
            except KeyboardInterrupt:  # while the command's libraries load: it has not begun
                raise Interrupted("", {}) from None
        return super().resolve_command(ctx, args)


app = typer.Typer(
    name="stiffmap",
    cls=_LazyCommands,
    help=(
        "Measure, model and map the stiffness and static positioning error of robots.\n\n"
        "Units inside stiffmap are N, mm, MPa and rad; options that take other units say so "
        "in their name (--square-mm, --scale-um-per-v). See docs/ for the conventions."
    ),
    no_args_is_help=True,
    **_TYPER_SETTINGS,
)


#: Where ``--debug`` is given (anywhere on the line) or set, a bug shows its traceback.
DEBUG_FLAG = "--debug"
DEBUG_ENV = "STIFFMAP_DEBUG"


def _version(value: bool) -> None:
    if value:
        typer.echo(f"stiffmap {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: bool = typer.Option(
        False, "--version", help="Print the version and exit.", callback=_version, is_eager=True
    ),
    debug: bool = typer.Option(
        False,
        DEBUG_FLAG,
        help="Show the traceback of an internal error (a bug), to report it. Anywhere on the line.",
    ),
) -> None:
    """stiffmap: stiffness and static-error measurement, models and maps."""


def _literal_brackets(app: typer.Typer) -> None:
    """Keep ``[optional parts]`` of help texts visible.

    Help is rendered with rich, which would read ``[and mx,my,mz]`` or
    ``[dx, dy, dz]`` as markup tags and drop them; the help texts use no markup,
    so every bracket is escaped to print as written.
    """
    for info in app.registered_commands:
        cb = info.callback
        if cb is None:
            continue
        if info.help:
            info.help = escape(info.help)
        if cb.__doc__:
            cb.__doc__ = escape(_unwrapped(cb.__doc__))
        for prm in inspect.signature(cb).parameters.values():
            d = prm.default
            if isinstance(d, ParameterInfo) and isinstance(d.help, str):
                d.help = escape(d.help)


def _unwrapped(doc: str) -> str:
    """A docstring with each paragraph on one line, for rich to wrap to the terminal's width.

    rich keeps the docstring's own line breaks, so a paragraph wrapped at the source's 100
    columns would come out ragged on an 80-column terminal. A bulleted paragraph (lines that
    begin with ``- `` or ``* ``) keeps one line per bullet, its continuation lines joined to it;
    one holding indented lines or a table (examples) is kept as written. A line that begins
    with an option (``--grid``) is no bullet: it is joined like any other.
    """
    out = []
    for para in inspect.cleandoc(doc).split("\n\n"):
        lines = para.split("\n")
        if any(ln.startswith(("- ", "* ")) for ln in lines):
            items: list[list[str]] = []
            for ln in lines:
                if ln.startswith(("- ", "* ")) or not items:
                    items.append([])
                items[-1].append(ln.strip())
            out.append("\n".join(" ".join(item) for item in items))
        elif any(ln.startswith((" ", "|")) for ln in lines):
            out.append(para)
        else:
            out.append(" ".join(ln.strip() for ln in lines))
    return "\n\n".join(out)


#: The widest the type column of a help page's options table gets (``<float range>``).
HELP_TYPE_WIDTH = 14


class _HelpOptionsFit:
    """A render hook of typer's help console: every option name whole at 80 columns.

    typer prints each panel of options as a table of option names, short names, negative
    forms, types and help; rich squeezes every column that may wrap to the same width when
    the table is too wide, and cuts what does not fit with an ellipsis
    (``--allow-outside-pat…``, ``(tcp://HOST:878…``). Here the columns empty on every row
    go, a column of option names keeps the width of its longest name, the type column
    wraps within :data:`HELP_TYPE_WIDTH`, and a word longer than its column folds.
    """

    def process_renderables(self, renderables: list) -> list:
        for r in renderables:
            table = getattr(r, "renderable", None) if isinstance(r, Panel) else None
            if isinstance(table, Table):
                _fit_options_table(table)
        return renderables


def _fit_options_table(table: Table) -> None:
    def plain(cell) -> str:
        return cell.plain if isinstance(cell, Text) else str(cell)

    table.columns[:] = [c for c in table.columns if any(plain(x).strip() for x in c.cells)]
    for col in table.columns:
        cells = [plain(c) for c in col.cells]
        col.overflow = "fold"
        for cell in col.cells:  # the help column's cells hold their paragraphs' texts
            for item in getattr(cell, "renderables", [cell]):
                if isinstance(item, Text):
                    item.overflow = "fold"
        if any(c.startswith("-") for c in cells):
            col.width = max(map(len, cells))
        elif col is not table.columns[-1] and max(map(len, cells), default=0) > HELP_TYPE_WIDTH:
            col.max_width = HELP_TYPE_WIDTH


def _help_console(stderr: bool = False):
    """typer's console for help pages and usage errors, with :class:`_HelpOptionsFit`."""
    console = _typer_console(stderr)
    console.push_render_hook(_HelpOptionsFit())
    return console


_typer_console = typer.rich_utils._get_rich_console
typer.rich_utils._get_rich_console = _help_console


def _one_line_warnings(message, category, filename, lineno, file=None, line=None) -> None:
    """Show a Python warning as one ``warning:`` line (no source path, no code line)."""
    warn(str(message))


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``stiffmap`` on ``argv`` (default ``sys.argv[1:]``) and return its exit status.

    The statuses are the same for every command (``cli.common.EXIT_*``): 0 done; 1 done with
    warnings (a command that printed a ``warning:`` line and would end with 0 ends with 1);
    2 a user error (:class:`~stiffmap.errors.InputError`, a file the system refuses, a command
    line that does not parse): one ``error:`` line; 3 a bug: anything else that escapes a
    command, one line that says so, names the command line and the exception; the traceback
    only with ``--debug`` (anywhere on the command line) or ``STIFFMAP_DEBUG=1``; 130
    interrupted.
    """
    reset_warnings()
    code = _run(argv)
    return EXIT_WARNINGS if code == 0 and warnings_printed() else code


def _run(argv: Sequence[str] | None) -> int:
    """The command line's own exit status (before the warnings are counted)."""
    args = list(sys.argv[1:] if argv is None else argv)
    debug = DEBUG_FLAG in args or os.environ.get(DEBUG_ENV, "") not in ("", "0")
    args = [a for a in args if a != DEBUG_FLAG]
    try:
        with warnings.catch_warnings():
            if not sys.warnoptions:
                warnings.showwarning = _one_line_warnings
            rv = app(args=args, prog_name="stiffmap", standalone_mode=False)
    except SystemExit as e:
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    except typer.Abort:
        fail("aborted", 1)
        return 1
    except TyperException as e:  # click's usage errors: an unknown option, a value of the wrong type
        return _usage_error(e)
    except InputError as e:
        fail(str(e))
        return EXIT_INPUT
    except OSError as e:
        # An output path that is a directory, a file where a folder is needed, no permission,
        # a full disk: the user's to fix, so one line that names the path, not a traceback.
        where = f"{e.filename}: " if e.filename else ""
        fail(f"{where}{e.strerror or e}")
        return EXIT_INPUT
    except Interrupted as e:
        fail(interrupted_line(e, args), EXIT_INTERRUPTED)
        return EXIT_INTERRUPTED
    except KeyboardInterrupt:
        fail("interrupted (Ctrl-C)", EXIT_INTERRUPTED)
        return EXIT_INTERRUPTED
    except Exception as e:  # the one place that turns a bug into a message
        if debug:
            traceback.print_exc()
        what = " ".join(str(e).split())[:300]
        line = shlex.join(args)[:300]
        advice = "Please report it with this line." if debug else "Rerun with --debug to see the traceback."
        fail(
            f"internal error (a bug in stiffmap {__version__}, not in your input): "
            f"{type(e).__name__}: {what} -- while running: stiffmap {line}. {advice}",
            EXIT_BUG,
        )
        return EXIT_BUG
    if rv == EXIT_INTERRUPTED:  # typer's silent exit of a Ctrl-C outside any command (parsing)
        fail(f"interrupted (Ctrl-C) before 'stiffmap {shlex.join(args)[:200]}' began: nothing was done", rv)
    return rv if isinstance(rv, int) else 0


def _usage_error(e: TyperException) -> int:
    """A command line that does not parse: one ``error:`` line naming the option (status 2).

    (Bare ``stiffmap`` prints the help, as ``stiffmap --help`` does, with status 2 as before.)
    """
    ctx = getattr(e, "ctx", None)
    if type(e).__name__ == "NoArgsIsHelpError":
        # Its message is the help: rich printed it when the error was made (and left it "").
        text = e.format_message() if hasattr(e, "format_message") else ""
        if text:
            typer.echo(text)
        return EXIT_INPUT
    where = ctx.command_path if ctx is not None else "stiffmap"
    message = e.format_message() if hasattr(e, "format_message") else str(e)
    message = message.replace(": Value error, ", ": ")  # pydantic's prefix, through typer's coercion
    fail(f"{' '.join(message.split())} (see '{where} --help')", getattr(e, "exit_code", EXIT_INPUT))
    return int(getattr(e, "exit_code", EXIT_INPUT))


def run() -> None:
    """Console-script entry point (``stiffmap``, ``python -m stiffmap``)."""
    sys.exit(main())


if __name__ == "__main__":  # pragma: no cover
    run()
