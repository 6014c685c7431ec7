"""The virtual robot: a known stiffness field, position repeatability, compliant poses.

A robot of the test-bed is a stiffness field ``K(points)`` over the workspace
-- from a mechanism model (:func:`delta_robot`, the default; anything with a
``stiffness(points)`` method) or any callable -- and the noise of its own
positioning. Conventions: ``docs/conventions.md`` (mm, N, rad; ``F = K u``).

The platform of a translational robot keeps its orientation; the tool point is
the origin of the ``tcp`` frame, whose axes are the base's. A load case is a
force F (N) applied at ``load_point_mm`` (tcp frame, default the tool point).

- 3x3 field (N/mm): the tool point moves by ``K^-1 F``; the orientation does not change.
- 6x6 field at the tool point (blocks N/mm, N, N*mm/rad; wrench (F, M) with M in
  N*mm, displacement (u, rotation vector)): the wrench at the tool point is
  (F, r x F) for the load point r, and ``(u, w) = K^-1 (F, r x F)``; the platform
  turns by the rotation vector w (base frame) about the tool point, which moves by u.

Repeatability: reaching a commanded position, the platform lands off by a
Gaussian error (``repeatability_mm`` per axis, ``repeatability_rad`` per axis of
a small rotation), shared by the unloaded and the loaded image of one
measurement (the robot does not move while the load is hung); each image adds
its own small jitter (``jitter_mm``: settling, vibration).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from ..geometry import euler_from_matrix, matrix_from_rotvec, transform_from
from ..models import arm6
from ..models.base import PoseError
from ..models.delta import DeltaRobot
from ..models.mobility import nearest_pose_note

__all__ = [
    "VirtualRobot",
    "delta_robot",
    "smooth_field",
    "with_rotational_compliance",
    "translational_stiffness",
    "serial_robot",
    "arm6_robot",
    "PlatformField",
    "platform_robot",
    "LEGS_NAME",
    "URDF_NAME",
    "LINKS_NAME",
]


def smooth_field(points) -> np.ndarray:
    """A smooth symmetric positive-definite stiffness field (N/mm) for tests and demos.

    Not a mechanism: principal stiffnesses 2, 4 and 9 N/mm (x-ish, y-ish, z-ish) at
    (0, 0, -300) mm, a third lower at the corners (+-200, +-200) of the reference grid,
    growing by a factor e^0.25 per 100 mm upwards, with principal axes turning slowly
    with x and y: ``K(p) = s(p) Q(p) diag(2, 4, 9) Q(p)^T`` with
    ``s = exp((z + 300) / 400) / (1 + (x^2 + y^2) / 160000)``; positive definite everywhere.

    Parameters
    ----------
    points : array_like, shape (N, 3), mm

    Returns
    -------
    ndarray, shape (N, 3, 3), N/mm
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    x, y, z = P[:, 0], P[:, 1], P[:, 2]
    s = np.exp((z + 300.0) / 400.0) / (1.0 + (x**2 + y**2) / 160000.0)
    a = 0.002 * x - 0.001 * y  # rad about z
    b = 0.0015 * y  # rad about x
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    Q = np.zeros((P.shape[0], 3, 3))
    # Q = Rz(a) Rx(b)
    Q[:, 0, 0] = ca
    Q[:, 0, 1] = -sa * cb
    Q[:, 0, 2] = sa * sb
    Q[:, 1, 0] = sa
    Q[:, 1, 1] = ca * cb
    Q[:, 1, 2] = -ca * sb
    Q[:, 2, 1] = sb
    Q[:, 2, 2] = cb
    D = np.array([2.0, 4.0, 9.0])
    return s[:, None, None] * np.einsum("nij,j,nkj->nik", Q, D, Q)


def with_rotational_compliance(field3, k_rot_nmm_per_rad: float, coupling_n: float = 0.0):
    """A 6x6 field at the tool point from a 3x3 field and a rotational stiffness.

    ``K6 = [[K3, c I], [c I, k_rot I]]`` (N/mm, N, N*mm/rad) with a small coupling
    c (N) between translation and rotation; positive definite when
    ``c^2 < lambda_min(K3) k_rot``.

    Parameters
    ----------
    field3 : callable
        (N, 3) mm -> (N, 3, 3) N/mm.
    k_rot_nmm_per_rad : float
        Rotational stiffness about each axis, N*mm/rad.
    coupling_n : float
        Coupling c, N.
    """
    k = float(k_rot_nmm_per_rad)
    c = float(coupling_n)
    if not (math.isfinite(k) and k > 0):
        raise ValueError(
            f"k_rot_nmm_per_rad must be a positive number of N*mm/rad, got {k_rot_nmm_per_rad!r}"
        )
    if not math.isfinite(c):
        raise ValueError(f"coupling_n must be a finite number of N, got {coupling_n!r}")

    def field6(points) -> np.ndarray:
        K3 = np.asarray(field3(points), dtype=np.float64).reshape(-1, 3, 3)
        K = np.zeros((K3.shape[0], 6, 6))
        K[:, :3, :3] = K3
        K[:, :3, 3:] = c * np.eye(3)
        K[:, 3:, :3] = c * np.eye(3)
        K[:, 3:, 3:] = k * np.eye(3)
        return K

    return field6


