"""Guided capture (stiffmap capture) with the simulated live camera of the virtual test-bed.

The campaigns are small (helpers.capture_campaigns: the demo's scene seen by a half-size
camera, one or two positions, four load cases, one or two repeats) and the simulated camera is
fast (5 frames per simulated second, a swing decaying with tau = 0.1 s). The must-show with K --
the quick demo's own campaign captured, then run, at full size -- is in
tests/test_campaign_run.py (it needs the quick demo's rendered images to compare with).
"""

from __future__ import annotations

import json
import re
import shlex
import signal
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers.capture_campaigns import FAST_SIM, small_campaign
from helpers.cli_process import run_in_process
from hypothesis import given, settings
from hypothesis import strategies as st

from stiffmap.campaign.robot import campaign_positions
from stiffmap.campaign.spec import load_spec, parse_spec
from stiffmap.capture.cameras import open_camera
from stiffmap.capture.plan import capture_steps
from stiffmap.capture.session import LOG_NAME, AutoOperator, CaptureStopped, run_capture
from stiffmap.errors import InputError
from stiffmap.sim.live_camera import SimulatedCamera
from stiffmap.sim.render import Photometry, blurred_reflectance
from stiffmap.sim.scene import Scene


def _log(root: Path) -> list[dict]:
    return [json.loads(line) for line in (root / LOG_NAME).read_text(encoding="utf-8").splitlines()]


def _plan_files(root: Path) -> set[str]:
    return {f for s in capture_steps(load_spec(root), root) for f in s.files}


def _images_on_disk(root: Path) -> set[str]:
    return {p.relative_to(root).as_posix() for p in (root / "images").rglob("*") if p.is_file()}


