"""Flexible links: a link's compliance as a 6-D virtual spring (the virtual joint method).

A link that bends is modelled, as in the virtual joint method (Pashkevich, Klimchik and
Chablat 2011; Salisbury's joint springs generalised to 6-D), by a 6-D spring at a frame
fixed to it -- by default where the link ends on the chain (the next joint's origin):
under the wrench ``w_s`` it carries, that frame, and everything the chain carries beyond
it, moves by the small twist ``d_s = C_s w_s`` (u mm, rotation vector rad, in the spring
frame's axes). With R_s the spring frame's rotation and r = p - o_s the measured point
from its origin (base frame),

    J_s = [[R_s, -[r]x R_s], [0, R_s]]       (6 x 6: the point's motion from the spring's)

and the compliance of the measured point adds up (``models.serial``):

    C = J_th K_th^-1 J_th^T + sum over the links J_s C_s J_s^T.

A link's ``C_s`` is a 6 x 6 matrix given directly, or that of a straight beam clamped at
its proximal end and loaded at the spring frame (its distal end), from its data in
N-mm-MPa: length L, Young's modulus E, shear modulus G, area A, second moments Iy, Iz
(about the section's axes y and z), torsion constant J, and for a Timoshenko beam the
shear coefficient kappa. Along the beam axis x (the wrench (F, M) at the free end):

    ux = L/(EA) Fx                        rx = L/(GJ) Mx
    uy = L^3/(3EIz) Fy + L^2/(2EIz) Mz    rz = L^2/(2EIz) Fy + L/(EIz) Mz
    uz = L^3/(3EIy) Fz - L^2/(2EIy) My    ry = -L^2/(2EIy) Fz + L/(EIy) My

plus ``L/(kappa G A)`` on uy and uz for a Timoshenko beam (shear deflection). Euler-Bernoulli
and Timoshenko beams are checked against a frame finite-element solution (anastruct) in
the tests.

Parameters (the fit's unknowns beside the joint stiffnesses). Each link's compliance is
linear in a few positive parameters, ``C_s = sum_p B_p / p``: a beam's ``E`` and ``G``
(MPa; ``B_E``, ``B_G`` its compliance at unit moduli), a given matrix's stiffness factor
``f`` (dimensionless, 1 as given: ``C_s = C_given / f``). They are named
``E_<name>``, ``G_<name>``, ``f_<name>`` after the link's ``name`` (default: the link's).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError

__all__ = [
    "Beam",
    "LinkSpring",
    "beam_compliance",
    "beam_basis",
    "spring_jacobians",
    "spring_columns",
    "beam_axes",
    "resolve_axis",
    "check_beam",
    "check_compliance_matrix",
    "AXES",
]

#: Beam axis names and their unit vectors in the spring frame.
AXES = {
    "x": (1.0, 0.0, 0.0),
    "y": (0.0, 1.0, 0.0),
    "z": (0.0, 0.0, 1.0),
    "-x": (-1.0, 0.0, 0.0),
    "-y": (0.0, -1.0, 0.0),
    "-z": (0.0, 0.0, -1.0),
}

#: A given compliance whose smallest eigenvalue is below this fraction of its largest is
#: not positive definite (a rigid direction, or a typing error).
PD_RTOL = 1e-12
#: Largest entry of a given compliance (mm/N, 1/N, rad/(N*mm)): beyond, not a link's.
MAX_COMPLIANCE = 1e6
#: Ranges of beam data taken (N-mm-MPa): a link of a robot, not of a bridge or a hair.
BEAM_RANGES = {
    "length_mm": (1e-3, 1e5),
    "E_MPa": (1e-3, 1e7),
    "G_MPa": (1e-3, 1e7),
    "area_mm2": (1e-6, 1e8),
    "Iy_mm4": (1e-9, 1e16),
    "Iz_mm4": (1e-9, 1e16),
    "J_mm4": (1e-9, 1e16),
}


@dataclass(frozen=True)
class Beam:
    """A straight beam's data (N-mm-MPa).

    Attributes
    ----------
    length_mm : float
    E_MPa, G_MPa : float
        Young's and shear moduli.
    area_mm2 : float
    Iy_mm4, Iz_mm4 : float
        Second moments of area about the section's y and z axes.
    J_mm4 : float
        Torsion constant.
    shear_factor : float or None
        Timoshenko's shear coefficient kappa (5/6 for a rectangle, 0.5 for a thin tube);
        None for an Euler-Bernoulli beam (no shear deflection).
    axis : str or None
        The beam axis in the spring frame, ``"x"`` ... ``"-z"`` (from the clamped end
        towards the spring frame); the section's y and z follow in cyclic order (axis z:
        y is the frame's x, z its y). None: the frame axis nearest to the direction from
        the link's origin (its joint) to the spring frame (resolved by the robot,
        :func:`resolve_axis`).
    """

    length_mm: float
    E_MPa: float
    G_MPa: float
    area_mm2: float
    Iy_mm4: float
    Iz_mm4: float
    J_mm4: float
    shear_factor: float | None = None
    axis: str | None = None


def beam_axes(axis: str) -> np.ndarray:
    """Columns: the beam's x, y, z in the spring frame, for ``axis`` ``"x"`` ... ``"-z"``."""
    if axis not in AXES:
        raise ValueError(f"beam axis must be one of {', '.join(AXES)}, got {axis!r}")
    x = np.array(AXES[axis])
    k = int(np.argmax(np.abs(x)))
    y = np.zeros(3)
    y[(k + 1) % 3] = 1.0
    return np.column_stack([x, y, np.cross(x, y)])


