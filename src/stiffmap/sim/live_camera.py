"""The virtual test-bed as a live camera: what the camera sees while a capture goes on.

:class:`SimulatedCamera` follows the camera-source protocol of :mod:`stiffmap.capture.sources`
(open, grab a frame with its timestamp, close, image size; a context manager) and is also the
rig's actuators: :meth:`~SimulatedCamera.move_to` commands the robot to a position and
:meth:`~SimulatedCamera.set_load` hangs a load (or removes it). Each :meth:`~SimulatedCamera.grab`
advances the simulated clock by one frame period (tests never sleep) and renders the scene for
the platform's pose at that instant (:class:`~stiffmap.sim.live_render.FrameRenderer`: the
fixed board and the background once, then only the mobile board's part of each frame and the
frame's noise; the image of a full :func:`~stiffmap.sim.render.render`, bit for bit):

- **repeatability**: reaching a commanded position, the platform lands off by the robot's
  repeatability (:meth:`stiffmap.sim.robot.VirtualRobot.reach`), kept until the next move;
- **static deflection**: with a load F hung, the platform sits at the compliant pose
  ``K^-1 F`` (and its rotation, for a 6x6 field) from the reached pose;
- **oscillation**: after a load change the platform swings about its new static pose as a
  damped sinusoid of the change of static deflection, ``d(t) = d0 exp(-t / tau) cos(2 pi f t)``
  (translation and rotation alike), ``d0`` the old static pose minus the new one; a move ends
  with a small ring ``move_ring_mm`` along the motion;
- **vibration**: every frame adds the robot's own jitter (``jitter_mm`` per axis), which no
  waiting removes.

The camera knows at every frame whether the platform had **settled**: the envelope of the
oscillation, ``(|d0_t| + L |d0_r|) exp(-t / tau)`` with ``L`` = 100 mm for the rotation, is below
``settled_mm`` (default the robot's per-frame vibration ``jitter_mm``, or 1 um without: the
swing is then lost in the motion the platform shows at rest, and a fraction of what a camera
measures: the demo's mobile board is measured to 1-5 um per frame). :class:`SimFrame` carries
it with the true pose, so a test can check that no saved image was taken before the platform settled.

Randomness: the seed and counters of moves and frames key every draw
(:func:`stiffmap.sim.testbed.seeded_generator`, keys starting with 0, 7), so the same calls give
the same frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Self

import numpy as np

from ..geometry import matrix_from_rotvec, rotvec_from_matrix
from .live_render import FrameRenderer
from .render import Photometry, render
from .robot import VirtualRobot
from .scene import Scene
from .testbed import seeded_generator

__all__ = ["SimFrame", "SimulatedCamera", "TableField", "ROTATION_LEVER_MM"]

#: Lever that turns the oscillation's rotation into a displacement for the settled test, mm.
ROTATION_LEVER_MM = 100.0
_KEY = (0, 7)  # seeded_generator keys of the live camera's draws (0: no campaign position)


@dataclass(frozen=True)
class SimFrame:
    """One frame of the simulated camera and its truth.

    Attributes
    ----------
    image : ndarray, shape (h, w) or (h, w, 3), uint8
    timestamp_s : float
        Simulated time, s.
    index : int
        0-based frame count since the camera was opened.
    tcp2base : ndarray, shape (4, 4)
        The platform's true pose in this frame, mm.
    envelope_mm : float
        Envelope of the oscillation at this frame (translation plus rotation times
        :data:`ROTATION_LEVER_MM`), mm.
    settled : bool
        ``envelope_mm`` below the camera's ``settled_mm``.
    """

    image: np.ndarray
    timestamp_s: float
    index: int
    tcp2base: np.ndarray
    envelope_mm: float
    settled: bool


@dataclass(frozen=True)
class TableField:
    """A stiffness field known only at some points (a simulated campaign's truth): K at each of them.

    Attributes
    ----------
    points : ndarray, shape (n, 3), mm
    K : ndarray, shape (n, m, m), m = 3 (N/mm) or 6 (at the tool point)
    """

    points: np.ndarray
    K: np.ndarray

    def __call__(self, points) -> np.ndarray:
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = []
        for p in P:
            d = np.linalg.norm(self.points - p, axis=1)
            i = int(np.argmin(d))
            if d[i] > 1e-6:
                raise ValueError(
                    f"the stiffness is known only at the campaign's positions, not at {p.tolist()} mm"
                )
            out.append(self.K[i])
        return np.array(out)


class SimulatedCamera:
    """A live camera looking at the virtual test-bed, and the actuators of its robot and loads.

    Parameters
    ----------
    scene : Scene
        Camera and boards (one camera).
    robot : VirtualRobot
        Stiffness field, repeatability, per-frame vibration (``jitter_mm``).
    photometry : Photometry, optional
    seed : int
    fps : float
        Frames per simulated second.
    frequency_hz : float
        Frequency of the platform's oscillation after a load change, Hz.
    time_constant_s : float
        Its decay time constant tau, s.
    settled_mm : float, optional
        Envelope below which the platform counts as settled, mm (default: the robot's
        ``jitter_mm``, or 1 um without jitter).
    move_ring_mm : float
        Amplitude of the ring a move ends with, mm, along the motion.
    name : str
    static_once : bool
        Render the static part of the scene (the fixed board, the background) once and only the
        mobile board's part of each frame (:class:`~stiffmap.sim.live_render.FrameRenderer`: the
        same image, bit for bit); False renders every frame in full.
    """

    def __init__(
        self,
        scene: Scene,
        robot: VirtualRobot,
        *,
        photometry: Photometry | None = None,
        seed: int = 0,
        fps: float = 10.0,
        frequency_hz: float = 2.2,
        time_constant_s: float = 0.25,
        settled_mm: float | None = None,
        move_ring_mm: float = 0.05,
        name: str = "simulated camera",
        static_once: bool = True,
    ) -> None:
        if scene.rig is not None:
            raise ValueError("the simulated live camera renders one camera; this scene has a rig")
        for k, v in (("fps", fps), ("frequency_hz", frequency_hz), ("time_constant_s", time_constant_s)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{k} must be a positive number, got {v!r}")
        self.scene = scene
        self.robot = robot
        self.photometry = photometry or Photometry()
        self.seed = int(seed)
        self.fps = float(fps)
        self.frequency_hz = float(frequency_hz)
        self.time_constant_s = float(time_constant_s)
        jit = robot.jitter_mm
        self.settled_mm = float(settled_mm) if settled_mm is not None else (jit if jit > 0 else 1e-3)
        self.move_ring_mm = float(move_ring_mm)
        self.name = name
        self.static_once = bool(static_once)
        self._renderer: FrameRenderer | None = None
        self.commanded_mm: np.ndarray | None = None
        self.force_n: np.ndarray | None = None
        self._reached = np.eye(4)
        self._static = np.eye(4)
        self._d0 = np.zeros(6)  # (translation mm, rotation vector rad) of the swing at its start
        self._t0 = 0.0  # when the swing started, s
        self._t = 0.0
        self._frames = 0
        self._moves = 0
        self._open = False

    # -- the protocol ---------------------------------------------------------------------

    @property
    def image_size(self) -> tuple[int, int]:
        return self.scene.camera.image_size

    def open(self) -> None:
        self._open = True

    def close(self) -> None:
        self._open = False

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def grab(self) -> SimFrame:
        """Advance the simulated clock by one frame period and render what the camera sees."""
        if not self._open:
            raise ValueError("the simulated camera is not open")
        if self.commanded_mm is None:
            raise ValueError("the simulated robot has not been moved to a position yet (move_to)")
        self._t += 1.0 / self.fps
        k = self._frames
        self._frames += 1
        rng = seeded_generator(self.seed, *_KEY, self._moves, k + 1)
        T = self.pose_at(self._t, rng)
        fixed, mobile = self.scene.targets(T)
        if self.static_once:
            if self._renderer is None:
                self._renderer = FrameRenderer(self.scene.camera, [fixed], self.photometry)
            image = self._renderer.frame([mobile], rng)
        else:
            image = render(self.scene.camera, [fixed, mobile], photometry=self.photometry, seed=rng).image
        env = self.envelope_mm()
        return SimFrame(image, self._t, k, T, env, env < self.settled_mm)

    # -- the actuators ----------------------------------------------------------------------

    def move_to(self, xyz_mm) -> None:
        """Command the robot to a position (no load may hang: a rig moves unloaded).

        The platform lands off by the robot's repeatability and rings ``move_ring_mm`` along
        the motion.
        """
        p = np.asarray(xyz_mm, dtype=np.float64).reshape(3)
        self.robot.stiffness(p)  # a position the field does not know fails here, not at a grab
        prev = self._static[:3, 3].copy()
        self._moves += 1
        self._reached = self.robot.reach(p, seeded_generator(self.seed, *_KEY, self._moves, 0))
        self.commanded_mm = p
        self.force_n = None
        self._static = self._reached.copy()
        step = self._static[:3, 3] - prev
        n = np.linalg.norm(step)
        d0 = np.zeros(6)
        if n > 0 and self._moves > 1:
            d0[:3] = self.move_ring_mm * step / n
        self._start_swing(d0)

    def set_load(self, force_n=None) -> None:
        """Hang a load (its force in N, base frame) or remove it (None); the platform swings to
        its new static pose."""
        if self.commanded_mm is None:
            raise ValueError("move the simulated robot to a position before hanging a load")
        old = self._static
        new = self._reached.copy()
        if force_n is not None:
            F = np.asarray(force_n, dtype=np.float64).reshape(3)
            K = self.robot.stiffness(self.commanded_mm)[0]
            u, w = self.robot.compliant_motion(K, F)
            new[:3, :3] = matrix_from_rotvec(w) @ new[:3, :3]
            new[:3, 3] += u
        self.force_n = None if force_n is None else np.asarray(force_n, dtype=np.float64).copy()
        d0 = np.concatenate([old[:3, 3] - new[:3, 3], rotvec_from_matrix(old[:3, :3] @ new[:3, :3].T)])
        self._static = new
        # The swing goes on from where the platform is: a change during a swing adds to it.
        d0 = d0 + self._swing_now()
        self._start_swing(d0)

    def wait(self, seconds: float) -> None:
        """Let simulated time pass without a frame (an operator confirming, a robot moving)."""
        self._t += max(float(seconds), 0.0)

    # -- the truth --------------------------------------------------------------------------

    @property
    def time_s(self) -> float:
        """The simulated clock, s."""
        return self._t

    def envelope_mm(self, t: float | None = None) -> float:
        """Envelope of the oscillation at time ``t`` (default now), mm (rotation times the lever)."""
        t = self._t if t is None else float(t)
        a = np.linalg.norm(self._d0[:3]) + ROTATION_LEVER_MM * np.linalg.norm(self._d0[3:])
        return float(a * math.exp(-max(t - self._t0, 0.0) / self.time_constant_s))

    @property
    def settled(self) -> bool:
        """The platform has settled now (:meth:`envelope_mm` below ``settled_mm``)."""
        return self.envelope_mm() < self.settled_mm

    def pose_at(self, t: float, rng: np.random.Generator | None = None) -> np.ndarray:
        """The platform's pose at time ``t``: static pose, swing and (with ``rng``) one frame's jitter."""
        d = self._swing(t)
        T = self._static.copy()
        T[:3, :3] = matrix_from_rotvec(d[3:]) @ T[:3, :3]
        T[:3, 3] += d[:3]
        if rng is not None and self.robot.jitter_mm > 0:
            T[:3, 3] += rng.normal(scale=self.robot.jitter_mm, size=3)
        return T

    def _swing(self, t: float) -> np.ndarray:
        s = max(t - self._t0, 0.0)
        return self._d0 * math.exp(-s / self.time_constant_s) * math.cos(2 * math.pi * self.frequency_hz * s)

    def _swing_now(self) -> np.ndarray:
        return self._swing(self._t)

    def _start_swing(self, d0: np.ndarray) -> None:
        self._d0 = np.asarray(d0, dtype=np.float64)
        self._t0 = self._t