def test_sigkill_then_resume_gives_the_same_files(tmp_path, monkeypatch, capsys):
    """A capture killed (SIGKILL) partway resumes at the first missing image and ends with the
    plan's files, as an uninterrupted capture does, and no temporary file."""
    root = small_campaign(tmp_path / "c", positions=(6,))
    plan = _plan_files(root)
    cmd = [sys.executable, "-m", "stiffmap", "capture", str(root), "--camera", FAST_SIM, "--yes"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        t0 = time.monotonic()
        while len(_images_on_disk(root) & plan) < 2 and time.monotonic() - t0 < 60:
            assert proc.poll() is None, "the capture ended before it could be killed"
            time.sleep(0.02)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    before = _images_on_disk(root) & plan
    assert 2 <= len(before) < len(plan)
    first_missing = next(f for s in capture_steps(load_spec(root), root) for f in s.files if f not in before)
    code, _, err = run_in_process(["capture", root, "--camera", FAST_SIM, "--yes"], monkeypatch, capsys)
    assert code == 0, err
    assert _images_on_disk(root) == plan
    log = _log(root)
    assert [e["event"] for e in log].count("start") == 2
    # The events after the second start (the kill can fall between an image's write and its log
    # line: counting the images on disk would then point one event too far).
    second = [i for i, e in enumerate(log) if e["event"] == "start"][1]
    resumed = [e for e in log[second:] if e["event"] == "saved"]
    assert resumed[0]["files"] == [first_missing]


def test_redo_and_skip_are_logged(tmp_path):
    """The operator redoes the last image (asked before overwriting) and skips one; the log says so."""
    root = small_campaign(tmp_path / "c", positions=(6,))
    spec = load_spec(root)

    class Scripted(AutoOperator):
        def __init__(self):
            self.answers = ["go", "redo", "go", "skip", "quit"]
            self.asked = []

        def confirm(self, instruction):
            return self.answers.pop(0)

        def overwrite(self, file):
            self.asked.append(file)
            return True

    op = Scripted()
    with open_camera(FAST_SIM, root, spec) as cam:
        summary = run_capture(root, spec, cam, operator=op)
    first = "images/p01/r01_unloaded.png"
    assert op.asked == [first]
    assert summary.saved == (first, first)
    assert summary.skipped == ("images/p01/l01_r01_loaded.png",)
    assert summary.stopped == "stopped by the operator"
    events = [(e["event"], e.get("files")) for e in _log(root)][1:]
    assert events == [
        ("saved", [first]),
        ("redo", [first]),
        ("saved", [first]),
        ("skip", ["images/p01/l01_r01_loaded.png"]),
        ("stop", None),
    ]


def _modified(root, spec, *, shift_mm=None, photometry=None) -> SimulatedCamera:
    cam = open_camera(FAST_SIM, root, spec)
    sc = cam.scene
    if shift_mm is not None:
        T = sc.cam2base.copy()
        T[:3, 3] += shift_mm
        sc = Scene(sc.camera, T, sc.fixed_board, sc.fixed2base, sc.mobile_board, sc.mobile2tcp, sc.margin_mm)
    return SimulatedCamera(
        sc,
        cam.robot,
        photometry=photometry or cam.photometry,
        fps=cam.fps,
        time_constant_s=cam.time_constant_s,
        frequency_hz=cam.frequency_hz,
    )


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        # The camera moved 700 mm sideways: the mobile board leaves the image.
        ({"shift_mm": [-700.0, 0.0, 0.0]}, "not found"),
        # Twice the exposure: the white squares clip at 255.
        ({"photometry": Photometry(gain=1.6)}, "saturated"),
    ],
    ids=["board out of view", "saturated board"],
)
def test_a_bad_view_stops_with_a_clear_message_and_keeps_the_images(tmp_path, change, needle):
    root = small_campaign(tmp_path / "c", positions=(6,), timeout=0.5)
    spec = load_spec(root)
    # One good image first: it must survive the failure.
    with open_camera(FAST_SIM, root, spec) as cam:

        class OneImage(AutoOperator):
            n = 0

            def confirm(self, instruction):
                self.n += 1
                return "go" if self.n == 1 else "quit"

        run_capture(root, spec, cam, operator=OneImage())
    kept = _images_on_disk(root)
    assert kept == {"images/p01/r01_unloaded.png"}
    with _modified(root, spec, **change) as cam, pytest.raises(CaptureStopped) as e:
        run_capture(root, spec, cam)
    msg = str(e.value)
    assert needle in msg and "images/p01/l01_r01_loaded.png" in msg and "kept" in msg
    assert "\n" not in msg
    assert _images_on_disk(root) == kept
    assert _log(root)[-1]["event"] == "stop"


def _one_line_error(code: int, err: str, *needles: str) -> None:
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert all(n in lines[0] for n in needles), lines[0]


def test_a_camera_that_cannot_be_opened_and_a_video_that_ends_early(tmp_path, monkeypatch, capsys):
    root = small_campaign(tmp_path / "c", positions=(6,))
    # No camera 57 on any test machine.
    code, _, err = run_in_process(["capture", root, "--camera", "57", "--yes"], monkeypatch, capsys)
    _one_line_error(code, err, "camera 57", "cannot be opened")
    # A video of the rig at rest, unloaded, that ends before the loaded images.
    spec = load_spec(root)
    with open_camera(FAST_SIM, root, spec) as cam:
        cam.move_to(campaign_positions(spec, root)[0])
        for _ in range(15):  # let the move's ring die out
            cam.grab()
        frames = [cam.grab().image for _ in range(6)]
    video = tmp_path / "rig.avi"
    h, w = frames[0].shape
    vw = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 5.0, (w, h), isColor=False)
    for f in frames:
        vw.write(f)
    vw.release()
    code, out, err = run_in_process(["capture", root, "--camera", video, "--yes"], monkeypatch, capsys)
    _one_line_error(code, err, "rig.avi", "the video ended after 6 frames", "kept")
    assert _images_on_disk(root) == {"images/p01/r01_unloaded.png"}
    assert "saved images/p01/r01_unloaded.png" in out


