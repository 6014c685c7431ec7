"""Run the real ``stiffmap`` command: in the test's process (the CLI harness) or as a subprocess."""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
from pathlib import Path

import pytest

from stiffmap.cli import common
from stiffmap.cli.main import main, run


def run_stiffmap(
    *args: str | Path,
    cwd: str | Path | None = None,
    timeout: float = 300,
    columns: int = 200,
    merged: bool = False,
) -> subprocess.CompletedProcess:
    """Run ``python -m stiffmap ARGS`` and return the completed process (text mode).

    The child runs with warnings as errors (``PYTHONWARNINGS=error``), ``columns`` columns
    (200 unless said) and no colour, so its output does not depend on the terminal. With
    ``merged``, stderr goes to stdout as on a terminal (``proc.stdout`` holds both, in the
    order they were printed; ``proc.stderr`` is None).
    """
    env = dict(os.environ, COLUMNS=str(columns), NO_COLOR="1", PYTHONWARNINGS="error", PYTHONUNBUFFERED="1")
    proc = subprocess.run(
        [sys.executable, "-m", "stiffmap", *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT if merged else subprocess.PIPE,
        text=True,
        cwd=cwd,
        env=env,
        timeout=timeout,
    )
    assert_tables_fit(proc.stdout, columns)
    return proc


def run_here(*args: str | Path, columns: int = 200) -> subprocess.CompletedProcess:
    """:func:`run_stiffmap` in this process: the same command line, exit status, stdout and
    stderr, without starting Python and importing stiffmap again (about 1.2 s of CPU a call).

    Needs no fixture (so it also runs inside a hypothesis test). The consoles are ``columns``
    wide, as ``COLUMNS`` makes them in a child; warnings are errors through pytest's
    ``filterwarnings``, as ``PYTHONWARNINGS=error`` makes them in a child. Use
    :func:`run_stiffmap` where the process is the point (``python -m``, a signal, stdout and
    stderr merged as on a terminal).
    """
    argv = [str(a) for a in args]
    outs, errs = io.StringIO(), io.StringIO()
    env = {"COLUMNS": str(columns), "NO_COLOR": "1"}
    saved_env = {k: os.environ.get(k) for k in env}
    widths = common.out._width, common.err._width  # None: the console follows its stream
    saved_argv = sys.argv
    try:
        sys.argv = ["stiffmap", *argv]  # what the command records of its command line
        os.environ.update(env)
        common.out.width = common.err.width = columns
        with contextlib.redirect_stdout(outs), contextlib.redirect_stderr(errs):
            code = main(argv)
    finally:
        common.out._width, common.err._width = widths
        sys.argv = saved_argv
        for k, v in saved_env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    proc = subprocess.CompletedProcess(["stiffmap", *argv], code, outs.getvalue(), errs.getvalue())
    assert_tables_fit(proc.stdout, columns)
    return proc


#: The first character of a line of a table (rich's boxes).
_TABLE_LINE = tuple("│┃┏┡└┌├┍┗┢╭╰┣┝")


def assert_tables_fit(stdout: str, columns: int) -> None:
    """What every command prints: no ``…`` (a number or a name cut to fit) and no table line
    wider than the terminal (``stiffmap.cli.common.fit_table``)."""
    assert "…" not in stdout, f"something was cut to fit {columns} columns:\n{stdout}"
    wide = [ln for ln in stdout.splitlines() if ln.startswith(_TABLE_LINE) and len(ln) > columns]
    assert not wide, f"table lines wider than {columns} columns:\n" + "\n".join(wide)


def assert_one_line_error(proc: subprocess.CompletedProcess, *needles: str) -> str:
    """A user error: non-zero exit, no traceback, one stderr line holding every needle."""
    assert proc.returncode != 0, proc.stdout
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = [ln for ln in proc.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    for n in needles:
        assert n in lines[0], f"{n!r} not in {lines[0]!r}"
    return lines[0]


def run_in_process(args, monkeypatch, capsys) -> tuple[int, str, str]:
    """Run ``stiffmap ARGS`` in this process (faster than :func:`run_stiffmap`, for many calls):
    ``(exit status, stdout, stderr)``."""
    monkeypatch.setattr(sys, "argv", ["stiffmap", *map(str, args)])
    with pytest.raises(SystemExit) as e:  # the command line always ends with an exit status
        run()
    cap = capsys.readouterr()
    return (e.value.code or 0), cap.out, cap.err