def beam_basis(beam: Beam) -> tuple[np.ndarray, np.ndarray]:
    """``(B_E, B_G)``: the beam's compliance (spring frame) is ``B_E / E + B_G / G``.

    Returns
    -------
    B_E, B_G : ndarray, shape (6, 6)
        Compliance at unit moduli (MPa * mm/N etc.), over (u mm, rotation rad) and
        (F N, M N*mm).
    """
    L, A, Iy, Iz, Jt = beam.length_mm, beam.area_mm2, beam.Iy_mm4, beam.Iz_mm4, beam.J_mm4
    BE = np.zeros((6, 6))
    BE[0, 0] = L / A
    BE[1, 1], BE[1, 5], BE[5, 5] = L**3 / (3 * Iz), L**2 / (2 * Iz), L / Iz
    BE[5, 1] = BE[1, 5]
    BE[2, 2], BE[2, 4], BE[4, 4] = L**3 / (3 * Iy), -(L**2) / (2 * Iy), L / Iy
    BE[4, 2] = BE[2, 4]
    BG = np.zeros((6, 6))
    BG[3, 3] = L / Jt
    if beam.shear_factor is not None:
        BG[1, 1] = BG[2, 2] = L / (beam.shear_factor * A)
    R = beam_axes(beam.axis)
    T = np.zeros((6, 6))
    T[:3, :3] = T[3:, 3:] = R
    return T @ BE @ T.T, T @ BG @ T.T


def beam_compliance(beam: Beam) -> np.ndarray:
    """The beam's 6 x 6 compliance at its free end, in the spring frame (module docstring)."""
    BE, BG = beam_basis(beam)
    return BE / beam.E_MPa + BG / beam.G_MPa


