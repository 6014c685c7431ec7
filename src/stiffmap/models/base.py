"""The mechanism protocol and the result objects every model shares.

A *mechanism* turns tool positions into joint coordinates and into the
translational stiffness K (N/mm) of the tool point in the base frame, for many
positions at once. Anything that implements :class:`Mechanism` can be mapped,
fitted to measurements (:mod:`stiffmap.models.fit`) and driven by the virtual
test-bed, without touching the rest of stiffmap.

Conventions (``docs/conventions.md``): lengths mm, forces N, stiffness N/mm,
angles rad. ``F = K u``: a force F (N) on the tool moves it by the static
error ``u = K^-1 F`` (mm).

Validity: a pose outside the workspace (*unreachable*) or at a singularity
(*singular*) has no meaningful stiffness. Vectorised maps
(:meth:`Mechanism.evaluate`) flag such points one by one (``valid`` False and a
reason) and hold NaN only there; calls meant for poses the caller expects to
be good (:meth:`Mechanism.stiffness`, :meth:`Mechanism.static_error`) raise
:class:`PoseError` naming the first bad pose.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar, Protocol, Self, runtime_checkable

import numpy as np

from ..errors import InputError
from ..loads import MAX_FORCE_N
from ..stiffness import MAX_POSITION_MM

__all__ = [
    "MAX_POSITION_MM",
    "STIFFNESS_RANGE",
    "check_stiffness",
    "Mechanism",
    "LegMechanism",
    "IKSolution",
    "ModelMap",
    "PoseError",
    "SINGULAR_TOL",
    "as_points",
    "as_forces",
    "check_positive",
    "model_map",
    "format_pose",
    "raise_first_invalid",
    "flag_singular",
    "inverse_condition",
    "constrained_directions",
    "leg_stiffness",
    "platform_stiffness",
    "RANK_RTOL",
    "RIGID_RTOL",
    "stiffness_of",
    "static_error_of",
    "POSE_DIM",
    "as_wrenches",
    "skew",
    "arm_map",
    "platform_stiffness6",
    "held_wrench_condition",
    "force_moment_stiffness",
]

#: The ``dim`` of a robot whose platform turns: its poses are x, y, z (mm) and roll, pitch,
#: yaw (rad; R = Rz(yaw) Ry(pitch) Rx(roll), URDF's convention), its K still the 3 x 3 stiffness
#: a pure force sees, and its 6 x 6 stiffness K6 besides (:func:`platform_stiffness6`).
POSE_DIM = 6

#: Default threshold of the dimensionless singularity measures (a sine or an inverse
#: condition number, 1 far from singularities, 0 at one) below which a pose is
#: flagged as singular.
SINGULAR_TOL = 1e-3
#: The joint and leg stiffnesses a user may give (N*mm/rad or N/mm), besides inf (rigid): a legs
#: TOML's [params], --param, campaign.toml's params. Beyond, compliances overflow or vanish.
STIFFNESS_RANGE = (1e-6, 1e12)


class PoseError(InputError):
    """A pose that cannot be evaluated: outside the workspace or at a singularity.

    A subclass of :class:`~stiffmap.errors.InputError` (hence of ``ValueError``);
    ``pose`` holds the offending position (mm), ``index`` its row in the input and
    ``reason`` why it cannot be evaluated (``"unreachable: ..."``, ``"singular: ..."``).
    """

    def __init__(
        self,
        message: str,
        *,
        pose=None,
        index: int | None = None,
        reason: str = "",
        source: str | None = None,
    ):
        super().__init__(message, source=source)
        self.pose = None if pose is None else tuple(float(v) for v in np.ravel(pose))
        self.index = index
        self.reason = reason


@runtime_checkable
class Mechanism(Protocol):
    """What stiffmap needs of a robot model.

    Attributes
    ----------
    name : str
        Short name (``"delta"``, ``"3prr"``).
    dim : int
        Number of translational degrees of freedom of the tool: 3 (spatial,
        points are (x, y, z) mm) or 2 (planar, (x, y) mm).

    Methods
    -------
    All take ``points`` of shape ``(N, dim)`` (or ``(dim,)`` for one pose), mm,
    in the mechanism's base frame.

    ``inverse_kinematics(points) -> IKSolution``
        Joint coordinates and a reachable mask (arrays of N rows; N = 1 for one
        pose); never raises for a bad pose.
    ``stiffness(points) -> ndarray, shape (N, dim, dim)``
        K (N/mm) at the tool point in the base frame; ``(dim, dim)`` for one
        pose. Raises :class:`PoseError` naming the first unreachable or singular pose.
    ``static_error(points, force) -> ndarray, shape (N, dim)``
        ``K^-1 F`` (mm) for a force F (N) of shape ``(dim,)`` or ``(N, dim)``.
    ``evaluate(points) -> ModelMap``
        The map: K (NaN only where flagged), validity and reasons per point, indices.
    ``with_params(**params) -> same type``
        A copy with some parameters changed (models are immutable); unknown names
        and non-positive stiffnesses or lengths raise ``ValueError``.
    ``params() -> dict[str, float]``
        The scalar parameters (the names ``with_params`` and the fitting accept).
    """

    name: str
    dim: int

    def inverse_kinematics(self, points) -> IKSolution: ...

    def stiffness(self, points) -> np.ndarray: ...

    def static_error(self, points, force) -> np.ndarray: ...

    def evaluate(self, points) -> ModelMap: ...

    def with_params(self, **params) -> Mechanism: ...

    def params(self) -> dict[str, float]: ...


@dataclass(frozen=True)
class IKSolution:
    """Inverse kinematics of many poses.

    Attributes
    ----------
    q : ndarray, shape (N, n_joints)
        Actuated joint coordinates (rad for revolute, mm for prismatic joints);
        NaN where ``reachable`` is False.
    reachable : ndarray of bool, shape (N,)
    reasons : tuple of str, length N
        Why a pose is unreachable (``""`` when reachable).
    """

    q: np.ndarray
    reachable: np.ndarray
    reasons: tuple[str, ...]


@dataclass(frozen=True)
class ModelMap:
    """A model evaluated over many poses.

    Attributes
    ----------
    mechanism : str
        The mechanism's name.
    params : dict of str to float
        The parameters it was evaluated with.
    points : ndarray, shape (N, dim), mm
    K : ndarray, shape (N, dim, dim), N/mm
        Stiffness at the tool point, base frame; NaN exactly where ``valid`` is False.
    valid : ndarray of bool, shape (N,)
        Reachable and not singular.
    reasons : tuple of str, length N
        ``""`` for a valid point, else why not (``"unreachable: ..."``,
        ``"singular: ..."``).
    q : ndarray, shape (N, n_joints)
        Actuated joint coordinates (rad or mm); NaN where unreachable.
    conditioning : ndarray, shape (N,)
        Kinematic conditioning of the pose, in [0, 1]: the smaller of the
        model's singularity measures (1 far from singularities, 0 at one);
        NaN where unreachable.
    det : ndarray, shape (N,)
        det K, (N/mm)^dim (the reference vision study's map value).
    eigenvalues : ndarray, shape (N, dim), N/mm
        Principal stiffnesses (eigenvalues of the symmetric part of K), ascending.
    min_principal : ndarray, shape (N,), N/mm
        Smallest principal stiffness (the softest direction).
    condition : ndarray, shape (N,)
        Condition number of K (largest over smallest principal stiffness).
    K6 : ndarray, shape (N, 6, 6), or None
        For a robot whose platform turns (``dim = 6``, points are poses): the stiffness of
        the platform at the tool point, base frame, mapping the small displacement
        (u mm, rotation vector rad) to the wrench (F N, M N*mm): blocks N/mm, N (= N*mm/mm)
        and N*mm/rad. NaN where invalid; None for a robot whose platform only translates.
        K is then the stiffness a pure force sees, ``(C6[:3, :3])^-1`` with C6 = K6^-1.
    K_rot : ndarray, shape (N, 3, 3), N*mm/rad, or None
        The rotational stiffness a pure moment sees, ``(C6[3:, 3:])^-1`` (with K6).
    min_principal_rot : ndarray, shape (N,), N*mm/rad, or None
        Its smallest principal stiffness (the softest axis of rotation).
    """

    mechanism: str
    params: dict[str, float]
    points: np.ndarray
    K: np.ndarray
    valid: np.ndarray
    reasons: tuple[str, ...]
    q: np.ndarray
    conditioning: np.ndarray
    det: np.ndarray
    eigenvalues: np.ndarray
    min_principal: np.ndarray
    condition: np.ndarray
    K6: np.ndarray | None = None
    K_rot: np.ndarray | None = None
    min_principal_rot: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @property
    def dim(self) -> int:
        """The translations K acts on: 2 or 3 (3 for a robot whose poses have six coordinates)."""
        return int(self.K.shape[-1])

    @property
    def n_valid(self) -> int:
        return int(np.count_nonzero(self.valid))

    def static_error(self, force) -> np.ndarray:
        """Static error ``K^-1 F`` (mm) at every point, NaN exactly where ``valid`` is False.

        Parameters
        ----------
        force : array_like, shape (dim,) or (N, dim), N
        """
        F = as_forces(force, len(self), self.dim)
        u = np.full((len(self), self.dim), np.nan)
        v = self.valid
        if np.any(v):
            u[v] = np.linalg.solve(self.K[v], F[v][..., None])[..., 0]
        return u

    def static_error6(self, wrench) -> np.ndarray:
        """Static error ``K6^-1 w`` (u mm, rotation vector rad) under a wrench at the tool point.

        Only for a map with ``K6`` (a robot whose platform turns).

        Parameters
        ----------
        wrench : array_like, shape (6,) or (N, 6)
            Force (N) and moment (N*mm) at the tool point, base frame.

        Returns
        -------
        ndarray, shape (N, 6)
            NaN exactly where ``valid`` is False.
        """
        if self.K6 is None:
            raise ValueError(f"{self.mechanism}: no 6 x 6 stiffness (the platform only translates)")
        w = as_wrenches(wrench, len(self))
        out = np.full((len(self), 6), np.nan)
        v = self.valid
        if np.any(v):
            out[v] = np.linalg.solve(self.K6[v], w[v][..., None])[..., 0]
        return out


def format_pose(p) -> str:
    """``(x, y[, z]) mm`` with up to 6 significant digits; a pose of six numbers (x, y, z mm, roll,
    pitch, yaw rad) as ``(x, y, z) mm, roll-pitch-yaw (r, p, y) deg``."""
    v = [float(x) for x in np.ravel(p)]
    if len(v) == 6:
        rpy = ", ".join(f"{math.degrees(x):.6g}" for x in v[3:])
        return "(" + ", ".join(f"{x:.6g}" for x in v[:3]) + f") mm, roll-pitch-yaw ({rpy}) deg"
    return "(" + ", ".join(f"{x:.6g}" for x in v) + ") mm"


def as_points(points, dim: int, name: str = "points") -> tuple[np.ndarray, bool]:
    """Check tool positions.

    Parameters
    ----------
    points : array_like, shape (N, dim) or (dim,), mm
        For ``dim = 6`` (:data:`POSE_DIM`, a robot whose platform turns) poses: x, y, z (mm)
        and roll, pitch, yaw (rad, within +-pi; R = Rz(yaw) Ry(pitch) Rx(roll)).
    dim : int

    Returns
    -------
    P : ndarray, shape (N, dim), float64
    single : bool
        True when one pose of shape ``(dim,)`` was given.
    """
    P = np.asarray(points, dtype=np.float64)
    single = P.ndim == 1
    if single:
        P = P[None, :]
    if P.ndim != 2 or P.shape[1] != dim:
        what = "poses: x, y, z mm, roll, pitch, yaw rad" if dim == POSE_DIM else "positions in mm"
        raise ValueError(f"{name} must have shape (N, {dim}) or ({dim},) ({what}), got {np.shape(points)}")
    if not np.all(np.isfinite(P)):
        i = int(np.argwhere(~np.all(np.isfinite(P), axis=1))[0, 0])
        raise ValueError(f"{name}: row {i} is not finite: {P[i].tolist()}")
    if dim == POSE_DIM:
        turned = np.flatnonzero(np.any(np.abs(P[:, 3:]) > math.pi, axis=1))
        if turned.size:
            i = int(turned[0])
            raise ValueError(
                f"{name}: row {i}: roll, pitch, yaw {P[i, 3:].tolist()} must be radians within +-pi "
                "(degrees only at the boundary: files and command lines)"
            )
        P3 = P[:, :3]
    else:
        P3 = P
    far = np.flatnonzero(np.any(np.abs(P3) > MAX_POSITION_MM, axis=1))
    if far.size:
        i = int(far[0])
        raise ValueError(
            f"{name}: row {i} {format_pose(P[i])} is beyond +-{MAX_POSITION_MM:g} mm: "
            "not a plausible position"
        )
    return P, single


def as_forces(force, n: int, dim: int) -> np.ndarray:
    """A force (N) broadcast to shape (n, dim), checked finite."""
    F = np.asarray(force, dtype=np.float64)
    if F.shape == (dim,):
        F = np.broadcast_to(F, (n, dim))
    if F.shape != (n, dim):
        raise ValueError(f"force must have shape ({dim},) or ({n}, {dim}) in N, got {np.shape(force)}")
    if not np.all(np.isfinite(F)):
        raise ValueError("force contains NaN or infinite values")
    if np.any(np.abs(F) > MAX_FORCE_N):
        raise ValueError(f"force beyond +-{MAX_FORCE_N:g} N: not a plausible load")
    return F


def as_wrenches(wrench, n: int) -> np.ndarray:
    """A wrench (F N, M N*mm) broadcast to shape (n, 6), checked finite and plausible."""
    w = np.asarray(wrench, dtype=np.float64)
    if w.shape == (6,):
        w = np.broadcast_to(w, (n, 6))
    if w.shape != (n, 6):
        raise ValueError(
            f"wrench must have shape (6,) or ({n}, 6): force N and moment N*mm, got {np.shape(wrench)}"
        )
    if not np.all(np.isfinite(w)):
        raise ValueError("wrench contains NaN or infinite values")
    as_forces(w[:, :3], n, 3)  # the force's bound
    return w


def check_stiffness(name: str, value: float, unit: str) -> float:
    """A stiffness a user gave: within :data:`STIFFNESS_RANGE` or inf, else ValueError naming it."""
    lo, hi = STIFFNESS_RANGE
    if math.isfinite(value) and not lo <= value <= hi:
        raise ValueError(
            f"{name}: a stiffness between {lo:g} and {hi:g} {unit} (or inf for rigid), got {value!r}"
        )
    return value


def check_positive(name: str, value, unit: str, *, allow_inf: bool = False) -> float:
    """A strictly positive finite float (``inf`` too when ``allow_inf``), else ValueError."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number of {unit}, got {value!r}") from None
    if math.isnan(v) or v <= 0 or (math.isinf(v) and not allow_inf):
        what = "a positive number" + (" (or inf for rigid)" if allow_inf else "")
        raise ValueError(f"{name} must be {what} of {unit}, got {value!r}")
    return v


