"""A guided capture: walk the campaign's plan, tell the operator what to do, save good images.

:func:`run_capture` goes through the steps of :func:`stiffmap.capture.plan.capture_steps` and,
for each image not yet on disk:

1. brings the rig to the step's state: moves the robot (``[capture] move_command``, or the
   operator does and confirms), removes the load or hangs the step's load (the operator, or an
   actuator: the simulated camera is one);
2. grabs frames and judges each (:class:`~stiffmap.capture.settle.SettleMonitor`) until the
   platform has settled with both boards found and no board saturated, then keeps ``frames``
   settled frames in a row (a frame that is not settled starts the count again);
3. writes the image -- the mean of the frames (``average = true``) or each frame as one repeat
   -- atomically under the campaign's file name, never over an existing file without asking;
4. records it in the capture log (:data:`LOG_NAME`, JSON lines in the campaign directory): the
   time, the files, the frames' timestamps and the settle figures; and skips, redos, stops,
   failures.

An interrupted capture resumes at the first missing image (images on disk are never taken
again). The operator may skip an image or redo the last one (:class:`Operator`); with
``--yes`` (:class:`AutoOperator`) nothing is asked and a step that gets no good settled frame
within ``timeout_s`` ends the capture with a clear message (the images saved so far are kept).
``timeout_s`` counts the source's time (a device's clock, a file's position, the simulated
clock) and the wall clock: a step gives up when either passes it (the wall clock: at least
:data:`MIN_WALL_S`, for a simulated camera rendering slower than real time with a short
``timeout_s``). A simulated camera of a billion frames per second, whose clock barely moves,
gives up after ``timeout_s`` of waiting.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import shlex
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, runtime_checkable

import cv2
import numpy as np

from ..campaign.runner import read_cameras
from ..campaign.spec import CampaignSpec
from ..errors import InputError, Stop
from ..io import atomic_write_bytes, to_jsonable
from ..targets import Chessboard, parse_board_size
from .plan import capture_steps, load_instruction
from .settle import FrameCheck, SettleMonitor, SettleSettings
from .sources import CameraSource, SourceEnded

__all__ = [
    "LOG_NAME",
    "Actuator",
    "Operator",
    "AutoOperator",
    "ViewState",
    "CaptureSummary",
    "CaptureStopped",
    "run_capture",
    "encode_for",
    "monitor_for",
]

#: The capture log in the campaign directory (one JSON object per line).
LOG_NAME = "capture_log.jsonl"
#: A step's wait on the wall clock ends after ``timeout_s``, but never before this (s).
MIN_WALL_S = 10.0
#: Most settled frames per image (``--frames``; ``[capture] frames`` has the same bound): they
#: are held in memory until the image is written.
MAX_FRAMES = 1000


@runtime_checkable
class Actuator(Protocol):
    """A rig that moves the robot and applies loads itself (the simulated camera is one)."""

    def move_to(self, xyz_mm) -> None: ...

    def set_load(self, force_n=None) -> None: ...


class Operator(Protocol):
    """The person at the rig (or a script): confirms actions, answers questions.

    ``confirm`` returns ``"go"`` (done, take the image), ``"skip"`` (leave this image out),
    ``"redo"`` (take the last saved image again) or ``"quit"``.
    """

    def confirm(self, instruction: str) -> str: ...

    def overwrite(self, file: str) -> bool: ...

    def gave_up(self, message: str) -> str: ...


class AutoOperator:
    """No questions (``--yes``): every action is taken as done, nothing is overwritten, and an
    image that gets no good settled frame in time stops the capture."""

    def confirm(self, instruction: str) -> str:
        return "go"

    def overwrite(self, file: str) -> bool:
        return False

    def gave_up(self, message: str) -> str:
        return "quit"


class CaptureStopped(Stop):
    """The capture stopped before the end (a source that ended, a step that timed out, the operator):
    a :class:`~stiffmap.errors.Stop`, not an input error; the images saved so far are kept."""


@dataclass
class ViewState:
    """What the live view shows (:mod:`stiffmap.capture.view`)."""

    campaign: str
    step: int = 0
    steps: int = 0
    image: str = ""
    on_disk: int = 0
    instruction: str = ""
    check: FrameCheck | None = None
    collected: int = 0
    needed: int = 1
    settle_seconds: float = 1.0
    status: str = ""
    saved: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class CaptureSummary:
    """What a capture did.

    Attributes
    ----------
    saved : tuple of str
        Image files written (relative paths).
    skipped : tuple of str
        Images the operator left out.
    present : int
        Images already on disk at the start.
    missing : tuple of str
        Images of the plan still missing at the end.
    frames : int
        Frames grabbed.
    stopped : str or None
        Why the capture stopped early (None: it went to the end of the plan).
    """

    saved: tuple[str, ...]
    skipped: tuple[str, ...]
    present: int
    missing: tuple[str, ...]
    frames: int
    stopped: str | None = None


def encode_for(path: str, image: np.ndarray) -> bytes:
    """Encode an 8-bit image in the format its file name says (.png, .jpg/.jpeg, .tif/.tiff, .bmp)."""
    ext = Path(path).suffix.lower()
    params: list[int] = []
    if ext in (".jpg", ".jpeg"):
        params = [cv2.IMWRITE_JPEG_QUALITY, 95]
    elif ext == ".png":
        # Huffman coding only: camera noise leaves little for LZ77 to find (a 5 MP frame of the
        # simulated camera: 75 ms and 2.2 MB against 96 ms and 2.6 MB, decoded in 28 ms against 45).
        params = [
            cv2.IMWRITE_PNG_COMPRESSION,
            1,
            cv2.IMWRITE_PNG_STRATEGY,
            cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY,
        ]
    elif ext not in (".tif", ".tiff", ".bmp"):
        raise InputError(
            f"cannot write an image named {path!r}: use .png, .jpg, .tif or .bmp in the [images] patterns"
        )
    ok, buf = cv2.imencode(ext, image, params)
    if not ok:  # pragma: no cover
        raise InputError(f"OpenCV could not encode {path}")
    return buf.tobytes()


def monitor_for(spec: CampaignSpec, root: Path, *, refine: str = "corners") -> SettleMonitor:
    """The settle monitor of a campaign: its camera file, its boards and ``[capture]`` settings."""
    _, rig = read_cameras(spec, root)
    t = spec.targets
    mobile = Chessboard(*parse_board_size(t.mobile.board), t.mobile.square_mm)
    fixed = Chessboard(*parse_board_size(t.fixed.board), t.fixed.square_mm)
    cap = spec.capture_settings
    settings = SettleSettings(settle_seconds=cap.settle_seconds, vibration_mm=cap.vibration_mm, refine=refine)
    return SettleMonitor(rig.cameras[0].camera, mobile, fixed, np.asarray(t.fixed.fixed2base), settings)


class _Log:
    """The capture log: one JSON object per line, flushed and synced line by line."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._f = open(path, "a", encoding="utf-8")  # noqa: SIM115 - closed by close()

    def write(self, event: str, **data) -> None:
        rec = {"time": _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds"), "event": event, **data}
        self._f.write(json.dumps(to_jsonable(rec), allow_nan=False) + "\n")
        self._f.flush()
        os.fsync(self._f.fileno())

    def close(self) -> None:
        self._f.close()


def _fmt(v: float) -> str:
    return f"{v:g}"


def _run_move(template: str, xyz, root: Path) -> None:
    x, y, z = (float(v) for v in xyz)
    line = template.format(x=x, y=y, z=z)
    try:
        argv = shlex.split(line)
        proc = subprocess.run(argv, cwd=root, capture_output=True, text=True, timeout=600)
    except (ValueError, OSError, subprocess.TimeoutExpired) as e:
        raise CaptureStopped(
            f"capture.move_command {line!r} could not run: {e}", source=str(root / "campaign.toml")
        ) from None
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or [""]
        raise CaptureStopped(
            f"capture.move_command {line!r} failed with exit status {proc.returncode}: {tail[0][:200]}",
            source=str(root / "campaign.toml"),
        )


def _remove_stale_temporaries(root: Path, steps) -> None:
    """Remove what a capture killed while writing left: the atomic writer's temporary files
    (``.NAME.*.tmp`` beside each image NAME); the images themselves are whole or absent."""
    for step in steps:
        for rel in step.files:
            p = root / rel
            if p.parent.is_dir():
                for tmp in p.parent.glob(f".{p.name}.*.tmp"):
                    tmp.unlink(missing_ok=True)


@dataclass
class _Session:
    """One capture's state, passed between its steps (:func:`run_capture`)."""

    root: Path
    spec: CampaignSpec
    source: CameraSource
    operator: Operator
    monitor: SettleMonitor
    view: Callable[[ViewState], None] | None
    steps: list
    n_frames: int
    average: bool
    actuator: Actuator | None
    loads: list
    n_pos: int
    present: int
    state: ViewState
    log: _Log
    saved: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    grabbed: int = 0
    position: int | None = None
    load_on: int | None = None  # None: no load (or not known to hang: the operator is told)
    last_done: int | None = None
    stopped: str | None = None
    redo_steps: set[int] = field(default_factory=set)

    def show(self, status: str = "") -> None:
        if status:
            self.state.status = status
        if self.view is not None:
            self.view(self.state)


def run_capture(
    root: str | os.PathLike,
    spec: CampaignSpec,
    source: CameraSource,
    *,
    operator: Operator | None = None,
    frames: int | None = None,
    view: Callable[[ViewState], None] | None = None,
    monitor: SettleMonitor | None = None,
) -> CaptureSummary:
    """Take a campaign's missing images from a live camera (see the module docstring).

    Parameters
    ----------
    root : path
        The campaign directory.
    spec : CampaignSpec
    source : CameraSource
        Open (the caller's ``with`` block).
    operator : Operator, optional
        Default :class:`AutoOperator` (no questions).
    frames : int, optional
        Settled frames per image (default ``[capture] frames``).
    view : callable, optional
        Called with the :class:`ViewState` after every frame and event (the live view).
    monitor : SettleMonitor, optional
        Default :func:`monitor_for` the campaign.

    Returns
    -------
    CaptureSummary

    Raises
    ------
    InputError
        A camera whose image size is not the campaign camera's, a bad ``[images]`` file name.
    CaptureStopped
        A source that ended, a step without a good settled frame within ``timeout_s`` (with
        :class:`AutoOperator`), a move command that failed: the images saved before are kept
        and in the log.
    """
    s = _start(Path(root), spec, source, operator or AutoOperator(), frames, view, monitor)
    try:
        i: int | None = 0
        while i is not None and i < len(s.steps):
            i = _take_step(s, i)
    except SourceEnded as e:
        s.stopped = str(e)
        s.log.write("stop", reason=s.stopped)
        raise CaptureStopped(
            f"{e.detail}: the images saved so far are kept; run stiffmap capture again to go on",
            source=e.source,
        ) from None
    except CaptureStopped as e:
        s.log.write("stop", reason=str(e))
        raise
    except KeyboardInterrupt:
        s.stopped = "interrupted"
        s.log.write("stop", reason=s.stopped)
        raise
    finally:
        missing = tuple(f for st in s.steps for f in st.files if not (s.root / f).is_file())
        if s.stopped is None and not missing:
            s.log.write("end", saved=len(s.saved), skipped=len(s.skipped))
        s.log.close()
    return CaptureSummary(tuple(s.saved), tuple(s.skipped), s.present, missing, s.grabbed, s.stopped)


def _frames_per_image(spec: CampaignSpec, root: Path, frames: int | None) -> tuple[int, bool]:
    """The settled frames of one image (``--frames`` or ``[capture] frames``) and whether they
    are averaged into one image (else each is one repeat)."""
    cap = spec.capture_settings
    n_frames = int(frames) if frames is not None else cap.frames
    if not 1 <= n_frames <= MAX_FRAMES:
        raise InputError(
            f"--frames must be 1 to {MAX_FRAMES} (the settled frames of one image, held in memory), "
            f"got {n_frames}"
        )
    average = cap.average or n_frames == 1
    if not average and n_frames != spec.repeats:
        raise InputError(
            f"--frames {n_frames} with capture.average = false keeps the frames as the repeats: "
            f"it must equal repeats = {spec.repeats}",
            source=str(root / "campaign.toml"),
        )
    return n_frames, average


def _start(root, spec, source, operator, frames, view, monitor) -> _Session:
    """Check the options and the camera, open the log and write its ``start`` line."""
    cap = spec.capture_settings
    n_frames, average = _frames_per_image(spec, root, frames)
    steps = capture_steps(spec, root, group_repeats=not average)
    monitor = monitor or monitor_for(spec, root)
    want = monitor.tracker.camera.image_size
    if tuple(source.image_size) != tuple(want) and source.image_size != (0, 0):
        raise InputError(
            f"{source.name} gives {source.image_size[0]}x{source.image_size[1]} px images; the campaign's "
            f"camera is calibrated at {want[0]}x{want[1]} px: use the camera and resolution it was "
            "calibrated with"
        )
    actuator = source if isinstance(source, Actuator) else None
    _remove_stale_temporaries(root, steps)
    loads = spec.loads.resolve(spec.g)
    n_pos = len({s.position for s in steps})
    present = sum(all((root / f).is_file() for f in s.files) for s in steps)
    state = ViewState(
        campaign=spec.name,
        steps=len(steps),
        on_disk=present,
        needed=n_frames if average else 1,
        settle_seconds=cap.settle_seconds,
    )
    s = _Session(
        root,
        spec,
        source,
        operator,
        monitor,
        view,
        steps,
        n_frames,
        average,
        actuator,
        loads,
        n_pos,
        present,
        state,
        _Log(root / LOG_NAME),
    )
    s.log.write(
        "start",
        camera=source.name,
        frames=n_frames,
        average=average,
        settle_seconds=cap.settle_seconds,
        images=sum(len(st.files) for st in steps),
        on_disk=present,
    )
    return s


def _take_step(s: _Session, i: int) -> int | None:
    """Take step ``i`` (or skip it, redo the last one, stop): the next step's index, None to stop."""
    step = s.steps[i]
    on_disk = [f for f in step.files if (s.root / f).is_file()]
    if len(on_disk) == len(step.files) and i not in s.redo_steps:
        return i + 1
    s.state.step, s.state.image = i + 1, ", ".join(step.files)
    instruction = _instruction(s, step)
    s.state.instruction = instruction
    s.state.check, s.state.collected = None, 0
    s.show("waiting for the operator")
    move_command = s.spec.capture_settings.move_command
    if s.position != step.position and move_command:
        _run_move(move_command, step.xyz_mm, s.root)
    answer = s.operator.confirm(instruction)
    if answer == "quit":
        s.stopped = "stopped by the operator"
        s.log.write("stop", reason=s.stopped, at=list(step.files))
        return None
    if answer == "skip":
        s.skipped.extend(f for f in step.files if f not in on_disk)
        s.log.write("skip", files=[f for f in step.files if f not in on_disk])
        return i + 1
    if answer == "redo":
        return _redo(s, i)
    _set_rig(s, step)
    kept, checks = _settled_frames(s, step)
    _save(s, i, step, kept, checks)
    s.last_done = i
    return i + 1


def _instruction(s: _Session, step) -> str:
    """What the operator does to bring the rig to the step's state (1. of the module docstring)."""
    actions = []
    if s.position != step.position:
        if s.load_on is not None:
            actions.append("remove the load")
        actions.append(
            f"position {step.position} of {s.n_pos}: move the robot to "
            f"({', '.join(_fmt(v) for v in step.xyz_mm)}) mm"
        )
    if step.state == "unloaded":
        if s.position == step.position and s.load_on is not None:
            actions.append("remove the load")
        elif s.position != step.position:
            actions.append("no load hangs")
    else:
        if s.position == step.position and s.load_on is not None:
            actions.append("remove the load")
        actions.append(load_instruction(s.spec, step.load))
    what = f"{step.state} image, load {step.load}, repeat {', '.join(str(sh.repeat) for sh in step.shots)}"
    return "; ".join(actions) + f"  ({what})"


def _redo(s: _Session, i: int) -> int:
    """The operator asked to take the last saved image again: the step to go to."""
    if s.last_done is None:
        s.show("nothing to redo yet")
        return i
    prev = s.steps[s.last_done]
    if not all(s.operator.overwrite(f) for f in prev.files if (s.root / f).is_file()):
        s.show("not redone: the images on disk are kept")
        return i
    s.log.write("redo", files=list(prev.files))
    s.redo_steps.add(s.last_done)
    return s.last_done


def _set_rig(s: _Session, step) -> None:
    """Move the robot and hang the step's load with an actuator; note the rig's new state."""
    if s.actuator is not None:
        if s.position != step.position:
            s.actuator.move_to(step.xyz_mm)
            s.load_on = None
        if s.load_on is not None:
            s.actuator.set_load(None)
        if step.state == "loaded":
            s.actuator.set_load(s.loads[step.load - 1].force)
    s.position = step.position
    s.load_on = step.load if step.state == "loaded" else None


def _settled_frames(s: _Session, step) -> tuple[list, list[FrameCheck]]:
    """Grab frames until settled, then ``n_frames`` settled frames in a row (2. of the module
    docstring); a step that times out asks the operator (``quit``: :class:`CaptureStopped`)."""
    cap = s.spec.capture_settings
    s.monitor.reset()
    kept: list = []
    checks: list[FrameCheck] = []
    t_start: float | None = None
    wall_start = 0.0  # the wall clock at the first frame (as t_start the source's)
    while True:
        frame = s.source.grab()
        s.grabbed += 1
        t = float(frame.timestamp_s)
        if t_start is None:
            t_start, wall_start = t, time.monotonic()
        c = s.monitor.check(frame.image, t)
        s.state.check = c
        if c.settled:
            kept.append(frame)
            checks.append(c)
        else:
            kept, checks = [], []
        s.state.collected = len(kept)
        if len(kept) >= s.n_frames:
            return kept, checks
        status = c.problem or (
            "settled: taking the image" if c.settled else "waiting for the platform to settle"
        )
        s.show(status)
        waited = time.monotonic() - wall_start
        if t - t_start > cap.timeout_s or waited > max(cap.timeout_s, MIN_WALL_S):
            message = f"{', '.join(step.files)}: no good settled frame in {cap.timeout_s:g} s" + (
                f"; the last frame: {c.problem}" if c.problem else " (the platform did not settle)"
            )
            s.log.write("timeout", files=list(step.files), reason=message)
            if s.operator.gave_up(message) == "quit":
                raise CaptureStopped(message + "; the images saved so far are kept")
            s.monitor.reset()
            kept, checks, t_start = [], [], None


def _save(s: _Session, i: int, step, kept: list, checks: list[FrameCheck]) -> None:
    """Write the step's image(s) from its settled frames and log them (3. and 4. of the module
    docstring); an image on disk is overwritten only on a redo or when the operator says so."""
    images = [np.asarray(f.image) for f in kept]
    if s.average and len(images) == 1:
        outs = [(step.files[0], images[0])]
    elif s.average:
        outs = [(step.files[0], np.clip(np.rint(np.mean(images, axis=0)), 0, 255).astype(np.uint8))]
    else:
        outs = list(zip(step.files, images, strict=True))
    redo = i in s.redo_steps
    written = []
    for rel, img in outs:
        if (s.root / rel).is_file() and not redo and not s.operator.overwrite(rel):
            continue
        atomic_write_bytes(s.root / rel, encode_for(rel, img))
        written.append(rel)
    s.redo_steps.discard(i)
    truth = {}
    if all(hasattr(f, "settled") for f in kept):
        truth = {
            "settled": [bool(f.settled) for f in kept],
            "envelope_mm": [float(f.envelope_mm) for f in kept],
        }
    s.log.write(
        "saved",
        files=written,
        position=step.position,
        state=step.state,
        load=step.load,
        repeats=[sh.repeat for sh in step.shots],
        frames=len(kept),
        averaged=s.average,
        timestamps_s=[float(f.timestamp_s) for f in kept],
        settle=checks[-1].figures(),
        **({"source_truth": truth} if truth else {}),
    )
    s.saved.extend(written)
    s.state.saved = s.saved[-3:]
    s.state.on_disk += len(written)
    s.show(f"saved {', '.join(written)}")
