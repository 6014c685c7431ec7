"""A virtual vision campaign: every image's true poses, lighting and noise seed (no I/O).

:func:`plan_campaign` turns a :class:`SimConfig` (scene, robot, positions,
loads, repeats, seed) into the list of images a real experiment would take --
for each position, load case and repeat an unloaded and a loaded image
(``docs/simulation.md``) -- each with the platform's true pose, the lighting
and the seed of its noise; :func:`render_job` renders one of them. The
stiffness is evaluated at the commanded positions: that is the truth.

Randomness: the seed and the 1-based indices (position, load, repeat) key a
:class:`numpy.random.SeedSequence`, so every image is the same whatever the
order or the number of processes that render them.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InputError
from ..geometry import matrix_from_euler
from ..loads import LoadCase
from ..models.base import PoseError
from ..rig import CAMERA_FIELD
from ..units import G_REFERENCE_PAPER
from .render import Photometry, Rendering, encode_image, render
from .robot import VirtualRobot, translational_stiffness
from .scene import Scene

__all__ = [
    "SimConfig",
    "ImageJob",
    "CampaignPlan",
    "plan_campaign",
    "render_job",
    "seeded_generator",
    "DEFAULT_PATTERNS",
    "DEFAULT_CALIBRATION_VIEWS",
]

#: Calibration views rendered before a campaign, by default (a careful lab takes about 20).
DEFAULT_CALIBRATION_VIEWS = 20

#: The campaign spec's default image names (1-based indices).
DEFAULT_PATTERNS = (
    "images/p{position:02d}/l{load:02d}_r{repeat:02d}_unloaded.png",
    "images/p{position:02d}/l{load:02d}_r{repeat:02d}_loaded.png",
)
#: When the robot stays at a position: one unloaded image per repeat, then each load's image.
STAYING_PATTERNS = (
    "images/p{position:02d}/r{repeat:02d}_unloaded.png",
    "images/p{position:02d}/l{load:02d}_r{repeat:02d}_loaded.png",
)


@dataclass(frozen=True)
class SimConfig:
    """What to simulate.

    Attributes
    ----------
    scene : Scene
        Camera and boards.
    robot : VirtualRobot
        Stiffness field and positioning noise.
    positions : ndarray, shape (n, 3)
        Commanded positions of the tool point, base frame, mm.
    loads : tuple of LoadCase
        Forces (N, base frame) applied at the robot's load point.
    repeats : int
        Measurements (unloaded + loaded image pairs) per position and load case.
    seed : int
        Seed of every random draw.
    photometry : Photometry
        Camera response and noise (per image, the gain and offset are jittered).
    gain_jitter : float
        Relative 1 sigma of the illumination between images.
    offset_jitter_dn : float
        1 sigma of the black level between images, DN.
    image_format : {"png", "jpeg"}
    jpeg_quality : int
    name : str
        Campaign name.
    g : float
        Gravity written to campaign.toml (m/s^2).
    border_px : float
        Every board must stay this far inside the image in every image.
    robot_stays : bool
        False: the robot reaches the position anew for every measurement (its
        repeatability moves each unloaded/loaded pair), and each load case of each
        repeat has its own unloaded image. True: it reaches each position once and
        stays during all its loads and repeats (only the per-image jitter remains);
        each repeat takes one unloaded image, then one image per load, and the
        campaign is written with ``pairing = "mean-reference"``.
    calibration_views : int
        Views of a calibration board rendered before the campaign
        (:mod:`stiffmap.sim.calibration_views`), from which the campaign's camera.json is
        calibrated as a lab would (default 20); 0: the campaign gets the true camera.
    orientations : ndarray, shape (n, 3), rad, optional
        The platform's commanded roll, pitch, yaw at each position (R = Rz(yaw) Ry(pitch)
        Rx(roll)), for a robot whose platform turns (:attr:`VirtualRobot.turns`); the
        platform's board turns with it. None: level.
    """

    scene: Scene
    robot: VirtualRobot
    positions: np.ndarray
    loads: tuple[LoadCase, ...]
    repeats: int = 3
    seed: int = 0
    photometry: Photometry = field(default_factory=Photometry)
    gain_jitter: float = 0.03
    offset_jitter_dn: float = 1.0
    image_format: str = "png"
    jpeg_quality: int = 95
    name: str = "virtual test-bed"
    g: float = G_REFERENCE_PAPER
    border_px: float = 20.0
    robot_stays: bool = False
    calibration_views: int = DEFAULT_CALIBRATION_VIEWS
    orientations: np.ndarray | None = None

    def __post_init__(self) -> None:
        P = np.array(self.positions, dtype=np.float64)
        if P.ndim != 2 or P.shape[1] != 3 or P.shape[0] == 0 or not np.all(np.isfinite(P)):
            raise ValueError(f"positions must be a non-empty (n, 3) array of finite mm, got shape {P.shape}")
        P.setflags(write=False)
        object.__setattr__(self, "positions", P)
        if self.orientations is not None:
            A = np.array(self.orientations, dtype=np.float64)
            if A.shape != P.shape or not np.all(np.isfinite(A)):
                raise ValueError(
                    f"orientations must be a finite ({P.shape[0]}, 3) array of rad, got {A.shape}"
                )
            if not self.robot.turns and np.any(A):
                raise ValueError("orientations: this robot's platform does not turn")
            A.setflags(write=False)
            object.__setattr__(self, "orientations", A)
        loads = tuple(self.loads)
        if not loads or not all(isinstance(ld, LoadCase) for ld in loads):
            raise ValueError("loads must be a non-empty sequence of LoadCase")
        object.__setattr__(self, "loads", loads)
        if int(self.repeats) < 1:
            raise ValueError(f"repeats must be >= 1, got {self.repeats}")
        object.__setattr__(self, "repeats", int(self.repeats))
        if int(self.seed) < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")
        object.__setattr__(self, "seed", int(self.seed))
        fmt = str(self.image_format).lower()
        if fmt not in ("png", "jpeg", "jpg"):
            raise ValueError(f"image_format must be png or jpeg, got {self.image_format!r}")
        object.__setattr__(self, "image_format", "jpeg" if fmt == "jpg" else fmt)
        n_cal = int(self.calibration_views)
        if n_cal != 0 and n_cal < 3:
            raise ValueError(
                f"calibration_views must be 0 (the true camera) or at least 3 (Zhang's method), "
                f"got {self.calibration_views!r}"
            )
        object.__setattr__(self, "calibration_views", n_cal)
        for k in ("gain_jitter", "offset_jitter_dn"):
            v = float(getattr(self, k))
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{k} must be a finite number >= 0, got {getattr(self, k)!r}")

    @property
    def patterns(self) -> tuple[str, str]:
        """(unloaded, loaded) image-name patterns, with the format's extension (and ``{camera}``
        with a rig: an :class:`ImageJob`'s ``file`` is then the name of its image set)."""
        pats = STAYING_PATTERNS if self.robot_stays else DEFAULT_PATTERNS
        if self.scene.rig is not None:  # one image per camera: ..._unloaded_{camera}.png
            pats = tuple(p[: -len(".png")] + "_" + CAMERA_FIELD + ".png" for p in pats)
        if self.image_format == "png":
            return pats
        return tuple(p[: -len(".png")] + ".jpg" for p in pats)