def model_map(
    mechanism: str,
    params: dict[str, float],
    points: np.ndarray,
    K: np.ndarray,
    valid: np.ndarray,
    reasons: Sequence[str],
    q: np.ndarray,
    conditioning: np.ndarray,
    K6: np.ndarray | None = None,
) -> ModelMap:
    """Assemble a :class:`ModelMap`: blank K where invalid and compute the indices.

    The helper for a new mechanism's ``evaluate``: give the stiffness at every
    point, the validity mask and the reasons; it computes det, principal
    stiffnesses and condition numbers and makes the arrays read-only.

    Parameters
    ----------
    K : ndarray, shape (N, dim, dim), N/mm
        Values where ``valid`` is False are ignored (set to NaN); for a robot whose platform
        turns, the 3 x 3 stiffness a pure force sees (:func:`force_moment_stiffness`).
    K6 : ndarray, shape (N, 6, 6), optional
        A robot whose platform turns: its 6 x 6 stiffness (:class:`ModelMap`); the map's
        ``K_rot`` and ``min_principal_rot`` are computed from it.
    """
    n = points.shape[0]
    dim = np.shape(K)[-1]
    K = np.array(K, dtype=np.float64, copy=True)
    valid = np.asarray(valid, dtype=bool)
    K[~valid] = np.nan
    det = np.full(n, np.nan)
    eig = np.full((n, dim), np.nan)
    cond = np.full(n, np.nan)
    if np.any(valid):
        Kv = K[valid]
        det[valid] = np.linalg.det(Kv)
        w = np.linalg.eigvalsh(0.5 * (Kv + np.swapaxes(Kv, 1, 2)))
        eig[valid] = w
        with np.errstate(divide="ignore"):
            cond[valid] = np.where(w[:, 0] > 0, w[:, -1] / np.where(w[:, 0] > 0, w[:, 0], 1.0), np.inf)
    six = {}
    if K6 is not None:
        K6 = np.array(K6, dtype=np.float64, copy=True)
        K6[~valid] = np.nan
        Kr = np.full((n, 3, 3), np.nan)
        if np.any(valid):
            Kr[valid] = force_moment_stiffness(K6[valid])[1]
        mr = np.full(n, np.nan)
        if np.any(valid):
            mr[valid] = np.linalg.eigvalsh(Kr[valid])[:, 0]
        six = {"K6": K6, "K_rot": Kr, "min_principal_rot": mr}
    for a in (points, K, valid, q, conditioning, det, eig, cond, *six.values()):
        a.setflags(write=False)
    return ModelMap(
        mechanism=mechanism,
        params=dict(params),
        points=points,
        K=K,
        valid=valid,
        reasons=tuple(reasons),
        q=q,
        conditioning=conditioning,
        det=det,
        eigenvalues=eig,
        min_principal=eig[:, 0].copy(),
        condition=cond,
        **six,
    )


