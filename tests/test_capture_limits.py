"""``stiffmap capture`` never waits without end or without a word (issue 27, hangs).

Before: ``--camera sim:fps=1e9`` never ended (the timeout counted the simulated clock, which
moves a nanosecond a frame); ``--frames 1000000000`` ran to the timeout keeping every frame in
memory; without a terminal nothing was printed while a step waited.
"""

from __future__ import annotations

import pytest
from helpers.capture_campaigns import small_campaign
from helpers.fuzz import run_argv

from stiffmap.campaign.spec import load_spec
from stiffmap.capture import session
from stiffmap.capture.cameras import MAX_SIM_FPS
from stiffmap.capture.session import MAX_FRAMES, run_capture
from stiffmap.cli import capture as cli_capture
from stiffmap.errors import InputError


def test_a_camera_whose_clock_barely_moves_gives_up_after_timeout_s_of_wall_clock(tmp_path, monkeypatch):
    root = small_campaign(tmp_path / "c", positions=(1,), timeout=1.0)
    monkeypatch.setattr(cli_capture, "WAITING_LINE_S", 0.0)  # a progress line at every frame
    monkeypatch.setattr(session, "MIN_WALL_S", 1.0)  # the wall clock's floor (10 s) shortened
    o = run_argv(["capture", str(root), "--camera", f"sim:fps={MAX_SIM_FPS:g}", "--yes"], time_limit=60.0)
    assert o.escaped is None, o.escaped  # not a hang (the fuzz layer's 60 s alarm)
    assert o.code == 2, o.stderr[-1000:]
    (line,) = [ln for ln in o.stderr.splitlines() if ln.startswith("error:")]
    assert "images/p01/r01_unloaded.png: no good settled frame in 1 s" in line
    assert "the images saved so far are kept" in line
    # The simulated camera moved a small part of a second of its own time in that second.
    assert o.seconds < 30.0
    # Without a terminal, lines told what the step waited for.
    waiting = [ln for ln in o.stdout.splitlines() if ln.startswith("step 1 of ")]
    assert waiting and "settled frames kept)" in waiting[0], o.stdout[-1000:]


@pytest.mark.parametrize("fps", ["1e9", "1001"])
def test_a_simulated_camera_faster_than_1000_fps_is_refused_in_one_line(tmp_path, fps):
    root = small_campaign(tmp_path / "c", positions=(1,))
    o = run_argv(["capture", str(root), "--camera", f"sim:fps={fps}", "--yes"], time_limit=30.0)
    (line,) = o.stderr.strip().splitlines()
    assert (
        o.code == 2
        and line == f"error: --camera sim:fps={fps}: fps must be at most 1000 frames per second, got {fps!r}"
    )
    assert not (root / "images").exists()  # refused before any frame


@pytest.mark.parametrize("frames", ["1000000000", "1001", "0"])
def test_frames_outside_1_to_1000_are_refused_before_any_frame(tmp_path, frames):
    o = run_argv(["capture", str(tmp_path), "--camera", "sim", "--frames", frames, "--yes"])
    (line,) = o.stderr.splitlines()
    assert o.code == 2 and line.startswith("error: Invalid value for '--frames'"), o.stderr
    assert "1000" in line or "greater than or equal to 1" in line, line


def test_the_library_refuses_too_many_frames_before_touching_the_camera(tmp_path):
    root = small_campaign(tmp_path / "c", positions=(1,))
    with pytest.raises(InputError, match=f"--frames must be 1 to {MAX_FRAMES}"):
        run_capture(root, load_spec(root), source=None, frames=10**9)
