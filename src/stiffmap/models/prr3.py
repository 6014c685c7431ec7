"""Redundant planar 3PRR mechanism with flexible prismatic joints (the reference milling study).

Geometry (the study's eqs. 1-3, its Fig. 6; x horizontal, y vertical, mm): three
rails start at the vertices ``V_1 = (0, 0)``, ``V_2 = (h, 0)``, ``V_3 = (h/2, sqrt(3)/2 h)``
of an equilateral triangle of side h and point to its centre, with unit
directions ``u_1 = (sqrt(3)/2, 1/2)``, ``u_2 = (-sqrt(3)/2, 1/2)``, ``u_3 = (0, -1)``.
Slider i sits at ``S_i = V_i + l_i u_i`` (0 <= l_i <= h / sqrt(3), the rail running
from its vertex to the centre) and carries a rod of length L, pinned at both ends,
to the tool point T = (x, y): ``|T - S_i| = L`` (eqs. 1-3).

Inverse kinematics (closed form): with ``d_i = T - V_i``, ``s_i = d_i . u_i`` and
``w_i = d_i . u_i^perp`` (the tool's distance from rail i's line),
``l_i = s_i - sqrt(L^2 - w_i^2)``: the slider sits between its vertex and the
tool's foot on the rail, so each rod leans towards the centre (one branch,
everywhere). Reachable iff ``|w_i| <= L`` and ``0 <= l_i <= h / sqrt(3)``.
Jacobian ``J = dl/dT``: row i is ``n_i^T / (n_i . u_i)``, with ``n_i = (T - S_i) / L``
the rod direction.

Truss model (the study's Figs. 7-8, eqs. 4-6): rods are bar elements of axial
stiffness ``E area / L``; slider node i is held by a spring ``kj`` along its rail
(the prismatic joint, actuator and screw) and ``kb`` across it (the bearing's
radial stiffness); a force F acts on the tool node. Each rod is a two-force
member, so a rod force f_i moves slider i by ``f_i Ks_i^-1 n_i`` with
``Ks_i = kj u_i u_i^T + kb u_i^perp u_i^perp^T``, and every leg acts on the tool
as one spring along its rod, in series:

    1 / k_leg,i = (n_i . u_i)^2 / kj + (n_i . u_i^perp)^2 / kb + L / (E area)
    K = sum_i k_leg,i n_i n_i^T                  (2x2, N/mm),   u = K^-1 F (mm)

which equals the assembled truss ``F = K d`` condensed to the tool node
(:meth:`PRR3.truss_displacements` solves the full 8-DOF system; the tests
compare both with anastruct). The code computes it as the virtual joint method's
assembly (:func:`~stiffmap.models.base.platform_stiffness`) of each leg's joint columns
at the tool: springs ``u_i`` (kj), ``u_i^perp`` (kb), ``n_i`` (E area / L); passive, the
pins, which free the direction normal to the rod. Singularities: *serial* where a rod is
perpendicular to its rail (``n_i . u_i`` = 0, the workspace boundary: the
slider cannot move the tool along the rod), *parallel* where the three rods are
parallel (K loses a direction). Measures: ``min_i n_i . u_i`` and the inverse
condition number of the matrix of rod directions, both in [0, 1].

Published values: ``kb = 9800`` N/mm (bearing catalogue) and ``kj = 525`` N/mm
(fitted to the measured static errors, the study's Section 4). The geometry
and rod section are not published; the default is illustrative: h = 800 mm,
L = 250 mm, aluminium rods (E = 70 000 MPa) of 200 mm^2 section (a 25 x 25 x
2.2 mm square tube), whose workspace holds the reconstructed 22-point layout
(:func:`stiffmap.models.presets.prr3_points22`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .base import (
    SINGULAR_TOL,
    IKSolution,
    LegMechanism,
    as_forces,
    as_points,
    check_positive,
    inverse_condition,
)

__all__ = ["PRR3", "PRR3Legs", "K_B_PUBLISHED", "K_J_PUBLISHED"]

#: Bearing radial stiffness of the milling study (NSK catalogue), N/mm.
K_B_PUBLISHED = 9800.0
#: Prismatic-joint stiffness the milling study fitted to its measurements, N/mm.
K_J_PUBLISHED = 525.0

_S3 = math.sqrt(3.0)


@dataclass(frozen=True)
class PRR3Legs:
    """Per-leg vectors of the 3PRR at many poses.

    Attributes
    ----------
    l : ndarray, shape (N, 3), mm
        Slider positions along their rails (NaN where a rod cannot reach its rail).
    reachable : ndarray of bool, shape (N,)
    S : ndarray, shape (N, 3, 2), mm
        Slider nodes.
    n : ndarray, shape (N, 3, 2)
        Unit rod directions, slider to tool.
    u : ndarray, shape (3, 2)
        Unit rail directions (vertex to centre).
    """

    l: np.ndarray
    reachable: np.ndarray
    S: np.ndarray
    n: np.ndarray
    u: np.ndarray


@dataclass(frozen=True)
class PRR3(LegMechanism):
    """Redundant planar 3PRR with flexible prismatic joints and elastic rods.

    Parameters
    ----------
    h : float, mm
        Side of the triangle of the rails' start points.
    L : float, mm
        Rod length.
    area : float, mm^2
        Rod cross-section.
    E : float, MPa
        Rods' Young's modulus.
    kj : float, N/mm
        Prismatic-joint stiffness along each rail (published fit: 525).
    kb : float, N/mm
        Bearing radial stiffness across each rail (published: 9800).
    singular_tol : float
        Poses whose serial or parallel singularity measure is below this are flagged.

    See the module docstring for the equations and the default geometry. The
    :class:`~stiffmap.models.base.Mechanism` methods (``evaluate``, ``stiffness``:
    the truss condensed to the tool node, ``static_error``, ``with_params``,
    ``params``) come from :class:`~stiffmap.models.base.LegMechanism`; K is 2x2
    and ``q`` of a map holds the slider positions (mm).
    """

    h: float = 800.0
    L: float = 250.0
    area: float = 200.0
    E: float = 70000.0
    kj: float = K_J_PUBLISHED
    kb: float = K_B_PUBLISHED
    singular_tol: float = SINGULAR_TOL

    name = "3prr"
    dim = 2
    _LABEL = "3PRR"
    _PARALLEL_SINGULARITY = "rods nearly parallel"

    _UNITS = {"h": "mm", "L": "mm", "area": "mm^2", "E": "MPa", "kj": "N/mm", "kb": "N/mm"}

    def __post_init__(self) -> None:
        for f, unit in self._UNITS.items():
            object.__setattr__(self, f, check_positive(f, getattr(self, f), unit))
        self._check_singular_tol()

    # ------------------------------------------------------------------ parameters

    @classmethod
    def param_names(cls) -> tuple[str, ...]:
        """Names of the scalar parameters (``with_params``, fitting, ``--param``)."""
        return tuple(cls._UNITS)

    # ------------------------------------------------------------------ geometry

    @property
    def vertices(self) -> np.ndarray:
        """Rails' start points V_i, shape (3, 2), mm."""
        h = self.h
        return np.array([[0.0, 0.0], [h, 0.0], [h / 2, _S3 / 2 * h]])

    @property
    def rail_directions(self) -> np.ndarray:
        """Unit rail directions u_i (vertex to centre), shape (3, 2)."""
        return np.array([[_S3 / 2, 0.5], [-_S3 / 2, 0.5], [0.0, -1.0]])

    @property
    def rail_length(self) -> float:
        """Usable rail length h / sqrt(3) (vertex to centre), mm."""
        return self.h / _S3

    @property
    def centre(self) -> np.ndarray:
        """Centre of the triangle, (h/2, h / (2 sqrt 3)) mm."""
        return np.array([self.h / 2, self.h / (2 * _S3)])

    def legs(self, points) -> PRR3Legs:
        """Inverse kinematics with every per-leg vector, for many poses.

        Parameters
        ----------
        points : array_like, shape (N, 2) or (2,), mm

        Returns
        -------
        PRR3Legs
        """
        T, _ = as_points(points, 2)
        V, u = self.vertices, self.rail_directions
        uperp = np.stack([-u[:, 1], u[:, 0]], axis=1)
        d = T[:, None, :] - V[None]  # (N, 3, 2)
        s = np.einsum("nij,ij->ni", d, u)
        w = np.einsum("nij,ij->ni", d, uperp)
        disc = self.L**2 - w * w
        with np.errstate(invalid="ignore"):
            l = s - np.sqrt(disc)  # eqs. 1-3, the branch with the slider behind the tool
        ok_leg = (disc >= 0) & (l >= 0) & (l <= self.rail_length)
        l = np.where(disc >= 0, l, np.nan)
        S = V[None] + l[..., None] * u[None]
        n = (T[:, None, :] - S) / self.L
        return PRR3Legs(l=l, reachable=np.all(ok_leg, axis=1), S=S, n=n, u=u)

    def _unreachable_reasons(self, T: np.ndarray, lg: PRR3Legs) -> list[str]:
        reasons = [""] * T.shape[0]
        Lr = self.rail_length
        for i in np.flatnonzero(~lg.reachable):
            parts = []
            for k in range(3):
                lk = lg.l[i, k]
                if not np.isfinite(lk):
                    d = T[i] - self.vertices[k]
                    u = self.rail_directions[k]
                    w = abs(d[0] * u[1] - d[1] * u[0])
                    parts.append(f"rod {k + 1} too short ({w:.4g} mm from rail {k + 1}, L = {self.L:g} mm)")
                elif lk < 0 or lk > Lr:
                    parts.append(
                        f"slider {k + 1} off its rail (l{k + 1} = {lk:.4g} mm, rail [0, {Lr:.4g}] mm)"
                    )
            reasons[i] = "unreachable: " + "; ".join(parts)
        return reasons

    def inverse_kinematics(self, points) -> IKSolution:
        """Slider positions l_i (mm) along the rails (eqs. 1-3).

        Parameters
        ----------
        points : array_like, shape (N, 2) or (2,), mm

        Returns
        -------
        IKSolution
            ``q`` of shape (N, 3), mm; NaN where unreachable.
        """
        T, _ = as_points(points, 2)
        lg = self.legs(T)
        return IKSolution(self._joint_coordinates(lg), lg.reachable, tuple(self._unreachable_reasons(T, lg)))

    def forward_kinematics(self, l) -> np.ndarray:
        """Tool position (mm) from the three slider positions (mm).

        The tool is where the circles of radius L about the three sliders meet: one of
        the two intersections of circles 1 and 2, the one on circle 3 (the redundant
        leg), with every rod leaning towards the centre (``inverse_kinematics``' branch).

        Parameters
        ----------
        l : array_like, shape (N, 3) or (3,), mm

        Returns
        -------
        ndarray, shape (N, 2) or (2,), mm
            NaN where the rods cannot close: circles 1 and 2 do not meet, slider 3 is off
            circle 3 by more than 1e-6 mm, or the pose is on the other branch (a
            ValueError for one pose).
        """
        Q, single = as_points(l, 3, "l")
        V, u = self.vertices, self.rail_directions
        S = V[None] + Q[..., None] * u[None]  # (N, 3, 2)
        s1, s2 = S[:, 0], S[:, 1]
        c = s2 - s1
        dd = np.linalg.norm(c, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            hh = np.sqrt(self.L**2 - (dd / 2) ** 2)
            perp = np.stack([-c[:, 1], c[:, 0]], axis=1) / dd[:, None]
        mid = 0.5 * (s1 + s2)
        cand = np.stack([mid + hh[:, None] * perp, mid - hh[:, None] * perp], axis=1)  # (N, 2, 2)
        miss3 = np.abs(np.linalg.norm(cand - S[:, None, 2], axis=2) - self.L)
        pick = np.argmin(np.nan_to_num(miss3, nan=np.inf), axis=1)
        rows = np.arange(Q.shape[0])
        T = cand[rows, pick]
        lean = np.einsum("nij,ij->ni", (T[:, None, :] - S) / self.L, u)
        ok = (miss3[rows, pick] <= 1e-6) & np.all(lean >= -1e-9, axis=1)
        T = np.where(ok[:, None], T, np.nan)
        if single:
            if not np.all(np.isfinite(T[0])):
                raise ValueError(f"forward kinematics: no tool position for l = {Q[0].tolist()} mm")
            return T[0]
        return T

    def jacobian(self, points) -> np.ndarray:
        """Inverse-kinematic Jacobian ``J = dl/dT`` (dimensionless), rows ``n_i^T / (n_i . u_i)``.

        Parameters
        ----------
        points : array_like, shape (N, 2) or (2,), mm

        Returns
        -------
        ndarray, shape (N, 3, 2) or (3, 2)
            Raises :class:`PoseError` on an unreachable or singular pose.
        """
        lg, single = self._valid_legs(points)
        J = lg.n / np.einsum("nij,ij->ni", lg.n, lg.u)[..., None]
        return J[0] if single else J

    def _measures(self, lg: PRR3Legs) -> tuple[np.ndarray, np.ndarray]:
        """Singularity measures (``singularity_measures``), parallel NaN where a rod cannot reach.

        serial: ``min_i n_i . u_i``, the sine of the smallest angle between a rod and the
        normal to its rail (0: the rod is perpendicular to its rail).
        parallel: inverse condition number of the 3x2 matrix of rod directions (0: all
        rods parallel).
        """
        serial = np.min(np.einsum("nij,ij->ni", lg.n, lg.u), axis=1)
        return serial, inverse_condition(lg.n, np.all(np.isfinite(lg.l), axis=1))

    # ------------------------------------------------------------------ stiffness

    def _leg_joints(self, lg: PRR3Legs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each leg's joint columns at the tool (virtual joint method).

        Springs: the prismatic joint along the rail (``u_i``, ``kj``), the bearing across it
        (``u_i^perp``, ``kb``) and the rod's axial stiffness (``n_i``, ``E area / L``).
        Passive: the pins at the slider (``L n_i^perp``) and at the tool (zero: it turns
        about the tool point).

        Returns
        -------
        springs : ndarray, shape (N, 3, 2, 3)
            ``[pose, leg, xy, joint]``.
        k : ndarray, shape (3, 3)
            ``[leg, joint]``, N/mm.
        passive : ndarray, shape (N, 3, 2, 2)
        """
        u = np.broadcast_to(lg.u, lg.n.shape)
        uperp = np.stack([-u[..., 1], u[..., 0]], axis=-1)
        nperp = np.stack([-lg.n[..., 1], lg.n[..., 0]], axis=-1)
        springs = np.stack([u, uperp, lg.n], axis=-1)
        k = np.tile([self.kj, self.kb, self.E * self.area / self.L], (3, 1))
        passive = np.stack([self.L * nperp, np.zeros_like(nperp)], axis=-1)
        return springs, k, passive

    def _joint_coordinates(self, lg: PRR3Legs) -> np.ndarray:
        """The slider positions (mm), NaN at unreachable poses."""
        return np.where(lg.reachable[:, None], lg.l, np.nan)

    def _serial_singularity(self, lg: PRR3Legs, i: int) -> str:
        k = int(np.argmin(np.einsum("ij,ij->i", lg.n[i], lg.u)))
        return f"rod {k + 1} perpendicular to its rail"

    def truss_displacements(self, point, force) -> np.ndarray:
        """Nodal displacements of the full truss (the study's eqs. 4-6) at one pose.

        Assembles the 8x8 stiffness of the tool node and the three slider nodes: each
        rod's bar element ``(E area / L) [[1, -1], [-1, 1]]`` in its direction, each
        slider's springs ``kj`` along and ``kb`` across its rail, then solves ``F = K d``.

        Parameters
        ----------
        point : array_like, shape (2,), mm
        force : array_like, shape (2,), N
            On the tool node.

        Returns
        -------
        ndarray, shape (4, 2), mm
            Displacements of the tool node (row 0) and of sliders 1-3.
        """
        T, single = as_points(point, 2, "point")
        if not single:
            raise ValueError(f"point must be one position of shape (2,), got {np.shape(point)}")
        F = as_forces(force, 1, 2)[0]
        lg, _ = self._valid_legs(T)
        Kg = np.zeros((8, 8))
        ka = self.E * self.area / self.L
        u = lg.u
        uperp = np.stack([-u[:, 1], u[:, 0]], axis=1)
        for i in range(3):
            n = lg.n[0, i]
            kb = ka * np.outer(n, n)  # bar element (eq. 5) rotated to the global frame
            dofs = [0, 1, 2 + 2 * i, 3 + 2 * i]
            ke = np.block([[kb, -kb], [-kb, kb]])
            Kg[np.ix_(dofs, dofs)] += ke  # eq. 6
            s = dofs[2:]
            Kg[np.ix_(s, s)] += self.kj * np.outer(u[i], u[i]) + self.kb * np.outer(uperp[i], uperp[i])
        rhs = np.zeros(8)
        rhs[:2] = F
        return np.linalg.solve(Kg, rhs).reshape(4, 2)  # eq. 4

    def describe(self) -> str:
        """One line with the geometry."""
        return (
            f"3PRR h={self.h:g} mm L={self.L:g} mm area={self.area:g} mm^2 E={self.E:g} MPa "
            f"kj={self.kj:g} kb={self.kb:g} N/mm"
        )