def raise_first_invalid(m: ModelMap, single: bool) -> None:
    """Raise :class:`PoseError` for the first invalid point of a map (used by ``stiffness``)."""
    if np.all(m.valid):
        return
    i = int(np.flatnonzero(~m.valid)[0])
    where = "" if single else f"point {i}: "
    nbad = len(m) - m.n_valid
    more = "" if single or nbad == 1 else f" ({nbad - 1} more invalid point(s); use evaluate() for a map)"
    raise PoseError(
        f"{m.mechanism}: {where}pose {format_pose(m.points[i])} {m.reasons[i]}{more}",
        pose=m.points[i],
        index=i,
        reason=m.reasons[i],
    )


def flag_singular(
    reachable: np.ndarray,
    serial: np.ndarray,
    parallel: np.ndarray,
    tol: float,
    reasons: list[str],
    serial_reason: Callable[[int], str],
    parallel_reason: Callable[[int], str],
) -> np.ndarray:
    """Flag reachable poses whose singularity measures are below ``tol``.

    Parameters
    ----------
    reachable : ndarray of bool, shape (N,)
    serial, parallel : ndarray, shape (N,)
        The model's singularity measures in [0, 1] (0 at a singularity).
    tol : float
        Threshold below which a measure flags the pose.
    reasons : list of str, length N
        Filled in place with ``"singular: ..."`` for every flagged pose.
    serial_reason, parallel_reason : callable, int -> str
        The text naming the serial or parallel singularity of pose i.

    Returns
    -------
    valid : ndarray of bool, shape (N,)
        Reachable and not singular.
    """
    valid = reachable.copy()
    for i in np.flatnonzero(reachable & ((serial < tol) | (parallel < tol))):
        parts = []
        if serial[i] < tol:
            parts.append(serial_reason(i))
        if parallel[i] < tol:
            parts.append(parallel_reason(i))
        reasons[i] = "singular: " + "; ".join(parts)
        valid[i] = False
    return valid