def test_the_simulated_camera_refuses_a_position_it_does_not_know(tmp_path):
    root = small_campaign(tmp_path / "c", positions=(6,))
    cam = open_camera(FAST_SIM, root, load_spec(root))
    with pytest.raises(ValueError, match="known only at the campaign's positions"):
        cam.move_to([0.0, 0.0, -350.0])
    with pytest.raises(InputError, match="sim:fps=x"):
        open_camera("sim:fps=x", root, load_spec(root))


# ---------------------------------------------------------------- [capture] in campaign.toml

_BASE_TOML = """
name = "capture spec"
repeats = 2
[camera]
file = "camera.json"
[targets.fixed]
board = "9x6"
square_mm = 10.0
fixed2base = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
[targets.mobile]
board = "15x14"
square_mm = 10.0
[positions]
list = [[0.0, 0.0, -300.0]]
[loads]
preset = "paper9"
"""

_KEYS = ("frames", "average", "settle_seconds", "vibration_mm", "timeout_s", "move_command", "fps")


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return (
            "nan" if v != v else ("inf" if v == float("inf") else ("-inf" if v == -float("inf") else repr(v)))
        )
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return str(v)


def _values():
    scalar = st.one_of(
        st.booleans(),
        st.integers(-(2**63), 2**63 - 1),
        st.floats(allow_nan=True, allow_infinity=True),
        st.text(max_size=30),
        st.sampled_from(["move {x} {y} {z}", "m {x:.3f}", "m {q}", "m {x", "m {}", "m {0}", "", " "]),
    )
    return st.one_of(scalar, st.lists(scalar, max_size=3))


@settings(max_examples=30, deadline=None)
@given(st.dictionaries(st.sampled_from(_KEYS), _values(), max_size=4))
def test_capture_section_fuzz(table):
    """Whatever a [capture] section holds, the spec reader accepts it with sane settings or says
    which capture key is wrong: never another error."""
    text = _BASE_TOML + "[capture]\n" + "".join(f"{k} = {_toml(v)}\n" for k, v in table.items())
    try:
        spec = parse_spec(text)
    except InputError as e:
        assert "capture" in str(e), str(e)
        return
    cap = spec.capture_settings
    assert isinstance(cap.frames, int) and 1 <= cap.frames <= 1000
    assert isinstance(cap.average, bool)
    assert 0 <= cap.settle_seconds <= 3600 and 0 <= cap.vibration_mm <= 10 and cap.timeout_s > 0
    assert cap.average or cap.frames in (1, spec.repeats)
    if cap.move_command is not None:
        cap.move_command.format(x=1.0, y=2.0, z=3.0)


# ---------------------------------------------------------------- --frames N, move_command


def _background_mask(cam: SimulatedCamera, tcp2base) -> np.ndarray:
    """Pixels that see the plain background only (no board, nor a board's blur), eroded by a
    few pixels: their mean is smooth (the vignetting) and the same in every frame."""
    ph = cam.photometry
    refl = blurred_reflectance(
        cam.scene.camera, cam.scene.targets(tcp2base), background=ph.background, blur_px=ph.blur_px
    )
    plain = (refl == np.float32(ph.background)).astype(np.uint8)
    return cv2.erode(plain, np.ones((9, 9), np.uint8)).astype(bool)


def _pixel_noise(image: np.ndarray, mask: np.ndarray) -> float:
    """1 sigma of the pixel noise, DN, from horizontal neighbours both in ``mask``
    (the difference of two independent pixels of the same mean has twice the variance)."""
    a = image.astype(np.float64)
    both = mask[:, 1:] & mask[:, :-1]
    d = (a[:, 1:] - a[:, :-1])[both]
    assert d.size > 100_000
    return float(np.sqrt(np.mean(d**2) / 2.0))