@dataclass(frozen=True, eq=False)
class LinkSpring:
    """A flexible link: a 6-D spring at a frame fixed to a link of the chain.

    Attributes
    ----------
    link : str
        The URDF link that bends (on the chain from the base frame to the tip).
    name : str
        The parameters' suffix (``E_<name>`` ...); default the link's name.
    origin_mm : ndarray, shape (3,) or None
        The spring frame's origin in the link's frame, mm; None: where the link ends on the
        chain (resolved by the robot).
    rotation : ndarray, shape (3, 3)
        The spring frame's axes in the link's frame.
    beam : Beam or None
        Beam data; or
    compliance : ndarray, shape (6, 6) or None
        The compliance given directly (spring frame; mm/N, 1/N, rad/(N*mm) blocks), at
        stiffness factor 1.
    factor : float
        The given compliance's stiffness factor ``f`` (``C_s = compliance / f``).
    where : str
        Where it was given, for messages (``LINKS.toml: links[2]``).
    """

    link: str
    name: str
    origin_mm: np.ndarray | None
    rotation: np.ndarray
    beam: Beam | None = None
    compliance: np.ndarray | None = None
    factor: float = 1.0
    where: str = ""

    def param_names(self) -> tuple[str, ...]:
        """``E_<name>``, ``G_<name>`` (a beam) or ``f_<name>`` (a given compliance)."""
        if self.beam is not None:
            return (f"E_{self.name}", f"G_{self.name}")
        return (f"f_{self.name}",)

    def params(self) -> dict[str, float]:
        if self.beam is not None:
            return {f"E_{self.name}": self.beam.E_MPa, f"G_{self.name}": self.beam.G_MPa}
        return {f"f_{self.name}": self.factor}

    def units(self) -> tuple[str, ...]:
        return ("MPa", "MPa") if self.beam is not None else ("",)

    def with_params(self, values: dict[str, float]) -> LinkSpring:
        """A copy with its parameters (by full name) changed; others ignored."""
        if self.beam is not None:
            E = values.get(f"E_{self.name}", self.beam.E_MPa)
            G = values.get(f"G_{self.name}", self.beam.G_MPa)
            return replace(self, beam=replace(self.beam, E_MPa=float(E), G_MPa=float(G)))
        return replace(self, factor=float(values.get(f"f_{self.name}", self.factor)))

    def basis(self) -> list[np.ndarray]:
        """One compliance matrix per parameter p (spring frame): ``C_s = sum_p basis_p / p``."""
        if self.beam is not None:
            return list(beam_basis(self.beam))
        return [np.asarray(self.compliance, dtype=float)]

    def matrix(self) -> np.ndarray:
        """``C_s`` (6 x 6, spring frame) at the current parameters."""
        vals = list(self.params().values())
        return sum((B / v for B, v in zip(self.basis(), vals, strict=True)), np.zeros((6, 6)))


def check_compliance_matrix(C, where: str) -> np.ndarray:
    """A given 6 x 6 compliance: finite, symmetric and positive definite, else InputError naming ``where``."""
    A = np.asarray(C, dtype=float)
    if A.shape != (6, 6) or not np.all(np.isfinite(A)):
        raise InputError(f"{where}: expected a 6 x 6 matrix of finite numbers, got shape {A.shape}")
    scale = float(np.max(np.abs(A)))
    if scale > MAX_COMPLIANCE:
        raise InputError(
            f"{where}: an entry of {scale:g} is beyond {MAX_COMPLIANCE:g} (mm/N, 1/N, rad/(N*mm))"
        )
    if scale == 0 or not np.allclose(A, A.T, rtol=1e-9, atol=1e-12 * scale):
        raise InputError(f"{where}: a compliance matrix must be symmetric (and not zero)")
    w = np.linalg.eigvalsh(0.5 * (A + A.T))
    if w[0] <= PD_RTOL * w[-1]:
        raise InputError(
            f"{where}: the compliance is not positive definite (eigenvalues {w[0]:.3g} to {w[-1]:.3g}): "
            "every direction of a link's spring must have a finite, positive compliance"
        )
    return 0.5 * (A + A.T)