@dataclass(frozen=True)
class ImageJob:
    """One image to render and its truth.

    Attributes
    ----------
    file : str
        Path relative to the campaign directory.
    position, load, repeat : int
        1-based indices.
    state : {"unloaded", "loaded"}
    commanded_mm : ndarray, shape (3,)
    tcp2base : ndarray, shape (4, 4)
        True platform pose in this image, mm.
    gain, offset_dn : float
        Photometry of this image (illumination change).
    """

    file: str
    position: int
    load: int
    repeat: int
    state: str
    commanded_mm: np.ndarray
    tcp2base: np.ndarray
    gain: float
    offset_dn: float

    @property
    def spawn_key(self) -> tuple[int, int, int, int]:
        return (self.position, self.load, self.repeat, 0 if self.state == "unloaded" else 1)


@dataclass(frozen=True)
class CampaignPlan:
    """Every image of a campaign and the true stiffness.

    Attributes
    ----------
    jobs : tuple of ImageJob
        In acquisition order: position, load case, repeat, unloaded then loaded.
    K : ndarray, shape (n, m, m)
        Field at each commanded position (m = 3, or 6 at the tool point).
    K3 : ndarray, shape (n, 3, 3), N/mm
        The translational stiffness a force-only identification recovers.
    """

    jobs: tuple[ImageJob, ...]
    K: np.ndarray
    K3: np.ndarray


