"""Entry point of the ``stiffmap`` command."""

from __future__ import annotations

import importlib
import inspect
import sys

import typer
from rich.markup import escape
from typer.models import ParameterInfo

from .. import __version__
from ..errors import InputError
from .common import EXIT_INPUT, fail

app = typer.Typer(
    name="stiffmap",
    help=(
        "Measure, model and map the stiffness and static positioning error of robots.\n\n"
        "Units inside stiffmap are N, mm, MPa and rad; options that take other units say so "
        "in their name (--square-mm, --scale-um-per-v). See docs/ for the conventions."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="rich",
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"stiffmap {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: bool = typer.Option(
        False, "--version", help="Print the version and exit.", callback=_version, is_eager=True
    ),
) -> None:
    """stiffmap: stiffness and static-error measurement, models and maps."""


#: Command modules; each defines ``register(app)``.
_COMMAND_MODULES = (
    "identify",
    "vision",
    "model",
    "sensor",
    "simulate",
    "campaign",
    "report",
    "demo",
)

for _name in _COMMAND_MODULES:
    importlib.import_module(f"{__package__}.{_name}").register(app)


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
            cb.__doc__ = escape(cb.__doc__)
        for prm in inspect.signature(cb).parameters.values():
            d = prm.default
            if isinstance(d, ParameterInfo) and isinstance(d.help, str):
                d.help = escape(d.help)


_literal_brackets(app)


def run() -> None:
    """Console-script entry point: user errors become one line and a non-zero exit."""
    try:
        app()
    except InputError as e:
        fail(str(e))
        sys.exit(EXIT_INPUT)
    except OSError as e:
        # An output path that is a directory, a file where a folder is needed, no permission,
        # a full disk: the user's to fix, so one line that names the path, not a traceback.
        where = f"{e.filename}: " if e.filename else ""
        fail(f"{where}{e.strerror or e}")
        sys.exit(EXIT_INPUT)
    except KeyboardInterrupt:
        fail("interrupted", 130)
        sys.exit(130)


if __name__ == "__main__":  # pragma: no cover
    run()
