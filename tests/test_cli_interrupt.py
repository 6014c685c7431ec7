"""Ctrl-C during a command: one line saying what was kept and how to go on, exit 130.

typer turns a KeyboardInterrupt inside a command into a silent exit 130; stiffmap's entry point
sees it first (``stiffmap.cli.main.Interrupted``). What the line promises is checked against the
files: the positions a run had written are in the database and the next run resumes from them,
the images a capture had saved are on disk and in its log.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers.capture_campaigns import FAST_SIM, small_campaign
from helpers.fuzz_campaign import bare_vision_seed

from stiffmap.campaign import runner
from stiffmap.campaign.store import DB_NAME, Store
from stiffmap.capture import session
from stiffmap.cli import main


def _write(files: dict[str, bytes], root: Path) -> Path:
    for name, data in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_bytes(data)
    return root


def _one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("measuring images")]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def test_ctrl_c_in_run_keeps_the_positions_written_and_the_next_run_resumes(tmp_path, monkeypatch, capsys):
    root = _write(bare_vision_seed(), tmp_path / "c")
    saved = []
    save = Store.save_position

    def save_then_ctrl_c(self, position, **rows):
        if saved:  # the second position: Ctrl-C before it is written
            raise KeyboardInterrupt
        save(self, position, **rows)
        saved.append(position)

    monkeypatch.setattr(Store, "save_position", save_then_ctrl_c)
    argv = ["run", str(root), "--quiet", "--workers", "1", "--no-report"]
    assert main.main(argv) == main.EXIT_INTERRUPTED
    line = _one_line(capsys.readouterr().err)
    assert line.startswith(f"error: interrupted (Ctrl-C) during 'stiffmap {' '.join(argv)}'")
    assert f"kept in {root}/{DB_NAME}" in line and "run the same command again to resume" in line
    with Store(root / DB_NAME, read_only=True) as store:
        assert [r.position for r in store.stiffness_rows()] == saved == [1]
    monkeypatch.undo()
    measured = []
    monkeypatch.setattr(runner, "measure_positions", _recording(runner.measure_positions, measured))
    assert main.main([*argv, "--json"]) == 0
    assert measured == [2]  # position 1 was kept: only the missing one is measured


def _recording(measure, measured: list):
    def call(ctx, tasks, *args, **kwargs):
        measured.extend(t.index for t in tasks)
        return measure(ctx, tasks, *args, **kwargs)

    return call


def test_ctrl_c_in_capture_keeps_the_images_saved(tmp_path, monkeypatch, capsys):
    root = small_campaign(tmp_path / "c", positions=(6,))
    writes = []
    write = session.atomic_write_bytes

    def write_then_ctrl_c(path, data):
        if len(writes) == 2:
            raise KeyboardInterrupt
        write(path, data)
        writes.append(Path(path))

    monkeypatch.setattr(session, "atomic_write_bytes", write_then_ctrl_c)
    argv = ["capture", str(root), "--camera", FAST_SIM, "--yes"]
    assert main.main(argv) == main.EXIT_INTERRUPTED
    line = _one_line(capsys.readouterr().err)
    assert line.startswith("error: interrupted (Ctrl-C) during 'stiffmap capture")
    assert f"the images saved before are kept in {root}" in line
    assert "run the same command again to go on at the first missing image" in line
    on_disk = sorted(p for p in (root / "images").rglob("*") if p.is_file())
    assert on_disk == sorted(writes) and len(on_disk) == 2
    log = [json.loads(ln) for ln in (root / session.LOG_NAME).read_text().splitlines()]
    assert [e["event"] for e in log].count("saved") == 2
    assert log[-1]["event"] == "stop" and log[-1]["reason"] == "interrupted"


def test_ctrl_c_while_a_command_loads_says_nothing_was_done(monkeypatch, capsys):
    def ctrl_c(module):
        raise KeyboardInterrupt

    monkeypatch.setattr(main, "load_commands", ctrl_c)
    assert main.main(["identify", "f.csv", "d.csv"]) == main.EXIT_INTERRUPTED
    line = _one_line(capsys.readouterr().err)
    assert (
        line == "error: interrupted (Ctrl-C) before 'stiffmap identify f.csv d.csv' began: nothing was done"
    )


@pytest.mark.slow
def test_ctrl_c_in_a_terminal_reaches_the_pool_workers_without_a_traceback(tmp_path):
    """In a terminal Ctrl-C signals the whole process group: the pool's workers too. They leave
    it to the parent (which stops them); the parent says its one line."""
    root = _write(bare_vision_seed(), tmp_path / "c")
    env = dict(os.environ, COLUMNS="200", NO_COLOR="1")
    cmd = [sys.executable, "-m", "stiffmap", "run", str(root), "--workers", "2", "--no-report"]

    def own_group():
        os.setpgrp()
        signal.signal(signal.SIGINT, signal.SIG_DFL)

    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, preexec_fn=own_group
    )
    try:
        t0 = time.monotonic()
        while not (root / DB_NAME).exists() and time.monotonic() - t0 < 60 and proc.poll() is None:
            time.sleep(0.05)
        time.sleep(0.3)  # the pool started, the first position measuring
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    if proc.returncode == 0:
        pytest.skip("the run ended before the Ctrl-C")
    assert proc.returncode == main.EXIT_INTERRUPTED, err
    assert "error: interrupted (Ctrl-C) during 'stiffmap run" in _one_line(err)