def test_averaged_frames_lower_the_pixel_noise_as_docs_capture_says(tmp_path):
    """--frames 4 (averaged): the saved image is the mean of 4 consecutive settled frames, and its
    pixel noise is what docs/capture.md says: sigma / sqrt(N) with the 8-bit rounding of the
    mean added, sqrt(sigma^2 / N + 1/12) (about half of one frame's: 1.9 times less here)."""
    first = "images/p01/r01_unloaded.png"
    noise = {}
    for n in (1, 4):
        root = small_campaign(tmp_path / f"n{n}", positions=(6,))
        spec = load_spec(root)

        class FirstImage(AutoOperator):
            asked = 0

            def confirm(self, instruction):
                self.asked += 1
                return "go" if self.asked == 1 else "quit"

        with open_camera(FAST_SIM, root, spec) as cam:
            summary = run_capture(root, spec, cam, operator=FirstImage(), frames=n)
            mask = _background_mask(cam, cam.pose_at(cam.time_s))
        assert summary.saved == (first,)
        saved = [r for r in _log(root) if r["event"] == "saved"]
        assert len(saved) == 1 and saved[0]["frames"] == n and saved[0]["averaged"] is True
        # n consecutive frames (5 frames/s), every one settled by the simulated camera's truth.
        assert np.allclose(np.diff(saved[0]["timestamps_s"]), 0.2, atol=1e-9)
        assert saved[0]["source_truth"]["settled"] == [True] * n
        image = cv2.imread(str(root / first), cv2.IMREAD_UNCHANGED)
        noise[n] = _pixel_noise(image, mask)
    # One frame of the default photometry on the 0.35 background (about 66 DN): read noise
    # 0.8 DN and shot noise 0.04 DN/e, sqrt(0.64 + 0.04 * 66 + 1/12) = 1.83 DN with rounding.
    assert 1.6 < noise[1] < 2.0
    predicted = np.sqrt(noise[1] ** 2 / 4 + 1 / 12)
    assert noise[4] == pytest.approx(predicted, rel=0.03)
    assert 1.8 < noise[1] / noise[4] < 2.0  # "4 frames halve it", less the rounding's 0.29 DN


def test_frames_kept_as_the_repeats_without_averaging(tmp_path, monkeypatch, capsys):
    """[capture] average = false and --frames 2 = repeats: each step keeps two consecutive
    settled frames as repeats 1 and 2 (two images with their own noise, not one written twice);
    --frames 3 is refused in one line naming campaign.toml."""
    root = small_campaign(tmp_path / "c", positions=(6,), repeats=2, extra="average = false\n")
    code, _, err = run_in_process(
        ["capture", root, "--camera", FAST_SIM, "--frames", "3", "--yes"], monkeypatch, capsys
    )
    _one_line_error(code, err, "campaign.toml", "--frames 3", "capture.average = false", "repeats = 2")
    assert not (root / "images").exists()
    code, out, err = run_in_process(
        ["capture", root, "--camera", FAST_SIM, "--frames", "2", "--yes"], monkeypatch, capsys
    )
    assert code == 0, err
    assert _images_on_disk(root) == _plan_files(root)
    saved = [r for r in _log(root) if r["event"] == "saved"]
    assert len(saved) == len(_plan_files(root)) // 2 == 5  # unloaded and 4 loads, two repeats each
    for r in saved:
        assert r["frames"] == 2 and r["averaged"] is False and r["repeats"] == [1, 2]
        assert re.fullmatch(r"(l0\d_)?r01_(un)?loaded\.png", Path(r["files"][0]).name), r["files"]
        assert r["files"][1] == r["files"][0].replace("r01", "r02")
        assert r["timestamps_s"][1] - r["timestamps_s"][0] == pytest.approx(0.2, abs=1e-9)
        assert r["source_truth"]["settled"] == [True, True]
    # The two repeats of the unloaded image: the same scene, independent noise (the difference
    # of two frames has sqrt(2) times one frame's noise).
    spec = load_spec(root)
    with open_camera(FAST_SIM, root, spec) as cam:
        cam.move_to(campaign_positions(spec, root)[0])
        mask = _background_mask(cam, cam.pose_at(0.0))
    a, b = (cv2.imread(str(root / f), cv2.IMREAD_UNCHANGED).astype(np.float64) for f in saved[0]["files"])
    one = _pixel_noise(a, mask)
    assert 1.6 < one < 2.0
    assert np.std((a - b)[mask]) == pytest.approx(np.sqrt(2) * one, rel=0.05)


