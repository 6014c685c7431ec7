"""Parallel robots whose platform turns (hexapods, 3-RPS): the virtual joint method in 6-D.

A legs TOML with ``dim = 6`` (``docs/models.md``, "Platforms that turn") describes a robot
whose platform has six coordinates: its pose is a position P (x, y, z, mm) and an
orientation R = Rz(yaw) Ry(pitch) Rx(roll) (URDF's convention; rad inside stiffmap, degrees
at the boundary). Each leg is, as for ``dim = 3``, a chain from the base to the centre of
its joint on the platform, ``attach_mm`` in the platform's frame; its inverse kinematics
(position only, from its seed) puts that centre at ``P + R attach``. The platform joint is
a ball joint (three free rotations; default) or a universal joint (two: one axis fixed in
the leg's last link, one in the platform).

The assembly, :func:`~stiffmap.models.base.platform_stiffness6`: leg i's columns are 6-D
at its platform joint (the joint centre's velocity and the angular velocity, base frame),
the platform joint's rotations among its passive columns; the leg holds the wrenches
reciprocal to its passive columns (a 6-UPS leg: the force along it; a 3-RPS leg: the
forces along it and across its plane; a universal joint adds the moment about its cross's
normal), with the compliance its springs give there,

    K_leg,i = U_h (U_h^T C_i U_h)^-1 U_h^T,      C_i = J_s diag(1/k) J_s^T  (6 x 6)

and with ``A_i = [[I, -[r_i]x], [0, I]]`` (r_i = R attach_i: the platform's displacement
``delta = (u, theta)`` at the tool point moves the joint centre by ``u + theta x r_i``),

    K6 = sum_i A_i^T K_leg,i A_i       at the tool point P, base frame, w = (F N, M N*mm)

For a leg that is a spring along its line (a 6-UPS), ``K6 = sum k_i a_i a_i^T`` with
``a_i = (n_i, r_i x n_i)``: Gosselin's ``J^T K J`` (tests). K, the stiffness a pure force
sees (what every :class:`~stiffmap.models.base.Mechanism` calls K; the platform free to
turn), is ``(C6[:3, :3])^-1``; K_rot, a pure moment's, ``(C6[3:, 3:])^-1``
(:func:`~stiffmap.models.base.force_moment_stiffness`).

Singularity measures in [0, 1]: *serial*, per leg, the sine between its actuated columns
and the wrenches it holds (as ``dim = 3``, with a twist's rotation rows times the robot's
size :attr:`LegRobot6.length_mm`); *parallel*, the inverse condition number of all the
legs' held wrenches at the tool point (moments over that size; a hexapod's Jacobian
losing rank: :func:`~stiffmap.models.base.held_wrench_condition`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from ..geometry import euler_from_matrix, matrix_from_euler
from .base import (
    POSE_DIM,
    RIGID_RTOL,
    SINGULAR_TOL,
    as_points,
    as_wrenches,
    force_moment_stiffness,
    held_wrench_condition,
    platform_stiffness6,
    raise_first_invalid,
)
from .legs import LegRobot, LegStates, unreachable_as_nan
from .legs_file import ROLES, LegDescription, LegJoint, legs_text

__all__ = [
    "LegRobot6",
    "LegStates6",
    "UNIVERSAL_TOL_RAD",
    "gough_stewart_points",
    "ups_legs",
    "rps_legs",
    "hexapod_toml",
    "rps3_toml",
    "HEXAPOD",
    "RPS3",
]

#: Above this many remembered poses the inverse-kinematics memo is cleared.
MEMO_MAX = 100_000
#: How far (rad) a universal platform joint's two axes may be from perpendicular (its cross)
#: at a pose before the joint cannot be assembled there.
UNIVERSAL_TOL_RAD = 1e-6


@dataclass(frozen=True)
class LegStates6(LegStates):
    """Every leg of a :class:`LegRobot6` at many poses (:class:`~stiffmap.models.legs.LegStates`
    with 6-row columns: the joint centre's velocity, mm per joint unit, then the angular
    velocity, rad per joint unit, base frame; ``passive`` ends with the platform joint's
    rotations).

    Attributes
    ----------
    arms : ndarray, shape (N, legs, 3), mm
        ``R attach``: from the tool point to each leg's platform joint, base frame.
    rotations : ndarray, shape (N, 3, 3)
        The platform's orientation (platform frame to base) at each pose.
    """

    arms: np.ndarray
    rotations: np.ndarray


@dataclass(frozen=True, eq=False)
class LegRobot6(LegRobot):
    """A parallel robot whose platform turns, described by its legs (``dim = 6``).

    :meth:`LegRobot.from_toml` of a ``dim = 6`` legs TOML gives one; the module docstring
    says what it computes. Points are poses (N, 6): x, y, z (mm), roll, pitch, yaw (rad).
    ``evaluate`` gives K (3 x 3, a pure force's), ``K6``, ``K_rot`` and their indices;
    ``stiffness`` K, :meth:`stiffness6` K6, ``static_error`` a pure force's translation,
    :meth:`static_error6` a wrench's (u, rotation).
    """

    #: The legs at the poses seen so far (their kinematics only: shared by ``with_params``
    #: copies, so that a fit of stiffnesses solves each pose's inverse kinematics once).
    _memo: dict = field(default_factory=dict, repr=False, compare=False)

    _FOR_DIM: ClassVar[int | None] = POSE_DIM
    _PARALLEL_SINGULARITY: ClassVar[str] = (
        "the legs' held wrenches nearly lose a direction (the platform gains a motion)"
    )

    @property
    def length_mm(self) -> float:
        """The robot's size (mm): the farthest platform joint from the tool point (at least 1 mm).

        A rad of a twist counts as this many mm in the rank decisions and the singularity
        measures.
        """
        r = max(float(np.linalg.norm(d.attach_mm)) for d in self.description)
        return max(r, 1.0)

    # ------------------------------------------------------------------ kinematics

    def leg_chains(self) -> tuple:
        """Each leg's chain from the base to its platform joint without its spring joints (the
        joints its kinematics move: actuated and passive) and that chain's seed, ``(Chain, q0)``:
        what :mod:`~stiffmap.models.mobility` closes."""
        return tuple((lg.ik_chain, lg.q0) for lg in self._legs)

    def _platform_columns(self, k: int, Rtip: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, str]:
        """Leg k's platform joint: its free rotations as 6-D columns, or why it cannot be assembled."""
        d = self.description[k]
        if d.platform_joint != "universal":  # a ball joint: every rotation about its centre
            return np.vstack([np.zeros((3, 3)), np.eye(3)]), ""
        a1 = Rtip @ np.asarray(d.platform_axes[0], dtype=float)
        a2 = R @ np.asarray(d.platform_axes[1], dtype=float)
        a1, a2 = a1 / np.linalg.norm(a1), a2 / np.linalg.norm(a2)
        angle = math.acos(max(-1.0, min(1.0, float(a1 @ a2))))
        if abs(angle - math.pi / 2) > UNIVERSAL_TOL_RAD:
            return np.zeros((6, 2)), (
                f"its universal platform joint cannot be assembled (its axes at {math.degrees(angle):.6g} "
                "deg; a universal joint's cross holds them at 90 deg)"
            )
        return np.vstack([np.zeros((3, 2)), np.stack([a1, a2], axis=1)]), ""

    def _leg_at(self, k: int, target: np.ndarray, R: np.ndarray):
        """Leg k with its platform joint at ``target``: (q, J 6 x n, platform columns) or (None, why)."""
        lg = self._legs[k]
        qf, why = lg.solve(target)
        if qf is None:
            return None, why
        q = np.zeros(lg.chain.n)
        q[lg.free] = qf
        cols, why = self._platform_columns(k, lg.chain.forward(q)[1], R)
        if why:
            return None, why
        return (q, lg.chain.jacobian(q), cols, lg.link_jacobians(q)), ""

    def legs(self, points) -> LegStates6:
        """Inverse kinematics of every leg and its 6-D joint columns, at many poses.

        Parameters
        ----------
        points : array_like, shape (N, 6) or (6,)
            Poses: x, y, z (mm), roll, pitch, yaw (rad).

        Returns
        -------
        LegStates6
        """
        P, _ = as_points(points, POSE_DIM)
        n, nl = P.shape[0], len(self._legs)
        R = matrix_from_euler(P[:, 3:])
        attach = np.array([d.attach_mm for d in self.description], dtype=float)
        arms = np.einsum("nij,lj->nli", R, attach)
        counts = {r: max(sum(x == r for x in lg.roles) for lg in self._legs) for r in ROLES}
        ns = max(sum(x != "passive" for x in lg.roles) for lg in self._legs)
        springs = np.full((n, nl, 6, ns), np.nan)
        actuated = np.full((n, nl, 6, counts["actuated"]), np.nan)
        passive = np.full((n, nl, 6, counts["passive"] + 3), np.nan)
        links = np.full((n, nl, max(len(lg.links) for lg in self._legs), 6, 6), np.nan)
        joints = [np.full((n, lg.chain.n), np.nan) for lg in self._legs]
        reasons = [""] * n
        if len(self._memo) > MEMO_MAX:
            self._memo.clear()
        for i in range(n):
            bad = []
            key = P[i].tobytes()
            if key not in self._memo:
                self._memo[key] = [self._leg_at(k, P[i, :3] + arms[i, k], R[i]) for k in range(nl)]
            for k, lg in enumerate(self._legs):
                got, why = self._memo[key][k]
                if got is None:
                    sep = " " if why.startswith(("cannot", "its")) else ": "
                    bad.append(f"leg {k + 1} ({lg.name}){sep}{why}")
                    continue
                q, J, platform, Jl = got
                joints[k][i] = q
                links[i, k] = 0.0
                links[i, k, : Jl.shape[0]] = Jl
                s_cols, a_cols, p_cols = lg.columns
                cols = (J[:, s_cols], J[:, a_cols], np.hstack([J[:, p_cols], platform]))
                for arr, c in zip((springs, actuated, passive), cols, strict=True):
                    arr[i, k, :, : c.shape[1]] = c
                    arr[i, k, :, c.shape[1] :] = 0.0
            if bad:
                reasons[i] = "unreachable: " + "; ".join(bad)
        arrays = (springs, actuated, passive, links)
        q, reachable = unreachable_as_nan(self._legs, joints, reasons, arrays)
        return LegStates6(q, tuple(joints), reachable, tuple(reasons), *arrays, arms, R)

    # ------------------------------------------------------------------ stiffness

    def _assemble(self, st: LegStates6, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
        """K (a pure force's), the rigid legs and K6 (:func:`platform_stiffness6`)."""
        Js, k, Jp = self._leg_joints(st)
        L = self.length_mm
        C = self._link_compliance(st)  # each leg's flexible links at its platform joint
        K6, rigid = platform_stiffness6(Js, k, Jp, st.arms, valid, length_mm=L, compliance=C)
        K = np.full((K6.shape[0], 3, 3), np.nan)
        ok = valid & ~np.any(rigid, axis=1)
        if np.any(ok):
            s = np.array([1.0, 1.0, 1.0, 1 / L, 1 / L, 1 / L])  # K6 over the scaled twists
            lam = np.linalg.eigvalsh(K6[ok] * s[:, None] * s[None, :])
            good = np.flatnonzero(ok)[lam[:, 0] > RIGID_RTOL * lam[:, -1]]
            if good.size:
                K[good] = force_moment_stiffness(K6[good])[0]
        return K, rigid, {"K6": K6}

    def stiffness6(self, points) -> np.ndarray:
        """K6 at the tool point, base frame (N/mm, N and N*mm/rad blocks).

        Parameters
        ----------
        points : array_like, shape (N, 6) or (6,)
            Poses: x, y, z (mm), roll, pitch, yaw (rad).

        Returns
        -------
        ndarray, shape (N, 6, 6) or (6, 6)

        Raises
        ------
        PoseError
            Naming the first unreachable or singular pose.
        """
        _, single = as_points(points, POSE_DIM)
        m = self.evaluate(points)
        raise_first_invalid(m, single)
        return m.K6[0].copy() if single else m.K6.copy()

    def static_error6(self, points, wrench) -> np.ndarray:
        """The platform's displacement ``K6^-1 w`` under a wrench at the tool point.

        Parameters
        ----------
        points : array_like, shape (N, 6) or (6,)
            Poses: x, y, z (mm), roll, pitch, yaw (rad).
        wrench : array_like, shape (6,) or (N, 6)
            Force (N) and moment (N*mm) at the tool point, base frame.

        Returns
        -------
        ndarray, shape (N, 6) or (6,)
            u (mm) and the rotation vector (rad), base frame.
        """
        P, single = as_points(points, POSE_DIM)
        w = as_wrenches(wrench, P.shape[0])
        d = np.linalg.solve(self.stiffness6(P), w[..., None])[..., 0]
        return d[0] if single else d

    # ------------------------------------------------------------------ singularities

    def _scaled(self, st: LegStates6) -> LegStates6:
        """The states with the columns' rotation rows times :attr:`length_mm` (rad as mm)."""
        s = np.array([1.0, 1.0, 1.0, *(3 * [self.length_mm])])[:, None]
        return replace(st, passive=st.passive * s, actuated=st.actuated * s, springs=st.springs * s)

    def _measures(self, st: LegStates6) -> tuple[np.ndarray, np.ndarray]:
        """Serial and parallel singularity measures (module docstring), NaN where unreachable."""
        n = st.reachable.shape[0]
        serial = np.full(n, np.nan)
        ok = st.reachable
        if np.any(ok):
            serial[ok] = self._leg_serial(self._scaled(st), ok).min(axis=1)
        parallel = held_wrench_condition(st.passive, st.arms, ok, length_mm=self.length_mm)
        return serial, parallel

    def _serial_singularity(self, st: LegStates6, i: int) -> str:
        return super()._serial_singularity(self._scaled(st), i)


# ---------------------------------------------------------------------- building hexapods and 3-RPS


def _frame_rpy(z_axis, y_axis=None) -> tuple[float, float, float]:
    """Roll, pitch, yaw (rad) of a frame whose z is ``z_axis`` (and y ``y_axis``, when given)."""
    z = np.asarray(z_axis, dtype=float)
    z = z / np.linalg.norm(z)
    if y_axis is None:
        y_axis = np.cross(z, [1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.cross(z, [0.0, 1.0, 0.0])
    y = np.asarray(y_axis, dtype=float)
    y = y - (y @ z) * z
    y = y / np.linalg.norm(y)
    return tuple(float(v) for v in euler_from_matrix(np.stack([np.cross(y, z), y, z], axis=1)))


def gough_stewart_points(
    base_radius_mm: float, platform_radius_mm: float, base_pair_deg: float, platform_pair_deg: float
) -> tuple[np.ndarray, np.ndarray]:
    """The joints of a semi-regular Gough-Stewart platform: pairs on two pitch circles.

    The usual parameterisation (e.g. Merlet, *Parallel Robots*, 2nd ed., Springer 2006,
    ch. 2): base joints in pairs about 270, 30 and 150 deg, ``base_pair_deg`` apart, on a
    circle of ``base_radius_mm``; platform joints in pairs about the same angles,
    ``platform_pair_deg`` apart, on ``platform_radius_mm``; leg i joins base joint i to
    platform joint i (with a platform pair wider than the base's, each leg leans towards
    the neighbouring pair: the legs cross as on most hexapods).

    Returns
    -------
    base : ndarray, shape (6, 3), mm
        Base frame (z = 0).
    platform : ndarray, shape (6, 3), mm
        Platform frame (z = 0).
    """
    centres = np.radians([270.0, 270.0, 30.0, 30.0, 150.0, 150.0])
    side = np.array([-0.5, 0.5, -0.5, 0.5, -0.5, 0.5])

    def circle(r, pair):
        a = centres + side * math.radians(pair)
        return np.stack([r * np.cos(a), r * np.sin(a), np.zeros(6)], axis=1)

    return circle(base_radius_mm, base_pair_deg), circle(platform_radius_mm, platform_pair_deg)


def ups_legs(
    base_mm, platform_mm, home_mm, stiffness: tuple[str, ...], *, stroke_mm=None, u_limit_deg: float = 60.0
) -> tuple[LegDescription, ...]:
    """6-UPS legs: a universal joint at the base, an actuated prismatic leg, a ball on the platform.

    Each leg's universal joint is two passive revolute joints at the base joint, its frame's
    z along the leg at the home pose (seeds 0, limits ``+-u_limit_deg``); the prismatic joint
    (role ``actuated``, the leg's axial stiffness) slides along that z to the platform joint
    (seed: the home length).

    Parameters
    ----------
    base_mm : array_like, shape (legs, 3), mm
        The universal joints' centres, base frame.
    platform_mm : array_like, shape (legs, 3), mm
        The ball joints' centres, platform frame (``attach_mm``).
    home_mm : array_like, shape (3,), mm
        The platform's position at the home pose (no rotation): the seeds' pose.
    stiffness : tuple of str
        Each leg's ``[params]`` name.
    stroke_mm : (float, float), optional
        The legs' length limits, mm.
    """
    B = np.asarray(base_mm, dtype=float)
    A = np.asarray(platform_mm, dtype=float)
    lim = math.radians(u_limit_deg)
    legs = []
    for i, (b, a, k) in enumerate(zip(B, A, stiffness, strict=True), start=1):
        d = np.asarray(home_mm, dtype=float) + a - b
        lo, hi = (None, None) if stroke_mm is None else stroke_mm
        joints = (
            LegJoint(
                "u1", "passive", None, 0.0, -lim, lim, "revolute", (1.0, 0.0, 0.0), tuple(b), _frame_rpy(d)
            ),
            LegJoint("u2", "passive", None, 0.0, -lim, lim, "revolute", (0.0, 1.0, 0.0)),
            LegJoint("stroke", "actuated", k, float(np.linalg.norm(d)), lo, hi, "prismatic", (0.0, 0.0, 1.0)),
        )
        legs.append(LegDescription(f"leg{i}", tuple(float(x) for x in a), joints))
    return tuple(legs)


def rps_legs(
    base_mm,
    axes,
    platform_mm,
    home_mm,
    stiffness: tuple[str, ...],
    bending: tuple[str, ...],
    *,
    stroke_mm=None,
    r_limit_deg: float = 60.0,
) -> tuple[LegDescription, ...]:
    """3-RPS legs: a revolute joint at the base, an actuated prismatic leg bending across its plane, a ball.

    Each leg: the passive revolute joint at its base joint (axis ``axes[i]``; its frame's z
    along the leg at the home pose, seed 0, limits ``+-r_limit_deg``), the actuated prismatic
    joint along the leg (its axial stiffness), and a ``spring`` joint for the leg's bending
    across its plane: a prismatic joint along the revolute's axis at the platform joint,
    with the leg's lateral stiffness there (a cantilever's 3 E I / L^3).

    Parameters
    ----------
    base_mm, axes : array_like, shape (legs, 3)
        Revolute joints' centres (mm) and axes, base frame.
    platform_mm : array_like, shape (legs, 3), mm
        Ball joints' centres, platform frame.
    home_mm : array_like, shape (3,), mm
        The platform's position at the home pose (no rotation); each leg must lie in the
        plane normal to its revolute's axis there.
    stiffness, bending : tuple of str
        Each leg's ``[params]`` names: axial and lateral stiffness.
    """
    B = np.asarray(base_mm, dtype=float)
    A = np.asarray(platform_mm, dtype=float)
    lim = math.radians(r_limit_deg)
    legs = []
    for i, (b, w, a, k, kb) in enumerate(zip(B, axes, A, stiffness, bending, strict=True), start=1):
        d = np.asarray(home_mm, dtype=float) + a - b
        w = np.asarray(w, dtype=float) / np.linalg.norm(w)
        if abs(w @ d) > 1e-9 * np.linalg.norm(d):
            raise ValueError(f"leg {i}: the leg is not normal to its revolute joint's axis at the home pose")
        lo, hi = (None, None) if stroke_mm is None else stroke_mm
        joints = (
            LegJoint(
                "r", "passive", None, 0.0, -lim, lim, "revolute", (0.0, 1.0, 0.0), tuple(b), _frame_rpy(d, w)
            ),
            LegJoint("stroke", "actuated", k, float(np.linalg.norm(d)), lo, hi, "prismatic", (0.0, 0.0, 1.0)),
            LegJoint("bend", "spring", kb, type="prismatic", axis=(0.0, 1.0, 0.0)),
        )
        legs.append(LegDescription(f"leg{i}", tuple(float(x) for x in a), joints))
    return tuple(legs)


#: The shipped hexapod (``robots/hexapod.toml``): a semi-regular 6-UPS
#: (:func:`gough_stewart_points`) of a laboratory hexapod's size.
HEXAPOD = {
    "base_radius_mm": 250.0,
    "platform_radius_mm": 150.0,
    "base_pair_deg": 20.0,
    "platform_pair_deg": 100.0,
    "height_mm": 300.0,
    "stroke_mm": (260.0, 440.0),
    "k_leg": 500.0,
}
#: The shipped 3-RPS (``robots/3rps.toml``): revolute joints tangent to the base circle.
RPS3 = {
    "base_radius_mm": 200.0,
    "platform_radius_mm": 100.0,
    "height_mm": 250.0,
    "stroke_mm": (180.0, 360.0),
    "k_leg": 500.0,
    "k_bend": 130.0,
}

_HEXAPOD_HEADER = """\
A 6-UPS hexapod (Gough-Stewart platform) described by its legs, dim = 6 (docs/models.md,
"Platforms that turn"). Written by stiffmap.models.legs6.hexapod_toml(); LegRobot.from_toml
reads it. Semi-regular geometry (Merlet, Parallel Robots, 2006, ch. 2): base joints in pairs
20 deg apart about 270, 30 and 150 deg on a 250 mm circle, platform joints in pairs 100 deg
apart about the same angles on a 150 mm circle (the legs cross), home height 300 mm; the
size of a laboratory hexapod. Each leg: a universal joint at the base (u1, u2; +-60 deg),
the actuated prismatic leg (stroke 260-440 mm) with its axial stiffness k_legK (N/mm; a
desktop hexapod's small electric actuators), a ball joint on the platform (implicit).
The tool point is the platform frame's origin, the centre of the platform joints' circle."""

_RPS3_HEADER = """\
A 3-RPS parallel robot described by its legs, dim = 6 (docs/models.md, "Platforms that
turn"). Written by stiffmap.models.legs6.rps3_toml(); LegRobot.from_toml reads it. Base
revolute joints at 90, 210 and 330 deg on a 200 mm circle, axes tangent to it; platform ball
joints at the same angles on a 100 mm circle; home height 250 mm. Each leg: the revolute
joint (r, +-60 deg), the actuated prismatic leg (stroke 180-360 mm, axial stiffness k_legK,
N/mm), and the leg's bending across its plane at the platform joint as a spring joint along
the revolute's axis (k_bendK, N/mm: 3 E I / L^3 of a 20 x 2 mm steel tube of 270 mm). The
platform has three degrees of freedom (z, and turns about two horizontal axes); x, y and yaw
follow from them: a pose off the legs' planes is unreachable, the leg named."""


def hexapod_toml(params: dict | None = None, *, name: str = "hexapod") -> str:
    """The legs TOML of a semi-regular 6-UPS (:data:`HEXAPOD` with ``params`` changed).

    ``robots/hexapod.toml`` is this for the defaults. Parameters: the keys of
    :data:`HEXAPOD`; the six legs' stiffnesses are ``k_leg1`` ... ``k_leg6``, all ``k_leg``.
    """
    p = {**HEXAPOD, **(params or {})}
    base, platform = gough_stewart_points(
        p["base_radius_mm"], p["platform_radius_mm"], p["base_pair_deg"], p["platform_pair_deg"]
    )
    names = tuple(f"k_leg{i}" for i in range(1, 7))
    legs = ups_legs(base, platform, (0.0, 0.0, p["height_mm"]), names, stroke_mm=p["stroke_mm"])
    return legs_text(name, 6, dict.fromkeys(names, p["k_leg"]), legs, SINGULAR_TOL, _HEXAPOD_HEADER)


def rps3_toml(params: dict | None = None, *, name: str = "3rps") -> str:
    """The legs TOML of a symmetric 3-RPS (:data:`RPS3` with ``params`` changed).

    ``robots/3rps.toml`` is this for the defaults; the legs' stiffnesses are ``k_leg1..3``
    (axial) and ``k_bend1..3`` (lateral).
    """
    p = {**RPS3, **(params or {})}
    ang = np.radians([90.0, 210.0, 330.0])
    e = np.stack([np.cos(ang), np.sin(ang), np.zeros(3)], axis=1)
    tangent = np.stack([-np.sin(ang), np.cos(ang), np.zeros(3)], axis=1)
    ks, kb = tuple(f"k_leg{i}" for i in (1, 2, 3)), tuple(f"k_bend{i}" for i in (1, 2, 3))
    legs = rps_legs(
        p["base_radius_mm"] * e,
        tangent,
        p["platform_radius_mm"] * e,
        (0.0, 0.0, p["height_mm"]),
        ks,
        kb,
        stroke_mm=p["stroke_mm"],
    )
    params = {**dict.fromkeys(ks, p["k_leg"]), **dict.fromkeys(kb, p["k_bend"])}
    return legs_text(name, 6, params, legs, SINGULAR_TOL, _RPS3_HEADER)