def seeded_generator(seed: int, *key: int) -> np.random.Generator:
    """The random generator of one draw of a simulation: ``seed`` and the draw's key (ints).

    Campaign images use 1-based (position, ...) keys; keys starting with 0 are free for
    draws that belong to no position (the calibration views).
    """
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=tuple(int(k) for k in key)))


def plan_campaign(config: SimConfig) -> CampaignPlan:
    """Every image's true poses and photometry; checks that the boards stay in view.

    Raises
    ------
    InputError
        If the stiffness field is bad at a position, or a board leaves the image
        in some image (naming the position, load and repeat).
    """
    cfg = config
    P = cfg.positions
    A = cfg.orientations
    try:
        K = cfg.robot.stiffness(P, A)
    except PoseError as e:
        if e.index is None:
            raise
        p = P[e.index]
        turned = (
            "" if A is None else f", roll/pitch/yaw {', '.join(f'{v:g}' for v in np.degrees(A[e.index]))} deg"
        )
        raise InputError(
            f"position {e.index + 1} ({', '.join(f'{v:g}' for v in p)}) mm{turned}: the robot model has no "
            f"stiffness there ({e.reason or e.detail})",
            items={"position": e.index + 1},
        ) from None
    K3 = translational_stiffness(K, cfg.robot.load_point_mm)
    pat_u, pat_l = cfg.patterns
    jobs: list[ImageJob] = []
    ph = cfg.photometry
    for ip, p in enumerate(P, start=1):
        R = None if A is None else matrix_from_euler(A[ip - 1])
        stay = cfg.robot.reach(p, seeded_generator(cfg.seed, ip), R) if cfg.robot_stays else None
        for il, ld in enumerate(cfg.loads, start=1):
            for ir in range(1, cfg.repeats + 1):
                rng = seeded_generator(cfg.seed, ip, il, ir)
                reached = cfg.robot.reach(p, rng, R) if stay is None else stay
                T_u = cfg.robot.image_pose(reached, rng)
                T_l = cfg.robot.image_pose(reached, rng, K[ip - 1], ld.force)
                for state, T, pat in (("unloaded", T_u, pat_u), ("loaded", T_l, pat_l)):
                    if state == "unloaded" and cfg.robot_stays and il > 1:
                        continue  # one unloaded image per repeat, shared by its loads
                    gain = ph.gain * max(1.0 + cfg.gain_jitter * rng.standard_normal(), 0.05)
                    offset = max(ph.offset_dn + cfg.offset_jitter_dn * rng.standard_normal(), 0.0)
                    why = cfg.scene.visibility_problem(T, border_px=cfg.border_px)
                    if why:
                        raise InputError(
                            f"position {ip} ({', '.join(f'{v:g}' for v in p)}) mm, load {il}, repeat {ir}, "
                            f"{state}: {why}",
                            items={"position": ip, "load": il, "repeat": ir},
                        )
                    T.setflags(write=False)
                    jobs.append(
                        ImageJob(
                            file=pat.format(position=ip, load=il, repeat=ir, camera=CAMERA_FIELD),
                            position=ip,
                            load=il,
                            repeat=ir,
                            state=state,
                            commanded_mm=p,
                            tcp2base=T,
                            gain=float(gain),
                            offset_dn=float(offset),
                        )
                    )
    return CampaignPlan(tuple(jobs), K, K3)


def render_job(
    scene: Scene,
    photometry: Photometry,
    seed: int,
    job: ImageJob,
    image_format: str = "png",
    jpeg_quality=95,
    camera: int = 0,
) -> tuple[bytes, Rendering]:
    """Render and encode one planned image (camera ``camera``'s, index, with a rig).

    Each camera of a rig has its own noise (the draw's key ends with the camera's index).

    Returns
    -------
    data : bytes
        The encoded image.
    rendering : Rendering
        The image array and the true poses and corners of the ``fixed`` and
        ``mobile`` targets.
    """
    ph = replace(photometry, gain=job.gain, offset_dn=job.offset_dn)
    key = job.spawn_key if scene.rig is None else (*job.spawn_key, camera)
    r = render(
        scene.cameras[camera][1],
        scene.targets(job.tcp2base, camera),
        photometry=ph,
        seed=seeded_generator(seed, *key),
    )
    return encode_image(r.image, image_format, jpeg_quality=jpeg_quality), r
