"""The command table of ``stiffmap.cli.main``: lazy loading that stays true to the commands."""

from __future__ import annotations

import inspect
import subprocess
import sys

import pytest
from helpers.cli_process import run_in_process

from stiffmap.cli import main


@pytest.mark.parametrize("name", sorted(main.COMMANDS))
def test_summary_is_the_command_docstring(name):
    """The help page's summary of each command is the first paragraph of its docstring."""
    entry = main.COMMANDS[name]
    commands = {c.name: c for c in main.load_commands(entry.module)}
    assert name in commands, f"stiffmap.cli.{entry.module} does not define {name!r}"
    first = inspect.cleandoc(commands[name].help).split("\n\n")[0]
    assert first.replace("\\[", "[") == entry.summary


def test_every_registered_command_is_listed():
    """No command module registers a command the table does not list."""
    modules = {e.module for e in main.COMMANDS.values()}
    names = {c.name for m in modules for c in main.load_commands(m)}
    assert names == set(main.COMMANDS)


def test_help_loads_no_command_module():
    """``stiffmap --help`` lists every command without importing a command module or a heavy library."""
    code = (
        "import sys\n"
        "from stiffmap.cli.main import app\n"
        "try:\n"
        "    app(['--help'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "heavy = [m for m in ('cv2', 'scipy', 'matplotlib', 'plotly', 'stiffmap.cli.vision',\n"
        "         'stiffmap.cli.campaign') if m in sys.modules]\n"
        "print('HEAVY', heavy)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "HEAVY []" in proc.stdout
    for name in main.COMMANDS:
        assert name in proc.stdout


def _raise_bug(*args, **kwargs):
    raise ZeroDivisionError("float division by zero")


def test_a_bug_is_one_line_naming_the_command_and_exit_3(monkeypatch, capsys, tmp_path):
    """An unexpected exception is one ``error:`` line saying it is a bug, never a traceback."""
    import stiffmap.cli.identify as cli_identify

    monkeypatch.setattr(cli_identify, "identify_from_files", _raise_bug)
    monkeypatch.delenv(main.DEBUG_ENV, raising=False)
    f = tmp_path / "forces.csv"
    assert main.main(["identify", str(f), str(f)]) == main.EXIT_BUG
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("error: internal error")
    assert "ZeroDivisionError: float division by zero" in lines[0]
    assert f"stiffmap identify {f} {f}" in lines[0] and "--debug" in lines[0]
    assert "Traceback" not in err


def test_debug_anywhere_shows_the_traceback(monkeypatch, capsys, tmp_path):
    import stiffmap.cli.identify as cli_identify

    monkeypatch.setattr(cli_identify, "identify_from_files", _raise_bug)
    f = tmp_path / "forces.csv"
    assert main.main(["identify", str(f), "--debug", str(f)]) == main.EXIT_BUG
    err = capsys.readouterr().err
    assert "Traceback" in err and "_raise_bug" in err
    assert err.strip().splitlines()[-1].startswith("error: internal error")


@pytest.mark.parametrize("name", sorted(main.COMMANDS))
def test_help_at_80_columns_cuts_no_option_name_or_word(name, monkeypatch, capsys):
    """``COLUMNS=80 stiffmap NAME --help``: every option name whole (it printed
    ``--allow-outside-pat…`` in run's, ``--rot-stiffness-nm…`` in simulate's), every word of
    the help shown (folded if it must), no line wider than the terminal."""
    monkeypatch.setenv("COLUMNS", "80")
    code, out, err = run_in_process([name, "--help"], monkeypatch, capsys)
    assert code == 0, err
    lines = out.splitlines()
    assert "…" not in out and max(map(len, lines)) <= 80, out
    (cmd,) = [c for c in main.load_commands(main.COMMANDS[name].module) if c.name == name]
    names = [o for p in cmd.params for o in (*p.opts, *p.secondary_opts) if o.startswith("--")]
    shown = {w.strip("│ ,") for ln in lines for w in ln.split()}
    assert [n for n in names if n not in shown] == [], out


def test_a_choice_not_offered_is_one_line_without_pydantic_words(monkeypatch, capsys):
    """``--method foo`` said "Invalid value for '--method': Value error, 'foo' is not one of ..."."""
    code, _, err = run_in_process(["identify", "f.csv", "d.csv", "--method", "foo"], monkeypatch, capsys)
    assert code == 2 and err.count("\n") == 1, err
    expected = "error: Invalid value for '--method': 'foo' is not one of 'compliance', 'paper', 'spd'"
    assert err.startswith(expected), err
    assert "Value error" not in err and "(see 'stiffmap identify --help')" in err