def inverse_condition(n: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Inverse condition number of each pose's matrix of leg directions (a parallel-singularity measure).

    Parameters
    ----------
    n : ndarray, shape (N, legs, dim)
        Unit leg directions, rows of one matrix per pose.
    ok : ndarray of bool, shape (N,)
        Poses to evaluate (their ``n`` finite).

    Returns
    -------
    ndarray, shape (N,)
        Smallest over largest singular value, in [0, 1] (0: the legs lose a direction);
        NaN where ``ok`` is False.
    """
    out = np.full(ok.shape, np.nan)
    if np.any(ok):
        s = np.linalg.svd(n[ok], compute_uv=False)
        out[ok] = s[:, -1] / s[:, 0]
    return out


# ---------------------------------------------------------------------- the virtual joint method

#: Relative tolerance on the singular values of a leg's passive columns below which a
#: direction does not count as freed (dependent or zero columns: a ball joint's spin about
#: its link, a pin at the measured point). The directions come from ``eigh`` of
#: ``J_p J_p^T``, whose eigenvalues are the squared singular values: 1e-6 keeps the test
#: (1e-12 on those) well above their roundoff.
RANK_RTOL = 1e-6
#: A leg whose compliance along the directions it holds has an eigenvalue below this
#: fraction of its largest is *rigid* there (no finite spring acts along it).
RIGID_RTOL = 1e-12


def constrained_directions(passive, *, rank_rtol: float = RANK_RTOL) -> tuple[np.ndarray, np.ndarray]:
    """The directions a leg holds: an orthonormal basis of the complement of ``range(J_p)``.

    Parameters
    ----------
    passive : array_like, shape (..., d, p)
        Tip velocity per unit rate of each passive joint (mm per rad or mm per mm), d task
        directions; columns may be zero or dependent.
    rank_rtol : float
        Singular values below ``rank_rtol`` times the largest count as zero.

    Returns
    -------
    U : ndarray, shape (..., d, d)
        Orthonormal, the held directions first: columns ``j < c`` span the complement of
        ``range(J_p)``, the others ``range(J_p)``.
    held : ndarray of bool, shape (..., d)
        True for the first c columns (c = d - rank J_p, the number of directions held).
    """
    P = np.asarray(passive, dtype=np.float64)
    d = P.shape[-2]
    if P.shape[-1] == 0:
        U = np.broadcast_to(np.eye(d), (*P.shape[:-2], d, d)).copy()
        return U, np.ones((*P.shape[:-2], d), dtype=bool)
    lam, U = np.linalg.eigh(P @ np.swapaxes(P, -1, -2))  # ascending: the held directions first
    rank = np.sum(lam > (rank_rtol * rank_rtol) * lam[..., -1:], axis=-1)
    return U, np.arange(d) < (d - rank)[..., None]


def leg_stiffness(springs, k, U, held, compliance=None) -> tuple[np.ndarray, np.ndarray]:
    """A leg's stiffness at its tip, passive joints free: ``K = U_h (U_h^T C U_h)^-1 U_h^T``.

    ``C = J_s diag(1/k) J_s^T`` is the tip compliance with the passive joints locked; the
    passive joints let the tip move freely in ``range(J_p)``, so the leg resists only along
    the held directions ``U_h`` (:func:`constrained_directions`), with the compliance C
    has there.

    Parameters
    ----------
    springs : array_like, shape (..., d, s)
        Tip velocity per unit rate of each spring joint (actuated joints and virtual springs
        standing for link compliances), mm per rad or mm per mm.
    k : array_like, broadcastable to (..., s)
        Their stiffnesses, N*mm/rad (revolute) or N/mm (prismatic); ``inf`` for rigid.
    U, held : ndarray, shapes (..., d, d) and (..., d)
        From :func:`constrained_directions`.
    compliance : array_like, shape (..., d, d), optional
        A compliance of the leg at its tip added to ``C`` (symmetric positive semi-definite,
        the units of C): what the spring columns do not describe, e.g. a link's 6-D compliance
        carried to the tip.

    Returns
    -------
    K : ndarray, shape (..., d, d), N/mm
        Symmetric positive semi-definite, rank c; NaN where ``rigid``.
    rigid : ndarray of bool, shape (...)
        Legs with no compliance along a direction they hold (their stiffness is infinite there).
    """
    Js = np.asarray(springs, dtype=np.float64)
    with np.errstate(divide="ignore"):
        w = 1.0 / np.asarray(k, dtype=np.float64)  # compliances; 0 for rigid springs
    d = Js.shape[-2]
    h = held.astype(np.float64)
    W = (np.swapaxes(U, -1, -2) @ Js) * h[..., :, None]  # held rows of U^T J_s
    M = (W * w[..., None, :]) @ np.swapaxes(W, -1, -2)  # U^T C U on the held block, 0 elsewhere
    if compliance is not None:
        E = np.swapaxes(U, -1, -2) @ np.asarray(compliance, dtype=np.float64) @ U
        M = M + 0.5 * (E + np.swapaxes(E, -1, -2)) * h[..., :, None] * h[..., None, :]
    c = np.count_nonzero(held, axis=-1)
    K = np.zeros(M.shape)
    rigid = np.zeros(c.shape, dtype=bool)
    one = c == 1  # a two-force member: it holds U[:, 0] with compliance M[0, 0]
    if np.any(one):
        m, u = M[..., 0, 0][one], U[..., :, 0][one]
        rigid[one] = m <= 0
        with np.errstate(divide="ignore", invalid="ignore"):
            K[one] = u[:, :, None] * u[:, None, :] / m[:, None, None]
    more = c > 1
    if np.any(more):
        # Invert the held block in one batched eigh: the other rows are filled with the
        # block's mean eigenvalue, so that a zero eigenvalue is judged at the block's scale.
        Mm, hm = M[more], h[more]
        scale = np.trace(Mm, axis1=-2, axis2=-1) / c[more]
        scale = np.where(scale > 0, scale, 1.0)
        lam, V = np.linalg.eigh(Mm + np.eye(d) * ((1.0 - hm) * scale[:, None])[:, None, :])
        rig = lam[:, 0] <= RIGID_RTOL * lam[:, -1]
        inv = np.where(rig[:, None], 0.0, 1.0 / np.where(rig[:, None], 1.0, lam))
        G = ((V * inv[:, None, :]) @ np.swapaxes(V, -1, -2)) * hm[:, :, None] * hm[:, None, :]
        Um = U[more]
        K[more] = Um @ G @ np.swapaxes(Um, -1, -2)
        rigid[more] = rig
    K[rigid] = np.nan
    return 0.5 * (K + np.swapaxes(K, -1, -2)), rigid


def platform_stiffness(springs, k, passive, valid, compliance=None) -> tuple[np.ndarray, np.ndarray]:
    """The platform's stiffness from its legs (virtual joint method): ``K = sum over legs of K_leg``.

    Every leg's tip moves with the tool point (a translational platform), so the legs act in
    parallel at the tool point and their stiffnesses add (:func:`leg_stiffness`).

    Parameters
    ----------
    springs : ndarray, shape (N, legs, d, s)
        Spring columns of every leg at every pose (pad with zero columns; NaN allowed where
        ``valid`` is False).
    k : array_like, shape (legs, s) or (N, legs, s)
        Their stiffnesses (``inf`` rigid, and for padding).
    passive : ndarray, shape (N, legs, d, p)
        Passive columns (pad with zero columns).
    valid : ndarray of bool, shape (N,)
        Poses to assemble.
    compliance : ndarray, shape (N, legs, d, d), optional
        Extra compliance of each leg at its tip (:func:`leg_stiffness`: its flexible links'), mm/N.

    Returns
    -------
    K : ndarray, shape (N, d, d), N/mm
        Exactly symmetric; zero where ``valid`` is False, NaN where a leg is rigid.
    rigid : ndarray of bool, shape (N, legs)
        Legs with no compliance along a direction they hold (False where not ``valid``).
    """
    Js = np.asarray(springs, dtype=np.float64)
    n, nlegs, d = Js.shape[:3]
    kk = np.asarray(k, dtype=np.float64)
    K = np.zeros((n, d, d))
    rigid = np.zeros((n, nlegs), dtype=bool)
    if np.any(valid):
        U, held = constrained_directions(np.asarray(passive, dtype=np.float64)[valid])
        extra = None if compliance is None else np.asarray(compliance, dtype=np.float64)[valid]
        Kl, rl = leg_stiffness(Js[valid], kk[valid] if kk.ndim == 3 else kk, U, held, extra)
        K[valid] = Kl.sum(axis=1)
        rigid[valid] = rl
    return K, rigid


# ---------------------------------------------------------------------- platforms that turn (6-D)


def skew(r) -> np.ndarray:
    """The cross-product matrix ``[r]x`` (``[r]x v = r x v``), shape (..., 3, 3)."""
    r = np.asarray(r, dtype=np.float64)
    S = np.zeros((*r.shape[:-1], 3, 3))
    S[..., 0, 1], S[..., 0, 2] = -r[..., 2], r[..., 1]
    S[..., 1, 0], S[..., 1, 2] = r[..., 2], -r[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -r[..., 1], r[..., 0]
    return S


def arm_map(r) -> np.ndarray:
    """``A = [[I, -[r]x], [0, I]]``: a rigid body's small displacement carried from one point to another.

    The body's displacement ``delta = (u mm, theta rad)`` at a point O (a translation and a
    rotation vector, base frame) moves the point ``O + r`` by ``u + theta x r`` and turns it
    by theta: ``(u + theta x r, theta) = A delta``. A wrench w at ``O + r`` is ``A^T w`` at O
    (the moment gains ``r x F``).

    Parameters
    ----------
    r : array_like, shape (..., 3), mm

    Returns
    -------
    ndarray, shape (..., 6, 6)
    """
    r = np.asarray(r, dtype=np.float64)
    A = np.zeros((*r.shape[:-1], 6, 6))
    A[..., :3, :3] = np.eye(3)
    A[..., 3:, 3:] = np.eye(3)
    A[..., :3, 3:] = -skew(r)
    return A


def _rows_scale(length_mm: float) -> np.ndarray:
    """``S = diag(1, 1, 1, L, L, L)``: a twist's rotation rows in mm (a rad counts as L mm)."""
    return np.array([1.0, 1.0, 1.0, length_mm, length_mm, length_mm])


def platform_stiffness6(
    springs, k, passive, arms, valid, *, length_mm: float = 1.0, compliance=None
) -> tuple[np.ndarray, np.ndarray]:
    """The 6 x 6 stiffness of a platform that turns, from its legs: ``K6 = sum A_i^T K_leg,i A_i``.

    Each leg's columns are 6-D at its platform joint (rows: the joint centre's velocity, mm
    per joint unit, then the angular velocity, rad per joint unit, base frame), passive
    columns including the platform joint's free rotations. :func:`leg_stiffness` in 6-D gives
    the leg's stiffness at its platform joint over the wrenches it holds (a 6-UPS leg: its
    axial force; a 3-RPS leg: the forces along it and across its plane; a universal platform
    joint adds the moment about its cross's normal); :func:`arm_map` carries it to the tool
    point, where the legs add up (the virtual joint method in 6-D).

    Rank decisions (:func:`constrained_directions`) and rigidity judge a twist with its
    rotation rows times ``length_mm``, so that rad and mm weigh alike at the robot's size; K6
    itself does not depend on that length.

    Parameters
    ----------
    springs : ndarray, shape (N, legs, 6, s)
        Spring columns (actuated and spring joints) of every leg at every pose; pad with zero
        columns, NaN allowed where ``valid`` is False.
    k : array_like, shape (legs, s) or (N, legs, s)
        Their stiffnesses, N*mm/rad or N/mm (``inf`` rigid, and for padding).
    passive : ndarray, shape (N, legs, 6, p)
        Passive columns, the platform joint's rotations among them (pad with zero columns).
    arms : ndarray, shape (N, legs, 3), mm
        From the tool point to each leg's platform joint, base frame.
    valid : ndarray of bool, shape (N,)
        Poses to assemble.
    length_mm : float
        The robot's size, for the rank decisions.
    compliance : ndarray, shape (N, legs, 6, 6), optional
        Extra compliance of each leg at its platform joint (:func:`leg_stiffness`), mm/N,
        1/N and rad/(N*mm) blocks.

    Returns
    -------
    K6 : ndarray, shape (N, 6, 6)
        N/mm, N and N*mm/rad blocks, at the tool point, base frame; exactly symmetric; zero
        where ``valid`` is False, NaN where a leg is rigid.
    rigid : ndarray of bool, shape (N, legs)
        Legs with no compliance along a wrench they hold (False where not ``valid``).
    """
    Js = np.asarray(springs, dtype=np.float64)
    n, nlegs = Js.shape[:2]
    kk = np.asarray(k, dtype=np.float64)
    K6 = np.zeros((n, 6, 6))
    rigid = np.zeros((n, nlegs), dtype=bool)
    if not np.any(valid):
        return K6, rigid
    S = _rows_scale(float(length_mm))
    Jp = np.asarray(passive, dtype=np.float64)[valid] * S[:, None]
    U, held = constrained_directions(Jp)
    extra = None
    if compliance is not None:
        extra = np.asarray(compliance, dtype=np.float64)[valid] * S[:, None] * S[None, :]
    Kl, rl = leg_stiffness(Js[valid] * S[:, None], kk[valid] if kk.ndim == 3 else kk, U, held, extra)
    Kl = Kl * S[:, None] * S[None, :]  # back from the scaled twists: K = S K' S
    A = arm_map(np.asarray(arms, dtype=np.float64)[valid])
    K = np.einsum("nlji,nljk,nlkm->nim", A, Kl, A)
    K6[valid] = 0.5 * (K + np.swapaxes(K, 1, 2))
    rigid[valid] = rl
    return K6, rigid


def held_wrench_condition(passive, arms, reachable, *, length_mm: float = 1.0) -> np.ndarray:
    """The parallel-singularity measure of a platform that turns: the inverse condition number
    of every leg's held wrenches carried to the tool point.

    The wrenches a leg holds (the complement of its passive columns, :func:`constrained_directions`)
    are what it can push the platform with; stacked over the legs at the tool point (moments
    divided by ``length_mm``) they span the six directions away from a parallel singularity
    (Gosselin and Angeles' type II: a hexapod's Jacobian losing rank), and their smallest over
    largest singular value, counted over six, is 0 there (and where the legs hold fewer than six).

    Parameters
    ----------
    passive : ndarray, shape (N, legs, 6, p)
    arms : ndarray, shape (N, legs, 3), mm
    reachable : ndarray of bool, shape (N,)
    length_mm : float

    Returns
    -------
    ndarray, shape (N,)
        In [0, 1]; NaN where not ``reachable``.
    """
    out = np.full(reachable.shape, np.nan)
    if not np.any(reachable):
        return out
    S = _rows_scale(float(length_mm))
    U, held = constrained_directions(np.asarray(passive, dtype=np.float64)[reachable] * S[:, None])
    W = U * held[..., None, :]  # (n, legs, 6, 6): held wrenches (f, m / L) as columns
    A = arm_map(np.asarray(arms, dtype=np.float64)[reachable] / float(length_mm))
    Wt = np.swapaxes(A, -1, -2) @ W  # at the tool point: (f, m / L + (r / L) x f)
    Z = np.swapaxes(Wt, 1, 2).reshape(Wt.shape[0], 6, -1)
    lam = np.clip(np.linalg.eigvalsh(Z @ np.swapaxes(Z, 1, 2)), 0.0, None)
    top = np.where(lam[:, -1] > 0, lam[:, -1], 1.0)
    out[reachable] = np.where(lam[:, -1] > 0, np.sqrt(lam[:, 0] / top), 0.0)
    return out


def force_moment_stiffness(K6) -> tuple[np.ndarray, np.ndarray]:
    """The stiffness a pure force sees and the one a pure moment sees, from K6.

    ``C6 = K6^-1``; a pure force F moves the tool point by ``C6[:3, :3] F`` (the platform free
    to turn), so ``K = (C6[:3, :3])^-1``, N/mm -- what the vision path measures with a force
    at the tool point; a pure moment turns the platform by ``C6[3:, 3:] M``, so
    ``K_rot = (C6[3:, 3:])^-1``, N*mm/rad. Neither is a block of K6 unless the blocks decouple.

    Parameters
    ----------
    K6 : array_like, shape (..., 6, 6)
        Invertible.

    Returns
    -------
    K : ndarray, shape (..., 3, 3), N/mm
    K_rot : ndarray, shape (..., 3, 3), N*mm/rad
    """
    K6 = np.asarray(K6, dtype=np.float64)
    C = np.linalg.inv(K6)
    K = np.linalg.inv(0.5 * (C[..., :3, :3] + np.swapaxes(C[..., :3, :3], -1, -2)))
    Kr = np.linalg.inv(0.5 * (C[..., 3:, 3:] + np.swapaxes(C[..., 3:, 3:], -1, -2)))
    return 0.5 * (K + np.swapaxes(K, -1, -2)), 0.5 * (Kr + np.swapaxes(Kr, -1, -2))


def stiffness_of(mechanism, points) -> np.ndarray:
    """``mechanism.stiffness(points)`` from its map: K (N/mm) at every pose, which must all be valid.

    The :class:`Mechanism` method for a model that has ``evaluate`` and ``dim``.

    Parameters
    ----------
    points : array_like, shape (N, dim) or (dim,), mm, base frame

    Returns
    -------
    ndarray, shape (N, dim, dim) or (dim, dim), N/mm

    Raises
    ------
    PoseError
        Naming the first unreachable or singular pose.
    """
    _, single = as_points(points, mechanism.dim)
    m = mechanism.evaluate(points)
    raise_first_invalid(m, single)
    return m.K[0].copy() if single else m.K.copy()


def static_error_of(mechanism, points, force) -> np.ndarray:
    """``mechanism.static_error(points, force)``: u = K^-1 F (mm) under a force F (N), base frame.

    Parameters
    ----------
    points : array_like, shape (N, dim) or (dim,), mm
    force : array_like, shape (d,) or (N, d), N
        d = dim, or 3 for a robot whose poses have six coordinates.

    Returns
    -------
    ndarray, shape (N, d) or (d,), mm
    """
    P, single = as_points(points, mechanism.dim)
    d = 3 if mechanism.dim == POSE_DIM else mechanism.dim  # a pose of six: a force of three
    F = as_forces(force, P.shape[0], d)
    K = mechanism.stiffness(P)
    u = np.linalg.solve(K, F[..., None])[..., 0]
    return u[0] if single else u


class LegMechanism:
    """The :class:`Mechanism` methods shared by stiffmap's parallel robots made of legs.

    Every such robot's stiffness is the virtual joint method's assembly,
    :func:`platform_stiffness` of its legs' joint columns: the built-in Delta and 3PRR
    (closed-form columns) and :class:`~stiffmap.models.legs.LegRobot` (columns from each
    leg's kinematic chain) are instances of it.

    A frozen dataclass inherits them. It has a ``singular_tol`` field and provides
    ``name``, ``dim``, ``_LABEL`` (its name in messages), the classmethod
    ``param_names()``, ``legs(points)`` (per-leg quantities with a ``reachable``
    mask), ``_unreachable_reasons(points, legs)``,
    ``_measures(legs)`` (serial and parallel singularity measures),
    ``_leg_joints(legs)`` (every leg's spring columns, their stiffnesses and its passive
    columns: the arguments of :func:`platform_stiffness` but ``valid``),
    ``_joint_coordinates(legs)`` (the map's ``q``), ``_serial_singularity(legs, i)``
    (what is singular at pose i, in words) and ``_PARALLEL_SINGULARITY`` (the same
    for a parallel singularity). From these :meth:`_map_from_legs` builds the
    :class:`ModelMap`.

    A third-party robot need not inherit this: :class:`Mechanism` is a protocol,
    and implementing its methods is all stiffmap asks.
    """

    name: ClassVar[str]
    dim: ClassVar[int]
    _LABEL: ClassVar[str]
    _PARALLEL_SINGULARITY: ClassVar[str]
    singular_tol: float

    def _check_singular_tol(self) -> None:
        """Store ``singular_tol`` as a float in [0, 1) (for ``__post_init__``)."""
        tol = float(self.singular_tol)
        if not (0 <= tol < 1):
            raise ValueError(f"singular_tol must be in [0, 1), got {self.singular_tol!r}")
        object.__setattr__(self, "singular_tol", tol)

    def params(self) -> dict[str, float]:
        """The scalar parameters and their values (units as the fields)."""
        return {k: getattr(self, k) for k in self.param_names()}

    def with_params(self, **params) -> Self:
        """A copy with some parameters changed (any field; unknown names raise ValueError)."""
        names = self.param_names()
        valid = [f.name for f in fields(self)]
        bad = sorted(set(params) - set(valid))
        if bad:
            raise ValueError(
                f"unknown {self._LABEL} parameter(s) {', '.join(bad)}; valid: {', '.join(names)}"
            )
        return replace(self, **params)

    def _map_from_legs(self, points, legs) -> ModelMap:
        """The :class:`ModelMap` of poses from their legs: reachable, not singular, K = sum of the legs' K.

        The conditioning of a pose is the smaller of its two singularity measures
        (NaN where unreachable).
        """
        P, _ = as_points(points, self.dim)
        reasons = self._unreachable_reasons(P, legs)
        serial, parallel = self._measures(legs)
        tol = self.singular_tol

        def serial_reason(i: int) -> str:
            return (
                f"{self._serial_singularity(legs, i)} (serial singularity, workspace boundary; "
                f"sine {serial[i]:.2g} < {tol:g})"
            )

        def parallel_reason(i: int) -> str:
            return (
                f"{self._PARALLEL_SINGULARITY} (parallel singularity; inverse condition "
                f"{parallel[i]:.2g} < {tol:g})"
            )

        valid = flag_singular(legs.reachable, serial, parallel, tol, reasons, serial_reason, parallel_reason)
        K, rigid, six = self._assemble(legs, valid)
        for i in np.flatnonzero(np.any(rigid, axis=1)):  # every spring along a held direction rigid
            which = [str(j + 1) for j in np.flatnonzero(rigid[i])]
            legs_ = ("leg " if len(which) == 1 else "legs ") + ", ".join(which)
            reasons[i] = f"singular: {legs_} rigid along a direction held (no finite spring acts there)"
            valid[i] = False
        for i in np.flatnonzero(valid & ~np.all(np.isfinite(K), axis=(1, 2))):
            reasons[i] = "singular: the legs do not hold the platform in every direction (K6 singular)"
            valid[i] = False
        cond = np.where(legs.reachable, np.fmin(serial, parallel), np.nan)
        return model_map(
            self.name, self.params(), P, K, valid, reasons, self._joint_coordinates(legs), cond, **six
        )

    def _assemble(self, legs, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
        """K (N/mm) of the valid poses from the legs, the rigid legs, and extra map fields.

        The platform translates: :func:`platform_stiffness` (a robot whose platform turns
        overrides this with :func:`platform_stiffness6` and gives ``K6``).
        """
        K, rigid = platform_stiffness(*self._leg_joints(legs), valid)
        return K, rigid, {}

    def _valid_legs(self, points) -> tuple[Any, bool]:
        """The legs of poses that must all be valid (PoseError naming the first that is not).

        Returns
        -------
        legs
            As :meth:`legs`.
        single : bool
            True when one pose of shape ``(dim,)`` was given.
        """
        _, single = as_points(points, self.dim)
        legs = self.legs(points)
        raise_first_invalid(self._map_from_legs(points, legs), single)
        return legs, single

    def singularity_measures(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Serial and parallel singularity measures, both in [0, 1] (0 at a singularity).

        Parameters
        ----------
        points : array_like, shape (N, dim) or (dim,), mm

        Returns
        -------
        serial, parallel : ndarray, shape (N,)
            What each measures is in the model's docstring.
        """
        return self._measures(self.legs(points))

    def evaluate(self, points) -> ModelMap:
        """Stiffness map over many poses, flagging unreachable and singular ones.

        Parameters
        ----------
        points : array_like, shape (N, dim) or (dim,), mm

        Returns
        -------
        ModelMap
            K (N/mm) at the tool point in the base frame; ``q`` the actuated joint
            coordinates (rad or mm).

        Examples
        --------
        The Delta's stiffness map at two poses, the second out of reach:

        >>> from stiffmap.models.delta import DeltaRobot
        >>> mp = DeltaRobot().evaluate([[0, 0, -400], [0, 0, -2000]])  # mm
        >>> mp.valid.tolist(), mp.reasons[1].split(":")[0]
        ([True, False], 'unreachable')
        >>> round(float(mp.min_principal[0]), 2)  # N/mm, along the softest direction
        3.18
        """
        return self._map_from_legs(points, self.legs(points))

    def stiffness(self, points) -> np.ndarray:
        """K (N/mm) at the tool point, base frame (the model's equations in its docstring).

        Parameters
        ----------
        points : array_like, shape (N, dim) or (dim,), mm

        Returns
        -------
        ndarray, shape (N, dim, dim) or (dim, dim), N/mm

        Raises
        ------
        PoseError
            Naming the first unreachable or singular pose.
        """
        return stiffness_of(self, points)

    def static_error(self, points, force) -> np.ndarray:
        """Static error ``u = K^-1 F`` (mm) of the tool under a force F (N).

        Parameters
        ----------
        points : array_like, shape (N, dim) or (dim,), mm
        force : array_like, shape (dim,) or (N, dim), N

        Returns
        -------
        ndarray, shape (N, dim) or (dim,), mm
        """
        return static_error_of(self, points, force)