def check_beam(beam: Beam, where: str) -> Beam:
    """Beam data within :data:`BEAM_RANGES` (floats), else InputError naming ``where`` and the field."""
    vals = {}
    for f, (lo, hi) in BEAM_RANGES.items():
        v = getattr(beam, f)
        if isinstance(v, bool) or not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise InputError(f"{where}.{f}: expected a positive number, got {v!r}")
        if not lo <= v <= hi:
            raise InputError(f"{where}.{f}: {v:g} is outside [{lo:g}, {hi:g}]: not a robot link's")
        vals[f] = float(v)
    k = beam.shear_factor
    if k is not None and (isinstance(k, bool) or not (isinstance(k, int | float) and 0.01 <= k <= 1)):
        raise InputError(
            f"{where}.shear_factor: expected a number in [0.01, 1] (5/6 for a rectangle), got {k!r}"
        )
    if beam.axis is not None and beam.axis not in AXES:
        raise InputError(f"{where}.axis: expected one of {', '.join(AXES)}, got {beam.axis!r}")
    return replace(beam, **vals, shear_factor=None if k is None else float(k))


def resolve_axis(spring: LinkSpring, origin_mm: np.ndarray) -> LinkSpring:
    """A beam spring with its axis set: given, or the spring-frame axis nearest to the direction
    from the link's origin to the spring's (``origin_mm``, link frame), else InputError."""
    if spring.beam is None or spring.beam.axis is not None:
        return spring
    v = np.asarray(spring.rotation, dtype=float).T @ np.asarray(origin_mm, dtype=float)
    if np.linalg.norm(v) < 1e-9:
        raise InputError(
            f"{spring.where}.beam.axis: the spring frame is at link {spring.link!r}'s origin, so the beam's "
            f"direction cannot be found; give axis = one of {', '.join(AXES)} (in the spring frame)"
        )
    k = int(np.argmax(np.abs(v)))
    axis = ("-" if v[k] < 0 else "") + "xyz"[k]
    return replace(spring, beam=replace(spring.beam, axis=axis))


def spring_jacobians(points: np.ndarray, origins: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """``J_s`` of springs: the measured point's motion (base frame) from each spring's twist.

    Parameters
    ----------
    points : ndarray, shape (N, 3), mm
        The measured point.
    origins : ndarray, shape (N, S, 3), mm
        Each spring frame's origin.
    rotations : ndarray, shape (N, S, 3, 3)
        Each spring frame's axes (spring to base).

    Returns
    -------
    ndarray, shape (N, S, 6, 6)
        ``[[R, -[r]x R], [0, R]]``, r = point - origin.
    """
    N, S = origins.shape[:2]
    r = points[:, None, :] - origins
    X = np.zeros((N, S, 3, 3))
    X[..., 0, 1], X[..., 0, 2] = -r[..., 2], r[..., 1]
    X[..., 1, 0], X[..., 1, 2] = r[..., 2], -r[..., 0]
    X[..., 2, 0], X[..., 2, 1] = -r[..., 1], r[..., 0]
    J = np.zeros((N, S, 6, 6))
    J[..., :3, :3] = rotations
    J[..., :3, 3:] = -X @ rotations
    J[..., 3:, 3:] = rotations
    return J


def spring_columns(jacobians: np.ndarray, compliances: np.ndarray) -> np.ndarray:
    """Springs as columns of unit compliance: ``J_s L_s`` with ``C_s = L_s L_s^T`` (Cholesky).

    ``sum_k col_k col_k^T = sum_s J_s C_s J_s^T``: the form the virtual joint method's
    assembly takes its springs in (``models.base.leg_stiffness``, stiffness 1 each), so a
    flexible link of a leg adds six columns to its spring joints'.

    Parameters
    ----------
    jacobians : ndarray, shape (N, S, 6, 6)
        :func:`spring_jacobians`.
    compliances : ndarray, shape (S, 6, 6)
        Each spring's C_s (positive definite).

    Returns
    -------
    ndarray, shape (N, 6, 6 S)
    """
    Js = np.asarray(jacobians, dtype=float)
    N, S = Js.shape[:2]
    if S == 0:
        return np.zeros((N, 6, 0))
    L = np.linalg.cholesky(np.asarray(compliances, dtype=float))  # (S, 6, 6)
    cols = np.einsum("nsij,sjk->nsik", Js, L)  # (N, S, 6, 6)
    return np.moveaxis(cols, 1, 2).reshape(N, 6, 6 * S)