def translational_stiffness(K, load_point_mm=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The 3x3 stiffness a force-only identification sees.

    For a 3x3 K, K itself. For a 6x6 K at the tool point and forces applied at
    ``load_point_mm`` (tcp frame), the tool point moves by
    ``C_tt F + C_tr (r x F) = (C_tt + C_tr [r]x) F`` with C = K^-1, so the
    answer is ``(C_tt + C_tr [r]x)^-1`` (N/mm).

    Parameters
    ----------
    K : array_like, shape (..., 3, 3) or (..., 6, 6)
    load_point_mm : array_like, shape (3,)

    Returns
    -------
    ndarray, shape (..., 3, 3), N/mm
    """
    K = np.asarray(K, dtype=np.float64)
    if K.shape[-2:] == (3, 3):
        return K.copy()
    if K.shape[-2:] != (6, 6):
        raise ValueError(f"K must be 3x3 or 6x6, got shape {K.shape}")
    C = np.linalg.inv(K)
    r = np.asarray(load_point_mm, dtype=np.float64)
    S = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    return np.linalg.inv(C[..., :3, :3] + C[..., :3, 3:] @ S)


@dataclass(frozen=True)
class VirtualRobot:
    """A robot with a known stiffness field and its own positioning noise.

    Attributes
    ----------
    field : callable
        ``field(points (N, 3) mm) -> (N, 3, 3)`` N/mm, or ``(N, 6, 6)`` at the tool
        point (module docstring).
    repeatability_mm : float
        1 sigma per axis of the platform's position error on reaching a
        commanded position (shared by an unloaded/loaded pair), mm.
    repeatability_rad : float
        1 sigma per axis of its small orientation error, rad.
    jitter_mm : float
        1 sigma per axis of each image's own position error (settling), mm.
    load_point_mm : (float, float, float)
        Where the loads act, tcp frame, mm.
    model : str
        ``"delta"``, ``"3prr"``, ``"urdf"`` or ``"none"`` (written to campaign.toml).
    params : dict
        The model's parameters (written to campaign.toml and truth.json).
    spec : dict
        More keys of campaign.toml's ``[robot]`` (a URDF robot's ``urdf``, ``tip_frame``, ...).
    files : dict
        Files the campaign folder gets: name there -> the file to copy, or its content as
        bytes (a URDF robot's URDF, a xacro file's expansion; its flexible links' file).
    """

    field: Callable[[np.ndarray], np.ndarray]
    repeatability_mm: float = 0.02
    repeatability_rad: float = 2e-5
    jitter_mm: float = 0.001
    load_point_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    model: str = "none"
    params: dict[str, Any] = field(default_factory=dict)
    spec: dict[str, Any] = field(default_factory=dict)
    files: dict[str, str | bytes] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not callable(self.field):
            raise ValueError("field must be a callable: points (N, 3) mm -> K (N, 3, 3) N/mm")
        for k in ("repeatability_mm", "repeatability_rad", "jitter_mm"):
            v = float(getattr(self, k))
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{k} must be a finite number >= 0, got {getattr(self, k)!r}")
            object.__setattr__(self, k, v)
        lp = tuple(float(v) for v in self.load_point_mm)
        if len(lp) != 3 or not all(math.isfinite(v) for v in lp):
            raise ValueError(f"load_point_mm must be three finite numbers (mm), got {self.load_point_mm!r}")
        object.__setattr__(self, "load_point_mm", lp)

    @property
    def turns(self) -> bool:
        """Whether its platform can be held turned (its field takes poses: :class:`PlatformField`)."""
        return bool(getattr(self.field, "turns", False))

    def stiffness(self, points, orientations=None) -> np.ndarray:
        """K at the tool point (N/mm; 6x6 for a 6x6 field), checked.

        Parameters
        ----------
        points : array_like, shape (N, 3), mm
        orientations : array_like, shape (N, 3), rad, optional
            The platform's roll, pitch, yaw at each point (a robot whose platform turns:
            :attr:`turns`); None: level.

        Returns
        -------
        ndarray, shape (N, m, m), m = 3 or 6

        Raises
        ------
        ValueError
            If the field returns the wrong shape, non-finite values or a matrix
            whose symmetric part is not positive definite (naming the position).
        """
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if orientations is None:
            K = np.asarray(self.field(P), dtype=np.float64)
        elif not self.turns:
            raise ValueError("this robot's platform does not turn: give its positions without orientations")
        else:
            A = np.asarray(orientations, dtype=np.float64).reshape(P.shape[0], 3)
            K = np.asarray(self.field(np.concatenate([P, A], axis=1)), dtype=np.float64)
        if K.ndim == 2:
            K = K[None]
        if K.shape not in ((P.shape[0], 3, 3), (P.shape[0], 6, 6)):
            raise ValueError(
                f"the stiffness field returned shape {K.shape} for {P.shape[0]} points; "
                f"expected ({P.shape[0]}, 3, 3) or ({P.shape[0]}, 6, 6)"
            )
        for i in range(K.shape[0]):
            if not np.all(np.isfinite(K[i])):
                raise ValueError(f"the stiffness at {P[i].tolist()} mm is not finite")
            if np.linalg.eigvalsh(0.5 * (K[i] + K[i].T))[0] <= 0:
                raise ValueError(f"the stiffness at {P[i].tolist()} mm is not positive definite")
        return K

    def compliant_motion(self, K, force) -> tuple[np.ndarray, np.ndarray]:
        """Displacement of the tool point (mm) and rotation vector (rad) under a force.

        Parameters
        ----------
        K : array_like, shape (3, 3) or (6, 6)
            From :meth:`stiffness` at the position.
        force : array_like, shape (3,), N

        Returns
        -------
        u : ndarray, shape (3,), mm
        w : ndarray, shape (3,), rad (zero for a 3x3 field)
        """
        K = np.asarray(K, dtype=np.float64)
        F = np.asarray(force, dtype=np.float64)
        if F.shape != (3,) or not np.all(np.isfinite(F)):
            raise ValueError(f"force must be a finite 3-vector in N, got {force!r}")
        if K.shape == (3, 3):
            return np.linalg.solve(K, F), np.zeros(3)
        if K.shape != (6, 6):
            raise ValueError(f"K must be 3x3 or 6x6, got shape {K.shape}")
        wrench = np.concatenate([F, np.cross(np.asarray(self.load_point_mm), F)])
        d = np.linalg.solve(K, wrench)
        return d[:3], d[3:]

    def reach(self, commanded_mm, rng: np.random.Generator, rotation=None) -> np.ndarray:
        """The platform's true pose on reaching a commanded position (repeatability), and
        commanded orientation ``rotation`` (3 x 3, platform to base; None: level).

        Returns
        -------
        tcp2base : ndarray, shape (4, 4)
        """
        p = np.asarray(commanded_mm, dtype=np.float64)
        dt = rng.normal(scale=self.repeatability_mm, size=3) if self.repeatability_mm > 0 else np.zeros(3)
        dr = rng.normal(scale=self.repeatability_rad, size=3) if self.repeatability_rad > 0 else np.zeros(3)
        R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
        return transform_from(matrix_from_rotvec(dr) @ R, p + dt)

    def image_pose(self, tcp2base, rng: np.random.Generator, K=None, force=None) -> np.ndarray:
        """The pose seen in one image: the reached pose, its jitter, and the load's motion.

        Parameters
        ----------
        tcp2base : ndarray, shape (4, 4)
            From :meth:`reach`.
        rng : numpy Generator
        K, force : optional
            Stiffness at the position and the applied force (N) of a loaded image.

        Returns
        -------
        tcp2base : ndarray, shape (4, 4)
        """
        T = np.array(tcp2base, dtype=np.float64)
        if self.jitter_mm > 0:
            T[:3, 3] += rng.normal(scale=self.jitter_mm, size=3)
        if force is not None:
            u, w = self.compliant_motion(K, force)
            # Rotation w about the tool point (the tcp origin), in the base frame.
            T[:3, :3] = matrix_from_rotvec(w) @ T[:3, :3]
            T[:3, 3] += u
        return T


def mechanism_robot(model, **kw) -> VirtualRobot:
    """Any mechanism with a 3x3 stiffness field as a virtual robot (the test-bed of its kind).

    Parameters
    ----------
    model : Mechanism
        Its ``stiffness(points)`` is the field (a picklable bound method: the image
        workers receive it); its ``name`` the campaign's ``robot.model``, its finite
        ``params()`` the campaign's ``robot.params``.
    **kw
        :class:`VirtualRobot` fields (repeatability_mm, jitter_mm, ...).
    """
    finite = {k: float(v) for k, v in model.params().items() if math.isfinite(v)}
    return VirtualRobot(field=model.stiffness, model=model.name, params=finite, **kw)


def delta_robot(params: dict[str, float] | None = None, **kw) -> VirtualRobot:
    """The Delta-type robot of :mod:`stiffmap.models.delta` as a virtual robot.

    Parameters
    ----------
    params : dict, optional
        Model parameters (``DeltaRobot.param_names()``: base_radius, platform_radius,
        arm_length, forearm_length (mm), k_theta (N*mm/rad), k_arm, k_forearm (N/mm)).
    **kw
        :class:`VirtualRobot` fields (repeatability_mm, jitter_mm, ...).
    """
    return mechanism_robot(DeltaRobot().with_params(**(params or {})), **kw)


@dataclass(frozen=True)
class SerialField:
    """The 6x6 stiffness field of a serial robot (a picklable callable: the test-bed's image
    workers receive it): K6 at the measured point of the configuration reaching each point."""

    model: Any

    def __call__(self, points) -> np.ndarray:
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        ik = self.model.configurations_for(P)
        for i in np.flatnonzero(~ik.reachable):  # unreachable, or ambiguous: named by the plan
            raise PoseError(
                f"the robot does not reach {P[i].tolist()} mm: {ik.reasons[i]}",
                pose=P[i],
                index=i,
                reason=ik.reasons[i],
            )
        K = []
        for i, q in enumerate(ik.q):
            try:
                K.append(self.model.stiffness6(q))
            except InputError as e:  # a singular configuration: named by the plan as its position
                raise PoseError(str(e), pose=P[i], index=i, reason=e.detail) from None
        return np.array(K).reshape(-1, 6, 6)

    def positions_q_deg(self, points) -> list[list[float]] | None:
        """The joint configurations of ``points`` when the model was given configurations
        (campaign.toml's ``positions.q_deg``: degrees, mm for a prismatic joint), else None
        (the campaign finds them by inverse kinematics, as the test-bed did)."""
        if self.model.configurations is None:
            return None
        ik = self.model.configurations_for(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        rev = np.array([t == "revolute" for t in self.model.chain.joint_types])
        return [
            [round(float(v), 9) + 0.0 for v in np.where(rev, np.degrees(q), q)] for q in np.atleast_2d(ik.q)
        ]


def _degrees(a) -> list[float]:
    """Angles in rad as degrees for campaign.toml, rounded to 1e-9 degree (no -0.0)."""
    return [round(float(v), 9) + 0.0 for v in np.degrees(np.asarray(a, dtype=float))]


#: The name of a URDF robot's URDF in a simulated campaign's folder.
URDF_NAME = "robot.urdf"
#: The name of its flexible links' file there.
LINKS_NAME = "links.toml"


def serial_robot(model, *, links_file=None, **kw) -> VirtualRobot:
    """A serial robot from its URDF (:class:`~stiffmap.models.serial.SerialRobot`) as a virtual robot.

    Its field is the 6x6 stiffness at the measured point (N/mm, N, N*mm/rad blocks, base axes)
    of the configuration that reaches each position (the model's own configurations, or
    inverse kinematics with its tool orientation): the platform turns under a load, and a
    load off the measured point (``load_point_mm``) turns the wrist joints too.

    The campaign folder gets the URDF the model was read from (:data:`URDF_NAME`; a xacro
    file's expansion, so the campaign needs neither xacro nor the packages), its base frame
    when it is not the URDF's root, and its flexible links' file (:data:`LINKS_NAME`).

    Parameters
    ----------
    model : SerialRobot
    links_file : path-like, optional
        The TOML the model's flexible links were read from (needed when it has some).
    **kw
        :class:`VirtualRobot` fields (repeatability_mm, load_point_mm, ...).
    """
    ch = model.chain
    spec = {
        "urdf": URDF_NAME,
        "tip_frame": ch.tip_frame,
        "tip_offset_mm": [float(v) for v in ch.tip_offset_mm],
        "q_seed_deg": _degrees(model.q_seed),
    }
    if model.tool_rotation is not None:
        spec["tool_rpy_deg"] = _degrees(euler_from_matrix(model.tool_rotation))
    if ch.base_frame != ch.root_frame:
        spec["base_frame"] = ch.base_frame
    files: dict[str, str | bytes] = {URDF_NAME: ch.urdf_text.encode() if ch.urdf_text else ch.source}
    if model.links:
        if links_file is None:
            raise ValueError("a robot with flexible links needs links_file, the TOML they were read from")
        spec["links"] = LINKS_NAME
        files[LINKS_NAME] = str(links_file)
    return VirtualRobot(
        field=SerialField(model),
        model=model.name,
        params={k: float(v) for k, v in model.params().items()},
        spec=spec,
        files=files,
        **kw,
    )


def arm6_robot(params: dict[str, float] | None = None, **kw) -> VirtualRobot:
    """stiffmap's six-joint arm (:mod:`stiffmap.models.arm6`) as a virtual robot.

    Parameters
    ----------
    params : dict, optional
        Joint stiffnesses ``k1`` .. ``k6`` (N*mm/rad) to change from :data:`~stiffmap.models.arm6.K_THETA`.
    **kw
        :class:`VirtualRobot` fields (load_point_mm, repeatability_mm, ...).
    """
    return serial_robot(arm6.model().with_params(**(params or {})), **kw)


@dataclass(frozen=True)
class PlatformField:
    """The 6x6 stiffness field of a parallel robot whose platform turns (a picklable callable):
    K6 at the tool point (N/mm, N, N*mm/rad blocks, base axes) of the pose that puts the tool
    point at each position with the platform at ``rpy`` (roll, pitch, yaw, rad), or of each
    pose given (N, 6: x, y, z mm, roll, pitch, yaw rad)."""

    model: Any
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: Its points may be poses: the platform held turned (:attr:`VirtualRobot.turns`).
    turns: bool = True

    def __call__(self, points) -> np.ndarray:
        P = np.asarray(points, dtype=np.float64)
        if P.ndim == 2 and P.shape[1] == 6:
            poses = P
        else:
            P = P.reshape(-1, 3)
            rpy = np.tile(np.asarray(self.rpy, dtype=np.float64), (P.shape[0], 1))
            poses = np.concatenate([P, rpy], axis=1)
        m = self.model.evaluate(poses)
        for i in np.flatnonzero(~m.valid):
            where = f"{poses[i, :3].tolist()} mm"
            if np.any(poses[i, 3:]):
                where += f", roll/pitch/yaw {np.round(np.degrees(poses[i, 3:]), 9).tolist()} deg"
            note = nearest_pose_note(self.model, poses[i])
            reason = m.reasons[i] + (f"; {note}" if note else "")
            raise PoseError(
                f"the robot cannot hold its platform at {where}: {reason}",
                pose=poses[i],
                index=int(i),
                reason=reason,
            )
        return m.K6


#: The name of a legs TOML in a simulated campaign's folder.
LEGS_NAME = "robot.toml"


def platform_robot(model, kind: str, file_key: str, **kw) -> VirtualRobot:
    """A parallel robot described by its legs TOML as a virtual robot (``dim = 6``: a platform
    that turns, :class:`~stiffmap.models.legs6.LegRobot6`; ``dim = 3``: a translational one).

    ``dim = 6``: its field is K6 at the tool point with the platform level (:class:`PlatformField`):
    under a load the platform turns as well as moves, and a load off the tool point
    (``load_point_mm``) turns it more. ``dim = 3``: its field is the model's 3x3 K (the platform
    keeps its orientation, as the Delta's). The campaign it writes is ``robot.model = kind``
    with its TOML copied into the folder (:data:`LEGS_NAME`) and named by ``robot.<file_key>``.

    Parameters
    ----------
    model : LegRobot
        Read from its TOML (``model.source``), with its parameters.
    kind, file_key : str
        The robot kind (the registry's) and its campaign.toml key of the TOML.
    **kw
        :class:`VirtualRobot` fields (load_point_mm, repeatability_mm, ...).

    Raises
    ------
    ValueError
        Not a legs robot of ``dim`` 3 or 6 read from a TOML, or legs given by URDFs (the
        campaign would need them too).
    """
    dim = getattr(model, "dim", None)
    if dim not in (3, 6) or not getattr(model, "source", None):
        raise ValueError("platform_robot needs a robot read from a dim = 6 or dim = 3 legs TOML")
    if any(d.urdf for d in model.description):
        raise ValueError(
            "platform_robot copies the legs TOML alone: its legs must be given by joints, not URDFs"
        )
    return VirtualRobot(
        field=PlatformField(model) if dim == 6 else model.stiffness,
        model=kind,
        # Its finite parameters (a rigid element, inf, stays the copied TOML's).
        params={k: float(v) for k, v in model.params().items() if math.isfinite(v)},
        spec={file_key: LEGS_NAME},
        files={LEGS_NAME: str(model.source)},
        **kw,
    )