_MOVE_SCRIPT = """
import sys
import time
from pathlib import Path

with open(Path(sys.argv[1]), "a", encoding="utf-8") as f:
    f.write(f"{time.time():.3f} " + " ".join(sys.argv[2:]) + "\\n")
if sys.argv[2] == "--fail":
    print("robot controller: axis 2 in fault", file=sys.stderr)
    sys.exit(3)
"""


def _move_campaign(tmp_path: Path, *args: str) -> Path:
    script = tmp_path / "move.py"
    script.write_text(_MOVE_SCRIPT, encoding="utf-8")
    template = " ".join(shlex.quote(str(a)) for a in (sys.executable, script, tmp_path / "moves.txt", *args))
    return small_campaign(tmp_path / "c", positions=(1, 22), extra=f"move_command = {json.dumps(template)}\n")


def test_move_command_runs_once_per_new_position_with_its_mm(tmp_path, monkeypatch, capsys):
    """[capture] move_command: run (no shell) once before the first image of each position, with
    the position's x, y, z in mm (plain and formatted placeholders)."""
    root = _move_campaign(tmp_path, "--x", "{x}", "--y", "{y:.3f}", "--z", "{z}")
    code, _, err = run_in_process(["capture", root, "--camera", FAST_SIM, "--yes"], monkeypatch, capsys)
    assert code == 0, err
    lines = (tmp_path / "moves.txt").read_text(encoding="utf-8").splitlines()
    P = campaign_positions(load_spec(root), root)
    assert len(lines) == len(P) == 2  # 2 positions, 5 images each: one move each
    saved = [r for r in _log(root) if r["event"] == "saved"]
    assert [r["position"] for r in saved] == [1] * 5 + [2] * 5
    for i, (line, p) in enumerate(zip(lines, P, strict=True)):
        t, *f = line.split()
        assert f[0::2] == ["--x", "--y", "--z"]
        x, y, z = (float(v) for v in f[1::2])
        assert x == p[0] and z == p[2]  # {x}: every digit of the mm value
        assert y == pytest.approx(p[1], abs=5e-4)  # {y:.3f}: to the micrometre
        # Run between the last image of the previous position and the first of this one.
        when = [datetime.fromisoformat(r["time"]).timestamp() for r in saved if r["position"] == i + 1]
        assert float(t) < min(when)
        if i:
            before = [datetime.fromisoformat(r["time"]).timestamp() for r in saved if r["position"] == i]
            assert max(before) < float(t) + 0.002  # the log's times are to the millisecond


def test_a_failing_move_command_is_one_line_naming_campaign_toml(tmp_path, monkeypatch, capsys):
    root = _move_campaign(tmp_path, "--fail", "{x}", "{y}", "{z}")
    code, _, err = run_in_process(["capture", root, "--camera", FAST_SIM, "--yes"], monkeypatch, capsys)
    _one_line_error(
        code,
        err,
        str(root / "campaign.toml"),
        "capture.move_command",
        "failed with exit status 3",
        "robot controller: axis 2 in fault",
    )
    assert len((tmp_path / "moves.txt").read_text(encoding="utf-8").splitlines()) == 1
    assert not (root / "images").exists() or not _images_on_disk(root)
    assert _log(root)[-1]["event"] == "stop"
    # A command that cannot be started at all: named too.
    toml = (root / "campaign.toml").read_text(encoding="utf-8")
    i = toml.index("move_command")
    (root / "campaign.toml").write_text(toml[:i] + 'move_command = "no-such-robot-mover {x} {y} {z}"\n')
    code, _, err = run_in_process(["capture", root, "--camera", FAST_SIM, "--yes"], monkeypatch, capsys)
    _one_line_error(
        code, err, "campaign.toml", "capture.move_command", "no-such-robot-mover", "could not run"
    )
