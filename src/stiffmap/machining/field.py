"""The deflection a model predicts at commanded tool positions: delta(p, F) = K(p)^-1 F.

A *field* turns commanded positions of the tool (mm, in the program's frame) and the
forces on it (N, base frame) into the tool's deflection (mm), with each position's
validity (reachable, away from singularities) and the reason when not. The program's
frame has the base's axes; its origin sits at ``place`` (mm) in the base frame.

- :class:`MechanismField`: any :class:`~stiffmap.models.base.Mechanism` through its
  vectorised map (``evaluate``). A planar mechanism (``dim`` 2, the 3PRR) deflects in
  its plane only: x and y are corrected, z passes through.
- :class:`ArmField`: a serial arm (:class:`~stiffmap.models.serial.SerialRobot`): the
  joint configuration that puts the tool point at a position while the tool holds its
  orientation (``tool_rotation`` turned by a spin about the program's z axis), by Newton
  steps from a nearby configuration (the path's neighbours: one branch along the whole
  program), then ``delta = (J K_theta^-1 J^T)[:3, :3] F`` (the force at the tool point).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import rotvec_from_matrix
from ..models.base import Mechanism, format_pose
from ..models.serial import SerialRobot
from ..stiffness import MAX_POSITION_MM

__all__ = ["FieldResult", "MechanismField", "ArmField", "field_for", "spin_rotation"]

#: Newton steps of the arm's inverse kinematics stop below these errors.
IK_TOL_MM = 1e-9
IK_TOL_RAD = 1e-11
IK_MAX_STEPS = 30


@dataclass(frozen=True)
class FieldResult:
    """Deflections at N positions.

    Attributes
    ----------
    delta : ndarray, shape (N, 3), mm
        Deflection of the tool (base axes); NaN where not ``valid``; z is 0 for a planar
        mechanism.
    valid : ndarray of bool, shape (N,)
    reasons : tuple of str
        ``""`` where valid, else why (``"unreachable: ..."``, ``"singular: ..."``).
    conditioning : ndarray, shape (N,)
        The model's kinematic conditioning in [0, 1] (NaN where unreachable).
    q : ndarray, shape (N, n), or None
        The arm's joint configurations (rad or mm), None for other mechanisms.
    """

    delta: np.ndarray
    valid: np.ndarray
    reasons: tuple[str, ...]
    conditioning: np.ndarray
    q: np.ndarray | None = None


def spin_rotation(R: np.ndarray, spin) -> np.ndarray:
    """``Rz(spin) R``: the tool orientation R turned by ``spin`` (rad, shape (N,)) about the
    program's z axis (the tool axis of a three-axis program), through the tool point."""
    c, s = np.cos(spin), np.sin(spin)
    Rz = np.zeros((np.size(spin), 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    return Rz @ np.asarray(R)


@dataclass(frozen=True)
class MechanismField:
    """Deflections from a mechanism's map (module docstring).

    Attributes
    ----------
    mechanism : Mechanism
    place : ndarray, shape (3,), mm
        The program's origin in the base frame (z unused by a planar mechanism).
    """

    mechanism: Mechanism
    place: np.ndarray

    @property
    def corrected(self) -> tuple[int, ...]:
        """The axes the compensation corrects: (0, 1) for a planar mechanism, else (0, 1, 2)."""
        return (0, 1) if self.mechanism.dim == 2 else (0, 1, 2)

    def with_place(self, place) -> MechanismField:
        return MechanismField(self.mechanism, np.asarray(place, dtype=float).reshape(3))

    def base_points(self, points) -> np.ndarray:
        """Program points (N, 3) in the base frame, (N, dim)."""
        P = np.asarray(points, dtype=float) + self.place
        return P[:, : self.mechanism.dim]

    def __call__(self, points, forces, q0=None, spin=None) -> FieldResult:
        """Deflections at program points (N, 3) mm under forces (N, 3) N (``q0``, ``spin`` unused)."""
        d = self.mechanism.dim
        P = self.base_points(points)
        F = np.asarray(forces, dtype=float)[:, :d]
        delta = np.full((F.shape[0], 3), np.nan)
        delta[:, d:] = 0.0
        near = np.all(np.abs(P) <= MAX_POSITION_MM, axis=1)  # the model refuses the rest
        v = np.zeros(len(P), dtype=bool)
        reasons = [f"unreachable: beyond +-{MAX_POSITION_MM:g} mm of the base"] * len(P)
        conditioning = np.full(len(P), np.nan)
        if np.any(near):
            mp = self.mechanism.evaluate(P[near])
            idx = np.flatnonzero(near)
            v[idx] = mp.valid
            for k, r in zip(idx, mp.reasons, strict=True):
                reasons[k] = r
            conditioning[idx] = mp.conditioning
            ok = idx[mp.valid]
            if ok.size:
                delta[ok, :d] = np.linalg.solve(mp.K[mp.valid], F[ok][..., None])[..., 0]
        return FieldResult(delta, v, tuple(reasons), conditioning)

    def describe_point(self, p) -> str:
        return format_pose(self.base_points(np.atleast_2d(p))[0]) + " (base frame)"


@dataclass(frozen=True)
class ArmField:
    """Deflections of a serial arm's tool point (module docstring).

    Attributes
    ----------
    robot : SerialRobot
    place : ndarray, shape (3,), mm
    rotation : ndarray, shape (3, 3)
        The tool's orientation (tip frame to base) along the program, before any spin.
    q_seed : ndarray, shape (n,)
        Start of the inverse kinematics of the program's first point (its branch).
    """

    robot: SerialRobot
    place: np.ndarray
    rotation: np.ndarray
    q_seed: np.ndarray

    corrected = (0, 1, 2)

    def with_place(self, place) -> ArmField:
        return ArmField(self.robot, np.asarray(place, dtype=float).reshape(3), self.rotation, self.q_seed)

    def base_points(self, points) -> np.ndarray:
        return np.asarray(points, dtype=float) + self.place

    def describe_point(self, p) -> str:
        return format_pose(self.base_points(np.atleast_2d(p))[0]) + " (base frame)"

    def beyond_reach(self, points) -> np.ndarray:
        """Which program points (N, 3) no configuration reaches: farther from the arm's first joint
        than its reach (:meth:`~stiffmap.models.chain.Chain.reach_mm`; margins of 1e-6 mm and 1e-9
        of the reach, below what the inverse kinematics calls converged)."""
        centre, radius = self.robot.chain.reach_mm()
        d = np.linalg.norm(self.base_points(points) - centre, axis=-1)
        return d > radius * (1 + 1e-9) + 1e-6

    def _rotations(self, n: int, spin) -> np.ndarray:
        if spin is None:
            return np.broadcast_to(self.rotation, (n, 3, 3))
        return spin_rotation(self.rotation, np.broadcast_to(np.asarray(spin, dtype=float), (n,)))

    def solve(self, points, q0, spin=None) -> tuple[np.ndarray, np.ndarray]:
        """Configurations putting the tool point at ``points`` (program frame), by Newton steps
        from ``q0`` (N, n) holding the tool's orientation; and whether each converged."""
        ch = self.robot.chain
        P = self.base_points(points)
        Rt = self._rotations(P.shape[0], spin)
        Q = np.array(q0, dtype=float, copy=True)
        done = np.zeros(P.shape[0], dtype=bool)
        L = self.robot.length
        for _ in range(IK_MAX_STEPS):
            idx = np.flatnonzero(~done)
            if idx.size == 0:
                break
            p, R = ch.forward_many(Q[idx])
            e_p = P[idx] - p
            e_r = rotvec_from_matrix(Rt[idx] @ np.swapaxes(R, 1, 2)).reshape(-1, 3)
            ok = (np.linalg.norm(e_p, axis=1) < IK_TOL_MM) & (np.linalg.norm(e_r, axis=1) < IK_TOL_RAD)
            done[idx[ok]] = True
            idx, e_p, e_r = idx[~ok], e_p[~ok], e_r[~ok]
            if idx.size == 0:
                break
            J = ch.jacobian_many(Q[idx])
            A = np.concatenate([J[:, :3], L * J[:, 3:]], axis=1)
            e = np.concatenate([e_p, L * e_r], axis=1)
            Q[idx] += _solve_steps(A, e)
        return Q, done

    def solve_path(self, points, spin=None, *, stop: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Configurations along a path in order: the first from ``q_seed`` (damped least squares,
        :meth:`~stiffmap.models.chain.Chain.inverse`), each next from the previous one; a point
        beyond the arm's reach (:meth:`beyond_reach`) is not tried (it would not converge). With
        ``stop``, the points after the first that does not converge or puts a joint beyond its
        limits are not tried either (for a caller that only asks whether all are valid)."""
        ch = self.robot.chain
        far = self.beyond_reach(points)
        P = self.base_points(points)
        Rt = self._rotations(P.shape[0], spin)
        Q = np.full((P.shape[0], self.robot.n), np.nan)
        ok = np.zeros(P.shape[0], dtype=bool)
        q = self.q_seed
        if stop and np.any(far):
            far[np.argmax(far) :] = True
        for i in np.flatnonzero(~far):
            r = ch.inverse(P[i], Rt[i], q0=q, length_mm=self.robot.length)
            if not r.converged:
                if stop:
                    break
                continue
            Q[i], ok[i] = r.q, True
            if stop and self._beyond_limits(r.q[None])[0]:  # invalid (deflect says why): stop
                break
            q = r.q
        return Q, ok

    def __call__(self, points, forces, q0=None, spin=None, *, stop: bool = False) -> FieldResult:
        """Deflections at program points (N, 3) mm under forces (N, 3) N; ``q0`` (N, n) are
        configurations near each point (None: solved along the points in order, ``stop``ping at
        the first that does not converge or is beyond the limits: :meth:`solve_path`)."""
        P = np.asarray(points, dtype=float)
        if q0 is None:
            Q, conv = self.solve_path(P, spin, stop=stop)
        else:
            Q, conv = self.solve(P, q0, spin)
        return self.deflect(P, forces, Q, conv)

    def _beyond_limits(self, Q) -> np.ndarray:
        """Which configurations (N, n) put a joint beyond its limits (1e-12 rad or mm of slack)."""
        ch = self.robot.chain
        return np.any((Q < ch.lower - 1e-12) | (Q > ch.upper + 1e-12), axis=1)

    def deflect(self, points, forces, Q, conv) -> FieldResult:
        """Deflections at program points (N, 3) under forces (N, 3) with the arm at configurations
        Q (N, n) already solved there (``conv``: which ones converged); joint limits and
        conditioning checked."""
        P, F = np.asarray(points, dtype=float), np.asarray(forces, dtype=float)
        n = P.shape[0]
        robot = self.robot
        reasons = [""] * n
        valid = conv.copy()
        for i in np.flatnonzero(~conv):
            reasons[i] = "unreachable: the inverse kinematics holding the tool orientation did not converge"
        beyond = valid & self._beyond_limits(Q)
        for i in np.flatnonzero(beyond):
            reasons[i] = "unreachable: " + "; ".join(robot.chain.beyond_limits(Q[i]))
        valid &= ~beyond
        cond = np.full(n, np.nan)
        delta = np.full((n, 3), np.nan)
        if np.any(valid):
            idx = np.flatnonzero(valid)
            joint, trans = robot.singularity_measures(Q[idx])
            cond[idx] = np.fmin(joint, trans)
            sing = cond[idx] < robot.singular_tol
            for i in idx[sing]:
                reasons[i] = (
                    f"singular: the arm's conditioning {cond[i]:.2g} is below {robot.singular_tol:g} "
                    "(joints aligned or the arm stretched)"
                )
            valid[idx[sing]] = False
            good = idx[~sing]
            if good.size:
                C = robot.compliance6(Q[good])[:, :3, :3]
                delta[good] = np.einsum("nij,nj->ni", C, F[good])
        return FieldResult(delta, valid, tuple(reasons), cond, Q)


def _solve_steps(A: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Newton steps ``dq`` of many (6 x n) systems: exact for square ones, least squares otherwise."""
    if A.shape[1] == A.shape[2]:
        try:
            return np.linalg.solve(A, e[..., None])[..., 0]
        except np.linalg.LinAlgError:
            pass
    return np.stack([np.linalg.lstsq(a, v, rcond=None)[0] for a, v in zip(A, e, strict=True)])


def field_for(mechanism: Mechanism, place=(0.0, 0.0, 0.0), *, tool_rotation=None, q_seed=None):
    """The field of a mechanism: an :class:`ArmField` for a serial arm, else a :class:`MechanismField`.

    Parameters
    ----------
    mechanism : Mechanism
    place : array_like, shape (3,), mm
        The program's origin in the base frame.
    tool_rotation : ndarray, shape (3, 3), optional
        A serial arm's tool orientation (default: the robot's ``tool_rotation``, else its
        orientation at ``q_seed``).
    q_seed : ndarray, shape (n,), rad or mm, optional
        A serial arm's first inverse-kinematics start (default: the robot's ``q_seed``).
    """
    place = np.asarray(place, dtype=float).reshape(3)
    if isinstance(mechanism, SerialRobot):
        seed = mechanism.q_seed if q_seed is None else np.asarray(q_seed, dtype=float)
        R = tool_rotation
        if R is None:
            R = (
                mechanism.tool_rotation
                if mechanism.tool_rotation is not None
                else mechanism.chain.forward(seed)[1]
            )
        return ArmField(mechanism, place, np.asarray(R, dtype=float), seed)
    return MechanismField(mechanism, place)
