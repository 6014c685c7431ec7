"""Run the real ``stiffmap`` command as a user would (a subprocess): the one CLI test harness."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from stiffmap.cli.main import run


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
