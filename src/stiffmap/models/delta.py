"""Delta-type translational parallel robot (Clavel's Delta, three rotary actuators).

Geometry (base frame at the centre of the fixed platform, z up, the tool below
the base at z < 0, as in the reference vision study):

- leg i (i = 1, 2, 3) lies in the vertical half-plane at angle ``phi_i`` about
  z, with radial unit vector ``e_i = (cos phi_i, sin phi_i, 0)``;
- its actuator axis is horizontal, tangent to the base circle, through
  ``A_i = R e_i`` (R = ``base_radius``);
- the arm of length ``a`` turns by the actuator angle ``theta_i`` (0 horizontal,
  pointing outwards; positive downwards): elbow ``B_i = A_i + a (cos theta_i e_i
  - sin theta_i z)``;
- the forearm (a parallelogram, a two-force member) of length ``b`` joins the
  elbow to ``C_i = P + r e_i`` on the moving platform (r = ``platform_radius``),
  whose orientation is fixed, so the tool point P has three translations.

Constraint of leg i: ``|C_i - B_i| = b``. Inverse kinematics (closed form, the
elbow-out branch everywhere): with ``D = P - (R - r) e_i``, ``rho = D.e_i``,
``zeta = D.z``, ``M = (|D|^2 + a^2 - b^2) / (2 a)``, ``G = sqrt(rho^2 + zeta^2)``,
``beta = atan2(zeta, rho)``: ``theta_i = -beta - acos(M / G)``; reachable iff
``|M| <= G`` and the tool is below the base (z < 0: at or above the base plane the
closed form has a mirror solution, the arms folded up through the base, which is refused
by name).

Jacobian: differentiating the constraint, ``dtheta_i = n_i . dP / (n_i . t_i)``
with ``n_i = (C_i - B_i) / b`` the forearm direction and ``t_i = dB_i/dtheta_i``;
``J = dtheta/dP`` has rows ``n_i^T / (n_i . t_i)`` (rad/mm).

Stiffness (Gosselin 1990, the reference study's ref. 3): ``K = J^T K_theta J`` with
``K_theta = k_theta I`` (N*mm/rad). With optional compliances of the arm (transverse
stiffness ``k_arm`` at the elbow, N/mm, in the leg's plane) and of the forearm
(axial stiffness ``k_forearm``, N/mm), each leg is a spring along its forearm,
in series:

    1 / k_leg,i = (n_i . t_i)^2 / k_theta + (n_i . t_i / a)^2 / k_arm + 1 / k_forearm
    K = sum_i k_leg,i n_i n_i^T                                   (N/mm)

which reduces to ``J^T K_theta J`` for rigid links. The code computes it as the
virtual joint method's assembly (:func:`~stiffmap.models.base.platform_stiffness`) of
each leg's joint columns at its platform joint: springs ``t_i`` (k_theta), ``t_i / a``
(k_arm), ``n_i`` (k_forearm); passive, the elbow's ball joint, which frees the plane
normal to ``n_i``. The leg then holds the one direction ``n_i``, with the compliance
above (the closed form is checked against it in ``tests/test_models_legs.py``). Singularities: *serial*
(the workspace boundary) where the forearm is aligned with the arm, measured
by ``s_i = |n_i . t_i| / a`` (a sine, 0 there; K is unbounded); *parallel*
where the three forearms are coplanar, measured by the inverse condition
number of the matrix N of rows ``n_i`` (0 there; K loses a direction).

Default geometry and k_theta: the reference study's Parallax LKF-2040 dimensions
are not published. The default (R = 150, r = 40, a = 300, b = 425 mm, legs at
90, 210, 330 degrees: motor 1 on +y, as the study's fixed target on the motor-1
support at y = 188.1 mm suggests) was chosen, among round values, to maximise
the smaller singularity measure over the box x, y in [-200, 200] mm,
z in [-400, -200] mm that holds the reference grid: both measures are >= 0.42
everywhere in it (``docs/models.md``). ``k_theta`` = 2.77e5 N*mm/rad (277 N*m/rad:
a servo under position control through a planetary gear) makes det K = 873
(N/mm)^3 at (-66.7, 66.7, -200) mm, the study's largest measured determinant
(873.27 at the centre of its upper plane, its Section 5), which is also the
largest over the model's grid; the principal stiffnesses over the grid then span
1.4 to 20 N/mm, the range of the study's Table III.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .base import (
    SINGULAR_TOL,
    IKSolution,
    LegMechanism,
    as_points,
    check_positive,
    inverse_condition,
)

__all__ = ["DeltaRobot", "DeltaLegs"]

_DEG = math.pi / 180.0


@dataclass(frozen=True)
class DeltaLegs:
    """Per-leg vectors of a Delta at many poses (all in the base frame).

    Attributes
    ----------
    theta : ndarray, shape (N, 3), rad
        Actuator angles (NaN where unreachable).
    reachable : ndarray of bool, shape (N,)
    A, B, C : ndarray, shape (N, 3, 3), mm
        Actuator joints, elbows and platform joints, ``[point, leg, xyz]``.
    n : ndarray, shape (N, 3, 3)
        Unit forearm directions (elbow to platform).
    t : ndarray, shape (N, 3, 3), mm/rad
        Elbow velocity per unit actuator rate, ``dB_i / dtheta_i``.
    """

    theta: np.ndarray
    reachable: np.ndarray
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    n: np.ndarray
    t: np.ndarray


@dataclass(frozen=True)
class DeltaRobot(LegMechanism):
    """Delta-type translational robot with three rotary actuators.

    Parameters
    ----------
    base_radius : float, mm
        R: distance from the base centre to each actuator axis.
    platform_radius : float, mm
        r: distance from the tool point to each forearm's platform joint.
    arm_length : float, mm
        a: actuator axis to elbow.
    forearm_length : float, mm
        b: elbow to platform joint.
    k_theta : float, N*mm/rad
        Stiffness of each actuator (motor, gear and position loop) about its axis.
    k_arm : float, N/mm
        Transverse stiffness of each arm at its elbow, in the leg's plane
        (``inf``: rigid, the default).
    k_forearm : float, N/mm
        Axial stiffness of each forearm (``inf``: rigid, the default).
    leg_angles : tuple of 3 floats, rad
        Angles ``phi_i`` of the legs about z (default 90, 210, 330 degrees).
    singular_tol : float
        Poses whose serial or parallel singularity measure (module docstring) is
        below this are flagged singular.

    See the module docstring for the equations and the default values. The
    :class:`~stiffmap.models.base.Mechanism` methods (``evaluate``, ``stiffness``:
    ``J^T K_theta J`` with the link compliances, ``static_error``, ``with_params``,
    ``params``) come from :class:`~stiffmap.models.base.LegMechanism`; ``q`` of a
    map holds the actuator angles (rad).
    """

    base_radius: float = 150.0
    platform_radius: float = 40.0
    arm_length: float = 300.0
    forearm_length: float = 425.0
    k_theta: float = 2.77e5
    k_arm: float = math.inf
    k_forearm: float = math.inf
    leg_angles: tuple[float, float, float] = (90.0 * _DEG, 210.0 * _DEG, 330.0 * _DEG)
    singular_tol: float = SINGULAR_TOL

    name = "delta"
    dim = 3
    _LABEL = "Delta"
    _PARALLEL_SINGULARITY = "forearms nearly coplanar"

    _LENGTHS = ("base_radius", "platform_radius", "arm_length", "forearm_length")
    _UNITS = {
        "base_radius": "mm",
        "platform_radius": "mm",
        "arm_length": "mm",
        "forearm_length": "mm",
        "k_theta": "N*mm/rad",
        "k_arm": "N/mm",
        "k_forearm": "N/mm",
    }

    def __post_init__(self) -> None:
        for f in self._LENGTHS + ("k_theta",):
            object.__setattr__(self, f, check_positive(f, getattr(self, f), self._UNITS[f]))
        for f in ("k_arm", "k_forearm"):
            object.__setattr__(self, f, check_positive(f, getattr(self, f), self._UNITS[f], allow_inf=True))
        try:
            ang = tuple(float(v) for v in self.leg_angles)
        except (TypeError, ValueError):
            raise ValueError(f"leg_angles must be three angles in rad, got {self.leg_angles!r}") from None
        if len(ang) != 3 or not all(math.isfinite(v) for v in ang):
            raise ValueError(f"leg_angles must be three finite angles in rad, got {self.leg_angles!r}")
        e = np.array([[math.cos(v), math.sin(v)] for v in ang])
        if min(np.linalg.norm(e[i] - e[j]) for i, j in ((0, 1), (1, 2), (0, 2))) < 1e-6:
            raise ValueError(f"leg_angles must be three different directions, got {self.leg_angles!r}")
        object.__setattr__(self, "leg_angles", ang)
        self._check_singular_tol()

    # ------------------------------------------------------------------ parameters

    @classmethod
    def param_names(cls) -> tuple[str, ...]:
        """Names of the scalar parameters (``with_params``, fitting, ``--param``)."""
        return cls._LENGTHS + ("k_theta", "k_arm", "k_forearm")

    # ------------------------------------------------------------------ kinematics

    def _frames(self) -> tuple[np.ndarray, np.ndarray]:
        phi = np.asarray(self.leg_angles)
        e = np.stack([np.cos(phi), np.sin(phi), np.zeros(3)], axis=1)  # (3 legs, xyz)
        w = np.stack([-np.sin(phi), np.cos(phi), np.zeros(3)], axis=1)  # actuator axes
        return e, w

    def legs(self, points) -> DeltaLegs:
        """Inverse kinematics with every per-leg vector, for many poses.

        Parameters
        ----------
        points : array_like, shape (N, 3) or (3,), mm

        Returns
        -------
        DeltaLegs
        """
        P, _ = as_points(points, 3)
        R, r, a, b = self.base_radius, self.platform_radius, self.arm_length, self.forearm_length
        e, _ = self._frames()
        z = np.array([0.0, 0.0, 1.0])
        D = P[:, None, :] - (R - r) * e[None, :, :]  # (N, 3, 3)
        rho = np.einsum("nij,ij->ni", D, e)
        zeta = D[..., 2]
        M = (np.einsum("nij,nij->ni", D, D) + a * a - b * b) / (2.0 * a)
        G = np.hypot(rho, zeta)
        with np.errstate(invalid="ignore", divide="ignore"):
            c = M / G
        # The platform hangs below the base (z < 0): a point at or above the base plane has
        # a mirror solution (the arms folded up through the base) that no Delta can take.
        ok_leg = (np.abs(c) <= 1.0) & (P[:, 2] < 0.0)[:, None]
        theta = np.where(ok_leg, -np.arctan2(zeta, rho) - np.arccos(np.clip(c, -1.0, 1.0)), np.nan)
        theta = np.where(ok_leg, (theta + np.pi) % (2 * np.pi) - np.pi, np.nan)
        ct, st = np.cos(theta), np.sin(theta)
        A = np.broadcast_to(R * e, D.shape)
        arm = ct[..., None] * e[None] - st[..., None] * z  # unit arm direction
        B = A + a * arm
        C = P[:, None, :] + r * e[None]
        n = (C - B) / b
        t = a * (-st[..., None] * e[None] - ct[..., None] * z)
        return DeltaLegs(theta=theta, reachable=np.all(ok_leg, axis=1), A=A, B=B, C=C, n=n, t=t)

    def inverse_kinematics(self, points) -> IKSolution:
        """Actuator angles (rad) of many poses, elbow-out branch.

        Parameters
        ----------
        points : array_like, shape (N, 3) or (3,), mm

        Returns
        -------
        IKSolution
            ``q`` of shape (N, 3) rad, NaN where unreachable; ``reasons`` names the
            legs that cannot reach.
        """
        L = self.legs(points)
        P, _ = as_points(points, 3)
        return IKSolution(L.theta, L.reachable, tuple(self._unreachable_reasons(P, L)))

    def _unreachable_reasons(self, P: np.ndarray, L: DeltaLegs) -> list[str]:
        reasons = [""] * P.shape[0]
        bad = np.flatnonzero(~L.reachable)
        if bad.size == 0:
            return reasons
        e, _ = self._frames()
        a, b = self.arm_length, self.forearm_length
        for i in bad:
            # Distance from each actuator axis's point A_i to the platform joint C_i.
            dist = np.linalg.norm(P[i][None, :] + self.platform_radius * e - self.base_radius * e, axis=1)
            parts = []
            for k in range(3):
                D = P[i] - (self.base_radius - self.platform_radius) * e[k]
                M = (D @ D + a * a - b * b) / (2 * a)
                if abs(M) <= math.hypot(D @ e[k], D[2]):
                    continue  # this leg reaches
                parts.append(
                    f"leg {k + 1} "
                    + ("too far" if M > 0 else "too close")
                    + f" ({dist[k]:.4g} mm from its actuator; arm {a:g} mm, forearm {b:g} mm)"
                )
            if not parts:  # every leg reaches, but above the base: the mirror solution
                parts.append(
                    f"z = {P[i, 2]:+.4g} mm is at or above the base: the Delta's workspace is below "
                    "its base (z < 0 in the base frame, z up; a sign of z flipped?)"
                )
            reasons[i] = "unreachable: " + "; ".join(parts)
        return reasons

    def forward_kinematics(self, theta) -> np.ndarray:
        """Tool positions (mm) from actuator angles: intersection of three spheres.

        Parameters
        ----------
        theta : array_like, shape (N, 3) or (3,), rad

        Returns
        -------
        ndarray, shape (N, 3) or (3,), mm
            The assembly below the elbows (the one ``inverse_kinematics`` inverts);
            NaN where the forearms cannot close (with a ValueError for one pose).
        """
        T, single = as_points(theta, 3, "theta")
        R, r, a, b = self.base_radius, self.platform_radius, self.arm_length, self.forearm_length
        e, _ = self._frames()
        z = np.array([0.0, 0.0, 1.0])
        ct, st = np.cos(T), np.sin(T)
        # Sphere centres: elbow shifted by -r e_i; radius b.
        S = (R - r + a * ct)[..., None] * e[None] - (a * st)[..., None] * z
        s1, s2, s3 = S[:, 0], S[:, 1], S[:, 2]
        u2, u3 = s2 - s1, s3 - s1
        nrm = np.cross(u2, u3)
        nn = np.einsum("ij,ij->i", nrm, nrm)
        # Circumcentre of the three centres: the foot of the intersection line.
        w = (
            np.einsum("ij,ij->i", u2, u2)[:, None] * np.cross(u3, nrm)
            + np.einsum("ij,ij->i", u3, u3)[:, None] * np.cross(nrm, u2)
        ) / (2.0 * nn[:, None])
        h2 = b * b - np.einsum("ij,ij->i", w, w)
        with np.errstate(invalid="ignore"):
            h = np.sqrt(h2)
        k = nrm / np.sqrt(nn)[:, None]
        k = np.where(k[:, 2:3] > 0, -k, k)  # the solution below
        Pout = s1 + w + h[:, None] * k
        if single:
            if not np.all(np.isfinite(Pout[0])):
                raise ValueError(
                    f"forward kinematics: the forearms cannot close for theta = {T[0].tolist()} rad"
                )
            return Pout[0]
        return Pout

    def jacobian(self, points) -> np.ndarray:
        """Inverse-kinematic Jacobian ``J = dtheta/dP`` (rad/mm).

        Parameters
        ----------
        points : array_like, shape (N, 3) or (3,), mm

        Returns
        -------
        ndarray, shape (N, 3, 3) or (3, 3)
            Row i is ``n_i^T / (n_i . t_i)``. Raises :class:`PoseError` on an
            unreachable or singular pose.
        """
        L, single = self._valid_legs(points)
        J = L.n / np.einsum("nij,nij->ni", L.n, L.t)[..., None]
        return J[0] if single else J

    def _measures(self, L: DeltaLegs) -> tuple[np.ndarray, np.ndarray]:
        """Singularity measures (``singularity_measures``), both NaN where unreachable.

        serial: ``min_i |n_i . t_i| / a``, the sine of the smallest angle between an arm
        and its forearm (0: a leg is stretched or folded, the workspace boundary).
        parallel: inverse condition number of the matrix of forearm directions (0: the
        three forearms are coplanar and the platform can move without the actuators).
        """
        serial = np.min(np.abs(np.einsum("nij,nij->ni", L.n, L.t)), axis=1) / self.arm_length
        return serial, inverse_condition(L.n, L.reachable)

    # ------------------------------------------------------------------ stiffness

    def _leg_joints(self, L: DeltaLegs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each leg's joint columns at its platform joint (virtual joint method, base frame).

        Springs: the actuator (``t_i``, mm/rad, stiffness ``k_theta``), the arm's transverse
        virtual spring at the elbow (``t_i / a``, ``k_arm``) and the forearm's axial one
        (``n_i``, ``k_forearm``). Passive: the elbow's ball joint, rotations about x, y, z
        (``b e_k x n_i``: they span the plane normal to the forearm; the spin is zero).

        Returns
        -------
        springs : ndarray, shape (N, 3, 3, 3)
            ``[pose, leg, xyz, joint]``.
        k : ndarray, shape (3, 3)
            ``[leg, joint]``, N*mm/rad and N/mm.
        passive : ndarray, shape (N, 3, 3, 3)
        """
        springs = np.stack([L.t, L.t / self.arm_length, L.n], axis=-1)
        k = np.tile([self.k_theta, self.k_arm, self.k_forearm], (3, 1))
        ball = self.forearm_length * np.cross(np.eye(3)[None, None], L.n[:, :, None, :])
        return springs, k, np.swapaxes(ball, -1, -2)

    def _joint_coordinates(self, L: DeltaLegs) -> np.ndarray:
        """The actuator angles (rad), NaN for a leg that cannot reach."""
        return L.theta

    def _serial_singularity(self, L: DeltaLegs, i: int) -> str:
        k = int(np.argmin(np.abs(np.einsum("ij,ij->i", L.n[i], L.t[i])) / self.arm_length))
        return f"arm and forearm of leg {k + 1} aligned"

    def describe(self) -> str:
        """One line with the geometry."""
        return (
            f"Delta R={self.base_radius:g} r={self.platform_radius:g} a={self.arm_length:g} "
            f"b={self.forearm_length:g} mm, k_theta={self.k_theta:g} N*mm/rad"
        )
