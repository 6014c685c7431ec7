"""Joint stiffnesses of a robot identified from measured deflections (virtual-joint model).

The model
---------
A serial robot, or the virtual-joint model of any robot, with n joints held by springs of
compliance ``c_j`` deflects at its measured point under a wrench ``w`` by

    delta = J C J^T w,      C = diag(c_1, ..., c_n),

- ``J`` (6 x n): the Jacobian of the measured point in the base frame, rows
  ``(vx, vy, vz, wx, wy, wz)``: the point's velocity (mm per joint unit) and the angular
  velocity (rad per joint unit). Column j of a revolute joint about the unit axis z_j
  through o_j is ``(z_j x (p - o_j), z_j)`` (mm/rad, rad/rad); of a prismatic joint along
  z_j, ``(z_j, 0)`` (mm/mm);
- ``w = (F, M)``: force (N) and moment (N*mm) at the measured point, base frame (a force F
  at the point p + r is the wrench ``(F, r x F)``);
- ``delta = (u, r)``: the point's displacement (mm) and the rotation vector of the loaded
  orientation relative to the unloaded one (rad), base frame (``docs/conventions.md``);
- ``c_j``: rad/(N*mm) for a revolute joint, mm/N for a prismatic one. The joint stiffness
  is ``k_j = 1 / c_j``: N*mm/rad (revolute) or N/mm (prismatic).

``J^T w`` is the generalised force on each joint (N*mm or N), ``C J^T w`` the joints'
deflections, ``J`` carries them to the measured point. The deflection is linear in c:

    delta = A c,     A[:, j] = J[:, j] (J[:, j] . w)             (:func:`joint_deflections`)

so the compliances follow from measured deflections under known wrenches at several
configurations by weighted linear least squares (:func:`fit_joint_compliances`). A
measurement is either a 6-DOF pose change (d = 6: u and r) or the displacement of a point
(d = 3: u only), each with its covariance (d x d, full).

The fit
-------
Each measured displacement is whitened by the Cholesky factor of its covariance
(``cov = L L^T``; ``L^-1`` applied to its row of A and to the displacement), so the fit
minimises ``chi2 = sum_m r_m^T cov_m^-1 r_m`` over the residuals r_m. Joints not fitted
are held at given compliances and their deflection is subtracted first. The covariance of
the estimates is ``(A_w^T A_w)^-1``, multiplied by the reduced chi-square ``chi2 / dof``
unless ``absolute_sigma`` (the covariances are then taken as exact), as
:mod:`stiffmap.models.fit` does. Compliances are kept non-negative by default
(``scipy.optimize.lsq_linear``, bounded variables): a joint held at 0 is reported
(``active``, a note), its standard error is NaN and the covariance covers the free joints.
The stiffness's standard error follows by the delta method, ``k_std = c_std / c^2``.

Identifiability
---------------
Before solving, :func:`joint_identifiability` looks at the whitened design with its columns
scaled to unit length (:class:`JointIdentifiability`):

- **not felt**: a joint whose column is negligible, its relative sensitivity below
  :data:`~stiffmap.models.fit.MIN_RELATIVE_SENSITIVITY`: no load acts on it (a revolute
  axis that no load has a moment about, a force through the axis), or it moves nothing
  that is measured (the measured point on its axis, translations only);
- **confounded**: joints whose compliances move the measurements only in a fixed
  combination: components of the right singular vectors whose singular value is below
  :data:`~stiffmap.models.fit.MIN_INVERSE_CONDITION` times the largest (joints 4 and 6 of
  a wrist held straight, for instance).

Either is refused with a :class:`~stiffmap.errors.DesignError` naming the joints, why, and
what would determine them. A design that determines every joint but badly (condition number
above :data:`~stiffmap.models.fit.CONDITION_WARN`) passes with an
:class:`~stiffmap.errors.IllConditionedWarning`.

The relative sensitivity of joint j compares its whitened column with the largest it could
be given the magnitudes of the wrenches, of the Jacobian's entries and of the weights: about
0.1-1 when the loads act on the joint and its motion is measured, about 1e-16 when it is felt
only through rounding errors. Rotations are compared with translations through a length, the
RMS lever arm ``l = |z_j x (p - o_j)|`` of the revolute joints at the measured point (at least
1 mm): a force through a revolute axis is "no moment about it" when its lever arm is below
1e-6 l, and, translations only, a measured point closer than 1e-6 l to the axis does not
see the joint move.

The misfit test: with covariances given, ``p = P(chi2_dof > chi2)``
(``scipy.stats.chi2.sf``); below :data:`~stiffmap.models.fit.MISFIT_P` a note says the model
or the uncertainties do not explain the data.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import DesignError, IllConditionedWarning, InputError
from ..io import to_jsonable
from ..stats import chi2_sf
from .fit import (
    CONDITION_WARN,
    MIN_INVERSE_CONDITION,
    MIN_RELATIVE_SENSITIVITY,
    MISFIT_P,
    MISFIT_RELATIVE,
    _group_poses,
    separation_notes,
)
from .whiten import as_float, check_finite, whitener

__all__ = [
    "LinkColumns",
    "JointFit",
    "JointIdentifiability",
    "fit_joint_compliances",
    "joint_deflections",
    "joint_identifiability",
    "NULL_WEIGHT",
]

#: A joint whose unit vector has a component above this in the numerical null space of the
#: column-scaled design is named as undetermined (its share of a combination the data
#: cannot see).
NULL_WEIGHT = 1e-3
#: A joint whose angular-velocity column has a norm above this (rad per joint unit) is revolute.
_REVOLUTE_MIN_OMEGA = 0.5

#: Why a joint is not felt, said of one joint and of several.
_WHY = {
    "moment": ("no load has a moment about its axis", "no load has a moment about their axes"),
    "force": ("no load has a force along its axis", "no load has a force along their axes"),
    "measure": (
        "it moves nothing that is measured (the measured point lies on its axis)",
        "they move nothing that is measured (the measured point lies on their axes)",
    ),
    "where": (
        "the loads act on it only where its motion is not measured",
        "the loads act on them only where their motion is not measured",
    ),
    "bend": (
        "the loads do not deform that link in a way the measurements see",
        "the loads do not deform those links in a way the measurements see",
    ),
}

_UNITS = {
    "revolute": ("rad/(N*mm)", "N*mm/rad"),
    "prismatic": ("mm/N", "N/mm"),
    "modulus": ("1/MPa", "MPa"),  # a flexible link's E or G: its "compliance" is 1/E
    "factor": ("1", "1"),  # a given link compliance's stiffness factor f: compliance 1/f
}
#: Kinds of a flexible link's parameter.
LINK_KINDS = ("modulus", "factor")


@dataclass(frozen=True)
class LinkColumns:
    """A flexible link's parameter p in the fit, beside the joints (:mod:`~stiffmap.models.links`).

    The link's compliance is ``sum_p B_p / p``, so the measured point deflects by
    ``sum_p (J_s B_p J_s^T w) / p``: linear in ``1/p``, the parameter's "compliance", fitted as a
    joint's. ``basis[m]`` is ``J_s B_p J_s^T`` at row m's configuration (6 x 6, base frame;
    :meth:`SerialRobot.link_bases`).

    Attributes
    ----------
    name : str
        ``E_<link>``, ``G_<link>`` or ``f_<link>``.
    basis : ndarray, shape (M, 6, 6)
        mm/N (etc.) times MPa for a modulus; as a compliance for a factor.
    kind : {"modulus", "factor"}
        p in MPa (a beam's E or G), or dimensionless (a given compliance's stiffness factor).
    """

    name: str
    basis: np.ndarray
    kind: str = "modulus"


# --------------------------------------------------------------------------- input checks


def _check_jacobians(jacobians) -> np.ndarray:
    J = as_float(jacobians, "jacobians")
    if J.ndim != 3 or J.shape[1] != 6 or J.shape[0] < 1 or J.shape[2] < 1:
        raise InputError(
            f"jacobians: expected shape (M, 6, n), one 6 x n Jacobian per measurement "
            f"(rows vx, vy, vz in mm and wx, wy, wz in rad per joint unit), got {J.shape}"
        )
    check_finite(J, "jacobians", "mm and rad per joint unit")
    return J


def _check_wrenches(wrenches, M: int) -> np.ndarray:
    W = as_float(wrenches, "wrenches")
    if W.shape != (M, 6):
        raise InputError(f"wrenches: expected shape ({M}, 6), (F in N, M in N*mm) per row, got {W.shape}")
    check_finite(W, "wrenches", "N and N*mm")
    return W


def _check_displacements(displacements, M: int) -> np.ndarray:
    D = as_float(displacements, "displacements")
    if D.ndim != 2 or D.shape[0] != M or D.shape[1] not in (3, 6):
        raise InputError(
            f"displacements: expected shape ({M}, 3) (translations, mm) or ({M}, 6) "
            f"(translations mm, rotation vector rad), got {D.shape}"
        )
    check_finite(D, "displacements", "mm and rad")
    return D


def _check_names(joint_names, n: int) -> tuple[str, ...]:
    if joint_names is None:
        return tuple(f"k{j + 1}" for j in range(n))
    if isinstance(joint_names, str):
        joint_names = (joint_names,)
    names = tuple(str(s) for s in joint_names)
    if len(names) != n:
        raise InputError(f"joint_names: expected {n} names (one per Jacobian column), got {len(names)}")
    dup = sorted({s for s in names if names.count(s) > 1})
    if dup:
        raise InputError(f"joint_names: {', '.join(dup)} given more than once")
    return names


def _check_fit_sets(names: tuple[str, ...], fit, fixed) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the fitted joints, and the compliances of all (NaN for the fitted)."""
    n = len(names)
    fixed = {} if fixed is None else fixed
    if not isinstance(fixed, Mapping):
        raise InputError(f"fixed: expected a mapping of joint name to compliance, got {type(fixed).__name__}")
    bad = [str(k) for k in fixed if k not in names]
    if bad:
        raise InputError(f"fixed: unknown joint(s) {', '.join(bad)}; joints: {', '.join(names)}")
    values = np.full(n, np.nan)
    for k, v in fixed.items():
        try:
            c = float(v)
        except (TypeError, ValueError):
            raise InputError(f"fixed: {k} must be a compliance (a number), got {v!r}") from None
        if not (np.isfinite(c) and c >= 0):
            raise InputError(f"fixed: {k} must be a finite non-negative compliance, got {c!r}")
        values[names.index(k)] = c
    if fit is None:
        fitted = [s for s in names if s not in fixed]
    else:
        if isinstance(fit, str):
            fit = (fit,)
        fitted = [str(s) for s in fit]
        bad = [s for s in fitted if s not in names]
        if bad:
            raise InputError(f"fit: unknown joint(s) {', '.join(bad)}; joints: {', '.join(names)}")
        dup = sorted({s for s in fitted if fitted.count(s) > 1})
        if dup:
            raise InputError(f"fit: {', '.join(dup)} given more than once")
        both = [s for s in fitted if s in fixed]
        if both:
            raise InputError(f"fit: {', '.join(both)} also held in fixed; a joint is either fitted or fixed")
        loose = [s for s in names if s not in fitted and s not in fixed]
        if loose:
            raise InputError(
                f"fixed: no compliance for {', '.join(loose)}, neither fitted nor fixed; give "
                f"{'its' if len(loose) == 1 else 'their'} compliance in fixed or fit "
                f"{'it' if len(loose) == 1 else 'them'}"
            )
    if not fitted:
        raise InputError("fit: no joint to fit")
    idx = np.array(sorted(names.index(s) for s in fitted), dtype=int)
    return idx, values


def _joint_types(J: np.ndarray) -> tuple[str, ...]:
    omega = np.sqrt(np.mean(np.sum(J[:, 3:, :] ** 2, axis=1), axis=0))
    return tuple("revolute" if w > _REVOLUTE_MIN_OMEGA else "prismatic" for w in omega)


def _design(J: np.ndarray, W: np.ndarray) -> np.ndarray:
    """A[m, :, j] = J[m, :, j] (J[m, :, j] . w_m): shape (M, 6, n), mm or rad per compliance unit."""
    g = np.einsum("mkj,mk->mj", J, W)
    return J * g[:, None, :]


# --------------------------------------------------------------------------- forward model


def joint_deflections(jacobians, wrenches, compliances) -> np.ndarray:
    """Deflection ``J C J^T w`` of the measured point under wrenches (the forward model).

    Parameters
    ----------
    jacobians : array_like, shape (M, 6, n)
        Jacobian of the measured point at each configuration, base frame: rows vx, vy, vz
        (mm per joint unit) and wx, wy, wz (rad per joint unit).
    wrenches : array_like, shape (M, 6) or (6,)
        Force (N) and moment (N*mm) at the measured point, base frame; one for all rows
        when 1-D.
    compliances : array_like, shape (n,) or (M, n)
        Joint compliances: rad/(N*mm) (revolute) or mm/N (prismatic).

    Returns
    -------
    ndarray, shape (M, 6)
        Displacement of the point (mm) and rotation vector (rad), base frame.

    Raises
    ------
    InputError
        Wrong shapes or non-finite values, naming the argument and the row.
    """
    J = _check_jacobians(jacobians)
    M, _, n = J.shape
    W = as_float(wrenches, "wrenches")
    if W.shape == (6,):
        W = np.broadcast_to(W, (M, 6))
    W = _check_wrenches(W, M)
    c = as_float(compliances, "compliances")
    if c.shape not in ((n,), (M, n)):
        raise InputError(f"compliances: expected shape ({n},) or ({M}, {n}), got {c.shape}")
    if not np.all(np.isfinite(c)):
        raise InputError("compliances: NaN or infinite values; expected finite compliances")
    c = np.broadcast_to(c, (M, n))
    return np.einsum("mkj,mj->mk", _design(J, W), c)


# --------------------------------------------------------------------------- identifiability


@dataclass(frozen=True)
class JointIdentifiability:
    """What a set of configurations and loads can determine (:func:`joint_identifiability`).

    Attributes
    ----------
    names : tuple of str
        The joints examined (the fitted ones), in the order of the arrays below.
    joint_types : tuple of str
        ``"revolute"`` or ``"prismatic"`` of each.
    sensitivity : ndarray, shape (p,)
        Relative sensitivity of the measurements to each joint, in [0, 1] (module docstring);
        below ``MIN_RELATIVE_SENSITIVITY`` the joint is not felt.
    condition : float
        Condition number of the whitened design over the felt joints, columns scaled to unit
        length (1 for orthogonal columns; ``inf`` when some joints are confounded).
    singular_values : ndarray, shape (q,)
        Singular values of that design relative to the largest, descending (q = felt joints).
    directions : ndarray, shape (q, p)
        The matching right singular vectors over all examined joints (0 for joints not
        felt), in the column-scaled parameters: row k is the combination of joints that
        the data see with strength ``singular_values[k]``; the last rows are the weakest.
    inflation : ndarray, shape (p,)
        How much the correlation with the other joints inflates each joint's standard error
        (square root of the variance inflation factor, >= 1; ``inf`` when undetermined).
    weakest : ndarray, shape (p,)
        For each joint, the relative singular value of the direction that contributes most
        to its variance (0 when undetermined).
    not_felt : dict of str to str
        Joints not felt, with the reason in words.
    confounded : tuple of tuple of str
        Groups of joints the data see only in a fixed combination.
    message : str
        Empty when every joint is determined, else the refusal (names, why, what to add).
    """

    names: tuple[str, ...]
    joint_types: tuple[str, ...]
    sensitivity: np.ndarray
    condition: float
    singular_values: np.ndarray
    directions: np.ndarray
    inflation: np.ndarray
    weakest: np.ndarray
    not_felt: dict[str, str]
    confounded: tuple[tuple[str, ...], ...]
    message: str

    @property
    def determined(self) -> bool:
        """True when the data determine every examined joint."""
        return not self.message

    @property
    def undetermined(self) -> tuple[str, ...]:
        """The joints the data cannot determine (not felt or confounded), in joint order."""
        bad = set(self.not_felt) | {s for g in self.confounded for s in g}
        return tuple(s for s in self.names if s in bad)

    def to_dict(self) -> dict:
        """Plain JSON-able summary (NaN and inf become None)."""
        return to_jsonable(
            {
                "joints": {
                    s: {
                        "type": t,
                        "sensitivity": float(v),
                        "inflation": float(f),
                        "weakest": float(w),
                        "determined": s not in self.undetermined,
                    }
                    for s, t, v, f, w in zip(
                        self.names,
                        self.joint_types,
                        self.sensitivity,
                        self.inflation,
                        self.weakest,
                        strict=True,
                    )
                },
                "condition": self.condition,
                "singular_values": self.singular_values,
                "directions": self.directions,
                "not_felt": dict(self.not_felt),
                "confounded": [list(g) for g in self.confounded],
                "message": self.message,
            }
        )


def _lever_arm(J: np.ndarray, types: tuple[str, ...]) -> float:
    """The length (mm) that compares rotations with translations: the RMS lever arm
    ``|z_j x (p - o_j)|`` of the revolute joints at the measured point, at least 1 mm."""
    rev = [j for j, t in enumerate(types) if t == "revolute"]
    if not rev:
        return 1.0
    return max(float(np.sqrt(np.mean(np.sum(J[:, :3, rev] ** 2, axis=1)))), 1.0)


def _relative_sensitivity(J, W, Linv, d, ell) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per joint: (relative sensitivity, load factor, motion factor), each in [0, 1].

    Row m, joint j: the whitened column is ``L^-1 S J_j (J_j . w)``. With the lever arm
    ``ell`` (mm) rotations compare with translations: ``D = diag(1, 1, 1, ell, ell, ell)``.
    The load factor compares ``|J_j . w|`` with its bound ``|D J_j| |D^-1 w|``; the motion
    factor compares ``|L^-1 S J_j|`` with ``|| |L^-1| |S J_j| || |D J_j| / |D S J_j|``, the
    whitened motion if all of the joint's motion were measured; the sensitivity compares the
    column with the product of the two bounds. Each ratio is taken over all rows at once.
    """
    Dv = np.array([1.0, 1.0, 1.0, ell, ell, ell])
    SJ = J[:, :d, :]  # (M, d, n): the measured part of each joint's motion
    g = np.einsum("mkj,mk->mj", J, W)  # generalised forces, N*mm or N
    djn = np.linalg.norm(J * Dv[None, :, None], axis=1)  # (M, n)
    h = djn * np.linalg.norm(W / Dv, axis=1)[:, None]  # bound of |g|
    dsjn = np.linalg.norm(SJ * Dv[None, :d, None], axis=1)
    u = np.where(
        dsjn[:, None, :] > 0, np.abs(SJ) / np.where(dsjn > 0, dsjn, 1.0)[:, None, :], 1.0 / np.sqrt(d)
    )
    motion = np.linalg.norm(Linv @ SJ, axis=1)  # (M, n)
    bound = np.linalg.norm(np.abs(Linv) @ u, axis=1) * djn  # bound of the motion

    def ratio(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        num, den = np.sqrt(np.sum(x**2, axis=0)), np.sqrt(np.sum(y**2, axis=0))
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)

    return ratio(motion * g, bound * h), ratio(g, h), ratio(motion, bound)


def _format_names(names: Sequence[str]) -> str:
    return ", ".join(names)


def _identify(
    Aw: np.ndarray,
    names: tuple[str, ...],
    types: tuple[str, ...],
    sens: np.ndarray,
    load_f: np.ndarray,
    motion_f: np.ndarray,
    *,
    d: int,
    n_config: int,
    has_moments: bool,
) -> JointIdentifiability:
    """The identifiability report of a whitened design ``Aw`` (N, p) over the joints ``names``."""
    felt = sens >= MIN_RELATIVE_SENSITIVITY
    not_felt, why_groups, hints = _not_felt(felt, names, types, load_f, motion_f)
    fi = np.flatnonzero(felt)
    s = _felt_spectrum(Aw, fi, names)
    message = ""
    bad_names = [j for j in names if j in not_felt or any(j in g for g in s.confounded)]
    if bad_names:
        message = _undetermined_message(
            bad_names,
            names,
            types,
            why_groups,
            hints,
            s.confounded,
            d=d,
            n_config=n_config,
            has_moments=has_moments,
        )
    return JointIdentifiability(
        names=names,
        joint_types=types,
        sensitivity=sens,
        condition=s.condition,
        singular_values=s.rel,
        directions=s.directions,
        inflation=s.inflation,
        weakest=s.weakest,
        not_felt=not_felt,
        confounded=tuple(s.confounded),
        message=message,
    )


def _not_felt(felt, names, types, load_f, motion_f):
    """Why each joint the data hardly feel is not felt (its message), the joints grouped by
    their reasons, and what to add -> the joints it would help."""
    not_felt: dict[str, str] = {}
    why_groups: dict[tuple[str, ...], list[str]] = {}  # reasons -> joints
    hints: dict[str, list[str]] = {}  # what to add -> the joints it would help
    for j in np.flatnonzero(~felt):
        s, t = names[j], types[j]
        why = []
        if t in LINK_KINDS:
            why.append("bend")
        elif load_f[j] < MIN_RELATIVE_SENSITIVITY:
            why.append("moment" if t == "revolute" else "force")
        if motion_f[j] < MIN_RELATIVE_SENSITIVITY:
            why.append("measure")
        if not why:
            why.append("where")
        for w in why:
            hints.setdefault(w, []).append(s)
        why_groups.setdefault(tuple(why), []).append(s)
        not_felt[s] = " and ".join(_WHY[w][0] for w in why)
    return not_felt, why_groups, hints


@dataclass
class _Spectrum:
    """The felt joints' scaled design, seen through its singular values (:func:`_felt_spectrum`)."""

    rel: np.ndarray  # singular values relative to the largest
    directions: np.ndarray  # (q, p) right singular vectors over all joints
    inflation: np.ndarray  # (p,) variance inflation (inf: not determined)
    weakest: np.ndarray  # (p,) the relative singular value each joint leans on most
    confounded: list[tuple[str, ...]]
    condition: float


def _felt_spectrum(Aw: np.ndarray, fi: np.ndarray, names: tuple[str, ...]) -> _Spectrum:
    """The SVD of the felt joints' unit columns: the condition, each joint's inflation and the
    groups of joints the data see only in a fixed combination (the null space)."""
    N, p = Aw.shape
    q = fi.size
    out = _Spectrum(np.zeros(q), np.zeros((q, p)), np.full(p, np.inf), np.zeros(p), [], np.inf)
    if not q:
        return out
    A = Aw[:, fi]
    norms = np.linalg.norm(A, axis=0)
    An = A / norms
    _, s, Vt = np.linalg.svd(An, full_matrices=N < q)
    s = np.concatenate([s, np.zeros(q - s.size)])
    rel = out.rel = s / s[0]
    out.directions[:, fi] = Vt
    null = rel < MIN_INVERSE_CONDITION
    if np.any(null):
        named = _null_groups(Vt[null], fi, names, out.confounded)
        good = ~named
    else:
        out.condition = float(1.0 / rel[-1])
        good = np.ones(q, dtype=bool)
    ok = ~null
    # The variance of the scaled parameters is V diag(1/s^2) V^T; with unit columns an
    # orthogonal design has variance 1, so the inflation is sqrt(sum_k V_jk^2 / s_k^2).
    contrib = Vt[ok].T ** 2 / s[ok][None, :] ** 2  # (q, r): each direction's share
    vif = np.sum(contrib, axis=1)
    for k in np.flatnonzero(good):
        out.inflation[fi[k]] = float(np.sqrt(vif[k]))
        out.weakest[fi[k]] = float(rel[ok][int(np.argmax(contrib[k]))])
    return out


def _null_groups(V0: np.ndarray, fi: np.ndarray, names, confounded: list) -> np.ndarray:
    """Append to ``confounded`` the groups of joints linked through the null space ``V0``
    (its rows); return which felt joints take part in it."""
    q = fi.size
    P = V0.T @ V0  # projector on the null space: independent of its basis
    named = np.diag(P) > NULL_WEIGHT**2
    link = (np.abs(P) > NULL_WEIGHT**2) & named[:, None] & named[None, :]
    seen = np.zeros(q, dtype=bool)
    for k in np.flatnonzero(named):
        if seen[k]:
            continue
        group, stack = [], [k]
        seen[k] = True
        while stack:
            i = stack.pop()
            group.append(i)
            for m in np.flatnonzero(link[i] & ~seen):
                seen[m] = True
                stack.append(m)
        confounded.append(tuple(names[fi[i]] for i in sorted(group)))
    return named


def _undetermined_message(
    bad_names, names, types, why_groups, hints, confounded, *, d, n_config, has_moments
):
    """The message naming the joints the data cannot determine, why, and what would determine them."""
    parts = []
    for why, js in why_groups.items():
        k = 0 if len(js) == 1 else 1
        parts.append(
            f"{_format_names(js)} {('is', 'are')[k]} not felt: " + " and ".join(_WHY[w][k] for w in why)
        )
    for g in confounded:
        if len(g) == 1:
            parts.append(f"{g[0]} is hardly felt: its column is nearly a combination of the others'")
        else:
            parts.append(
                f"{_format_names(g)} change the measured displacements only in a fixed combination "
                "(the data see their sum, weighted, not each one)"
            )
    todo = [_hint(key, js) for key, js in hints.items()]
    if confounded:
        todo.append(
            "add configurations" if n_config == 1 else "add configurations where their axes lie differently"
        )
        if not has_moments:
            todo.append("load cases with moments (a load point off the tool axis)")
        else:
            todo.append("load cases in other directions")
        if d == 3:
            todo.append("measure rotations (6-DOF poses)")
    one = len(bad_names) == 1
    links_too = any(types[names.index(s)] in LINK_KINDS for s in bad_names)
    what = (
        ("parameter" if one else "joint and link parameters") if links_too else ("joint" if one else "joints")
    )
    return (
        f"{what} {_format_names(bad_names)} cannot be determined from these "
        "configurations and loads: "
        + "; ".join(parts)
        + f". To determine {'it' if one else 'them'}: "
        + ", or ".join(dict.fromkeys(todo))
        + f"; or hold {'it' if one else 'them'} at a known compliance (fixed) and fit the others"
    )


def _hint(key: str, js: list[str]) -> str:
    """What to add (``key`` of :data:`_WHY`) so that the joints ``js`` are felt."""
    them = _format_names(js)
    axes = "its axis" if len(js) == 1 else "their axes"
    return {
        "moment": f"load cases with moments about the {'axis' if len(js) == 1 else 'axes'} of "
        f"{them} (a load point off {axes})",
        "force": f"load cases with forces along {axes} ({them})",
        "measure": f"measure rotations (6-DOF poses) or a point off {axes} ({them})",
        "where": f"load cases that act on {them} where {'its' if len(js) == 1 else 'their'} "
        "motion is measured",
        "bend": f"load cases that bend or twist the link{'' if len(js) == 1 else 's'} of {them} "
        "(forces across it, moments), measured beyond it",
    }[key]


def _check_links(
    links, M: int, joint_names: tuple[str, ...]
) -> tuple[tuple[str, ...], tuple[str, ...], np.ndarray]:
    """Names, kinds and bases (M, 6, 6, L) of the flexible links' parameters."""
    links = tuple(links or ())
    B = np.zeros((M, 6, 6, len(links)))
    names, kinds = [], []
    for i, lk in enumerate(links):
        if not isinstance(lk, LinkColumns):
            raise InputError(f"links: expected LinkColumns, got {type(lk).__name__}")
        b = as_float(lk.basis, f"links[{lk.name}].basis")
        if b.shape != (M, 6, 6):
            raise InputError(f"links[{lk.name}].basis: expected shape ({M}, 6, 6), got {b.shape}")
        check_finite(b, f"links[{lk.name}].basis", "compliances")
        if lk.kind not in LINK_KINDS:
            raise InputError(
                f"links[{lk.name}].kind: expected one of {', '.join(LINK_KINDS)}, got {lk.kind!r}"
            )
        if lk.name in joint_names or lk.name in names:
            raise InputError(
                f"links: {lk.name} is named twice (joints and links' parameters need distinct names)"
            )
        B[..., i] = b
        names.append(str(lk.name))
        kinds.append(lk.kind)
    return tuple(names), tuple(kinds), B


def _full_design(J: np.ndarray, W: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The joints' columns (:func:`_design`) then the links' ``B w``: shape (M, 6, n + L)."""
    A = _design(J, W)
    if B.shape[-1] == 0:
        return A
    return np.concatenate([A, np.einsum("mijl,mj->mil", B, W)], axis=2)


def _link_sensitivity(B: np.ndarray, W: np.ndarray, Linv: np.ndarray, d: int, ell: float) -> np.ndarray:
    """Relative sensitivity of each link parameter, in [0, 1]: its whitened column ``L^-1 S B w``
    against ``|L^-1| |D B D| |D^-1 w|`` (D = diag(1, 1, 1, ell, ell, ell)), over all rows."""
    if B.shape[-1] == 0:
        return np.zeros(0)
    Dv = np.array([1.0, 1.0, 1.0, ell, ell, ell])
    col = np.einsum("mab,mbl->mal", Linv, np.einsum("mijl,mj->mil", B, W)[:, :d, :])
    DBD = B * Dv[None, :, None, None] * Dv[None, None, :, None]
    nb = np.linalg.norm(np.moveaxis(DBD, 3, 1), ord=2, axis=(2, 3))  # (M, L)
    bound = np.linalg.norm(Linv, ord=2, axis=(1, 2))[:, None] * nb * np.linalg.norm(W / Dv, axis=1)[:, None]
    num = np.sqrt(np.sum(np.sum(col**2, axis=1), axis=0))
    den = np.sqrt(np.sum(bound**2, axis=0))
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def _prepare(jacobians, wrenches, d_or_displacements, cov, joint_names, fit, fixed, links=None):
    J = _check_jacobians(jacobians)
    M, _, n = J.shape
    W = _check_wrenches(wrenches, M)
    if isinstance(d_or_displacements, int):
        d, D = d_or_displacements, None
        if d not in (3, 6):
            raise InputError(f"measured: expected 3 (translations) or 6 (poses), got {d}")
    else:
        D = _check_displacements(d_or_displacements, M)
        d = D.shape[1]
    Linv = whitener(cov, M, d)
    names = _check_names(joint_names, n)
    lnames, kinds, B = _check_links(links, M, names)
    names = names + lnames
    idx, fixed_values = _check_fit_sets(names, fit, fixed)
    return J, W, D, d, Linv, names, idx, fixed_values, B, kinds


def _too_few_message(M: int, d: int, fitted: tuple[str, ...]) -> str:
    return (
        f"{M * d} observation(s) ({M} row(s) of {d} components) cannot determine {len(fitted)} joint "
        f"compliances ({_format_names(fitted)}); measure more"
    )


def _too_few(M: int, d: int, fitted: tuple[str, ...], types: tuple[str, ...]) -> JointIdentifiability:
    """The report of a design with fewer observations than joints: none determined."""
    p = len(fitted)
    return JointIdentifiability(
        names=fitted,
        joint_types=types,
        sensitivity=np.full(p, np.nan),
        condition=np.inf,
        singular_values=np.zeros(0),
        directions=np.zeros((0, p)),
        inflation=np.full(p, np.inf),
        weakest=np.zeros(p),
        not_felt={},
        confounded=(fitted,),
        message=_too_few_message(M, d, fitted),
    )


def _report(J, W, Linv, d, names, types, idx, config_keys, B=None) -> tuple[JointIdentifiability, np.ndarray]:
    """The identifiability report over the parameters ``idx`` (joints, then links' parameters
    with their bases ``B`` (M, 6, 6, L)) and the whitened design (M*d, n + L)."""
    M, _, n = J.shape
    B = np.zeros((M, 6, 6, 0)) if B is None else B
    A = _full_design(J, W, B)[:, :d, :]
    Aw = np.einsum("mab,mbj->maj", Linv, A).reshape(M * d, -1)
    ell = _lever_arm(J, types[:n])
    jidx, lidx = idx[idx < n], idx[idx >= n] - n
    sens, load_f, motion_f = _relative_sensitivity(J[:, :, jidx], W, Linv, d, ell)
    if lidx.size:
        ones = np.ones(lidx.size)
        sens = np.concatenate([sens, _link_sensitivity(B[..., lidx], W, Linv, d, ell)])
        load_f, motion_f = np.concatenate([load_f, ones]), np.concatenate([motion_f, ones])
    n_config = _group_poses(config_keys)[0].shape[0]
    force = np.linalg.norm(W[:, :3], axis=1)
    has_moments = bool(np.any(np.linalg.norm(W[:, 3:], axis=1) > 1e-6 * np.maximum(force, 1e-300)))
    if M * d < idx.size:
        return _too_few(M, d, tuple(names[j] for j in idx), tuple(types[j] for j in idx)), Aw
    rep = _identify(
        Aw[:, idx],
        tuple(names[j] for j in idx),
        tuple(types[j] for j in idx),
        sens,
        load_f,
        motion_f,
        d=d,
        n_config=n_config,
        has_moments=has_moments,
    )
    return rep, Aw


def joint_identifiability(
    jacobians,
    wrenches,
    cov=None,
    *,
    measured: int = 6,
    joint_names: Sequence[str] | None = None,
    fit: Sequence[str] | None = None,
    links: Sequence[LinkColumns] = (),
) -> JointIdentifiability:
    """Which joint compliances a set of configurations and loads can determine (no data needed).

    Plan an experiment with it before measuring: it never raises for an undetermined joint,
    but says so in ``message``. :func:`fit_joint_compliances` refuses a fit whose report
    has a message.

    Parameters
    ----------
    jacobians : array_like, shape (M, 6, n)
        Jacobian of the measured point at the configuration of each planned measurement.
    wrenches : array_like, shape (M, 6)
        Wrench (N, N*mm) at the measured point, base frame, of each measurement.
    cov : array_like, shape (M, d, d) or (M, d), optional
        Expected covariance (or standard deviations) of each measured displacement; unit
        weights when omitted.
    measured : {3, 6}
        3 for point translations, 6 for poses (ignored when ``cov`` says it by its shape).
    joint_names : sequence of str, optional
        Default ``k1`` ... ``kn``.
    fit : sequence of str, optional
        The joints (and links' parameters) to examine (default all).
    links : sequence of LinkColumns, optional
        Flexible links' parameters beside the joints (after them in ``names``).

    Returns
    -------
    JointIdentifiability
    """
    if cov is not None:
        shape = np.shape(cov)
        if len(shape) >= 2 and shape[1] in (3, 6):
            measured = int(shape[1])
    J, W, _, d, Linv, names, idx, _, B, kinds = _prepare(
        jacobians, wrenches, measured, cov, joint_names, fit, None, links
    )
    rep, _ = _report(J, W, Linv, d, names, _joint_types(J) + kinds, idx, J.reshape(J.shape[0], -1), B)
    return rep


# --------------------------------------------------------------------------- the fit


@dataclass(frozen=True)
class JointFit:
    """Joint compliances fitted to measured deflections (:func:`fit_joint_compliances`).

    Arrays are read-only. ``n`` joints, ``p`` fitted, ``M`` measured rows of ``d``
    components, ``G`` configurations, ``L`` load-case labels.

    Attributes
    ----------
    names : tuple of str
        All joints, in the Jacobians' column order.
    joint_types : tuple of str
        ``"revolute"`` or ``"prismatic"`` (from the Jacobians: a revolute column has a unit
        angular velocity).
    fitted : tuple of str
        The fitted joints, in joint order; the others were held at ``fixed``.
    compliance : ndarray, shape (n,)
        rad/(N*mm) (revolute) or mm/N (prismatic); the fixed value for joints not fitted.
    compliance_std : ndarray, shape (n,)
        Standard errors; NaN where not estimated (held fixed, or held at 0 by the bound).
    stiffness, stiffness_std : ndarray, shape (n,)
        ``1 / compliance`` (N*mm/rad or N/mm; ``inf`` for a zero compliance) and its standard
        error ``c_std / c^2`` (NaN where the compliance is 0 or not estimated).
    covariance : ndarray, shape (p, p)
        Covariance of the fitted compliances (NaN rows and columns for joints held at 0).
    correlation : ndarray, shape (p, p)
    residuals : ndarray, shape (M, d)
        Measured minus predicted displacement (mm, rad).
    normalized_residuals : ndarray, shape (M, d)
        Residuals whitened by the Cholesky factor of their covariance, ``L^-1 r`` (unit-free;
        about unit variance when the covariances are right). Equal to ``residuals`` without
        covariances.
    config_index : ndarray of int, shape (M,)
        The configuration of each row, 0 .. G-1 in order of first appearance.
    configs : ndarray, shape (G,)
        The configuration ids given in ``config_index`` (or 0 .. G-1 when grouped by
        Jacobian).
    residual_rms_per_config : ndarray, shape (G, 2)
        RMS residual per component of each configuration: translations (mm), rotations (rad;
        NaN when only translations are measured).
    normalized_rms_per_config : ndarray, shape (G,)
        RMS of the normalised residuals of each configuration (about 1 when it fits).
    labels : tuple of str or None
        Load-case label of each row, as given.
    label_names : tuple of str
        The distinct labels in order of first appearance (empty without labels).
    residual_rms_per_label : ndarray, shape (L, 2)
    normalized_rms_per_label : ndarray, shape (L,)
    chi2 : float
        Sum of squared normalised residuals.
    dof : int
        Observations (M * d) minus free fitted compliances.
    reduced_chi2 : float
        ``chi2 / dof`` (NaN when dof = 0).
    p_value : float
        ``P(chi2_dof > chi2)``: small when the model or the covariances do not explain the
        data (NaN without covariances or without dof).
    condition : float
        Condition number of the column-scaled whitened design (``identifiability``).
    sensitivity : ndarray, shape (p,)
        Relative sensitivity of each fitted joint (``identifiability``).
    identifiability : JointIdentifiability
    active : tuple of str
        Fitted joints held at 0 by the non-negativity bound.
    notes : tuple of str
        What may make the result wrong (a misfit no extra noise explains, no residual degree of
        freedom, a joint not felt): a campaign counts them as failures.
    absolute_sigma : bool
    extra_translation_std : float, mm
        With ``extra_noise``: the standard deviation per axis of the translation noise added to
        every displacement's covariance so that the reduced chi-square is 1 (0 when none was
        needed or asked for).
    info : tuple of str
        What the fit did that a reader should know but that is accounted for (the extra noise
        added, in words): printed, not a failure.
    """

    names: tuple[str, ...]
    joint_types: tuple[str, ...]
    fitted: tuple[str, ...]
    compliance: np.ndarray
    compliance_std: np.ndarray
    stiffness: np.ndarray
    stiffness_std: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    residuals: np.ndarray
    normalized_residuals: np.ndarray
    config_index: np.ndarray
    configs: np.ndarray
    residual_rms_per_config: np.ndarray
    normalized_rms_per_config: np.ndarray
    labels: tuple[str, ...] | None
    label_names: tuple[str, ...]
    residual_rms_per_label: np.ndarray
    normalized_rms_per_label: np.ndarray
    chi2: float
    dof: int
    reduced_chi2: float
    p_value: float
    condition: float
    sensitivity: np.ndarray
    identifiability: JointIdentifiability
    active: tuple[str, ...]
    absolute_sigma: bool
    notes: tuple[str, ...] = field(default_factory=tuple)
    extra_translation_std: float = 0.0
    info: tuple[str, ...] = field(default_factory=tuple)

    @property
    def values(self) -> dict[str, float]:
        """Stiffness by joint name (N*mm/rad or N/mm)."""
        return {s: float(k) for s, k in zip(self.names, self.stiffness, strict=True)}

    def predict(self, jacobians, wrenches, links: Sequence[LinkColumns] = ()) -> np.ndarray:
        """Deflection (M, 6) (mm, rad) with the fitted compliances (:func:`joint_deflections`);
        with flexible links, their bases at the same rows (the fit's ``links``)."""
        n = len(self.names) - len(links)
        d = joint_deflections(jacobians, wrenches, self.compliance[:n])
        W = np.broadcast_to(as_float(wrenches, "wrenches"), d.shape)
        for lk, c in zip(links, self.compliance[n:], strict=True):
            d = d + c * np.einsum("mij,mj->mi", as_float(lk.basis, "basis"), W)
        return d

    def to_dict(self) -> dict:
        """Plain JSON-able summary (NaN and inf become None)."""
        rows = []
        for j, s in enumerate(self.names):
            cu, ku = _UNITS[self.joint_types[j]]
            rows.append(
                (
                    s,
                    {
                        "type": self.joint_types[j],
                        "fitted": s in self.fitted,
                        "active": s in self.active,
                        "compliance": float(self.compliance[j]),
                        "compliance_std": float(self.compliance_std[j]),
                        "compliance_unit": cu,
                        "stiffness": float(self.stiffness[j]),
                        "stiffness_std": float(self.stiffness_std[j]),
                        "stiffness_unit": ku,
                    },
                )
            )
        r = self.residuals
        return to_jsonable(
            {
                "joints": dict(rows),
                "fitted": list(self.fitted),
                "correlation": self.correlation,
                "n_rows": int(r.shape[0]),
                "measured": int(r.shape[1]),
                "dof": self.dof,
                "chi2": self.chi2,
                "reduced_chi2": self.reduced_chi2,
                "p_value": self.p_value,
                "condition": self.condition,
                "sensitivity": dict(zip(self.fitted, self.sensitivity.tolist(), strict=True)),
                "identifiability": self.identifiability.to_dict(),
                "absolute_sigma": self.absolute_sigma,
                "residual_rms_mm": float(np.sqrt(np.mean(r[:, :3] ** 2))),
                "residual_rms_rad": float(np.sqrt(np.mean(r[:, 3:] ** 2))) if r.shape[1] == 6 else None,
                "configs": [
                    {"config": c, "rms_mm": t[0], "rms_rad": t[1], "normalized_rms": z}
                    for c, t, z in zip(
                        self.configs.tolist(),
                        self.residual_rms_per_config.tolist(),
                        self.normalized_rms_per_config.tolist(),
                        strict=True,
                    )
                ],
                "load_cases": [
                    {"label": c, "rms_mm": t[0], "rms_rad": t[1], "normalized_rms": z}
                    for c, t, z in zip(
                        self.label_names,
                        self.residual_rms_per_label.tolist(),
                        self.normalized_rms_per_label.tolist(),
                        strict=True,
                    )
                ],
                "active": list(self.active),
                "notes": list(self.notes),
                "info": list(self.info),
                "extra_translation_std_mm": self.extra_translation_std,
            }
        )


def _rms_table(index: np.ndarray, G: int, r: np.ndarray, rn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per group: RMS per component of translations (mm) and rotations (rad), normalised RMS."""
    count = np.bincount(index, minlength=G).astype(float)
    d = r.shape[1]
    tr = np.sqrt(np.bincount(index, np.sum(r[:, :3] ** 2, axis=1), G) / (3 * count))
    if d == 6:
        rot = np.sqrt(np.bincount(index, np.sum(r[:, 3:] ** 2, axis=1), G) / (3 * count))
    else:
        rot = np.full(G, np.nan)
    nrm = np.sqrt(np.bincount(index, np.sum(rn**2, axis=1), G) / (d * count))
    return np.stack([tr, rot], axis=1), nrm


def _solve(An: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least squares of a column-scaled system: solution and (An^T An)^-1, by the SVD."""
    U, s, Vt = np.linalg.svd(An, full_matrices=False)
    x = Vt.T @ ((U.T @ y) / s)
    cov = (Vt.T / s**2) @ Vt
    return x, cov


#: How far the extra translation variance of ``extra_noise`` is searched, in mean squared
#: translation residuals: a million (an extra noise 1000 times the residuals' RMS), where the
#: translations no longer weigh in the chi-square and what is left of it is the rotations'.
EXTRA_NOISE_CAP = 1e6


# Longer than ~80 lines for its documentation: the parameters, raises and warnings take ~80 lines;
# the body (~15 lines) hands over to _fit_once or _fit_with_extra_noise.
def fit_joint_compliances(
    jacobians,
    wrenches,
    displacements,
    cov=None,
    *,
    joint_names: Sequence[str] | None = None,
    fit: Sequence[str] | None = None,
    fixed: Mapping[str, float] | None = None,
    nonnegative: bool = True,
    absolute_sigma: bool = False,
    config_index=None,
    labels: Sequence[str] | None = None,
    extra_noise: bool = False,
    links: Sequence[LinkColumns] = (),
) -> JointFit:
    """Joint compliances from measured deflections, by weighted linear least squares.

    Row m: at a configuration with Jacobian ``jacobians[m]`` the wrench ``wrenches[m]``
    moves the measured point by ``displacements[m]``, modelled as ``J C J^T w`` (module
    docstring).

    Parameters
    ----------
    jacobians : array_like, shape (M, 6, n)
        Jacobian of the measured point at each row's configuration, base frame: rows vx, vy,
        vz (mm per joint unit) then wx, wy, wz (rad per joint unit).
    wrenches : array_like, shape (M, 6)
        Force (N) and moment (N*mm) at the measured point, base frame.
    displacements : array_like, shape (M, 3) or (M, 6)
        Measured deflection: translations (mm), and for d = 6 the rotation vector (rad).
    cov : array_like, shape (M, d, d) or (M, d), optional
        Covariance of each displacement (mm^2, mm*rad, rad^2; full, symmetric positive
        definite), or its standard deviations. Unit weights when omitted (then
        ``absolute_sigma`` must be False, and there is no p-value).
    joint_names : sequence of str, optional
        The n joints' names (default ``k1`` ... ``kn``), used in messages and results.
    fit : sequence of str, optional
        The joints to fit; default every joint not in ``fixed``.
    fixed : mapping of str to float, optional
        Compliances of the joints not fitted (rad/(N*mm) or mm/N; 0 for a rigid joint);
        their deflection is subtracted from the data.
    nonnegative : bool
        Keep compliances >= 0 (default); a joint the bound holds at 0 is said in ``active``
        and ``notes``.
    absolute_sigma : bool
        Take ``cov`` as exact; otherwise scale the covariance by the reduced chi-square.
    config_index : array_like of int, shape (M,), optional
        The configuration of each row, for the per-configuration residuals; default: rows
        with identical Jacobians form a configuration.
    labels : sequence of str, shape (M,), optional
        The load case of each row, for the per-load-case residuals.
    extra_noise : bool
        The given covariances may leave out a noise the measurements have (a robot's jitter
        between images, vibration): when the fit's reduced chi-square is above 1, estimate the
        standard deviation s of an isotropic translation noise such that with ``cov + s^2 I``
        on the translations the reduced chi-square is 1, and fit with that covariance (a
        variance component: the weights become right, the chi-square test then says nothing
        more). ``extra_translation_std`` and a note give s. Needs ``cov``.
    links : sequence of LinkColumns, optional
        Flexible links' parameters fitted (or held in ``fixed``, by their "compliance" 1/p)
        beside the joints: they follow the joints in ``names``; ``stiffness`` gives p (MPa, or
        the stiffness factor) and its standard error.

    Returns
    -------
    JointFit

    Raises
    ------
    InputError
        Wrong shapes, non-finite values, a covariance that is not symmetric positive
        definite, unknown names in ``fit`` or ``fixed``, a joint neither fitted nor fixed:
        the message names the argument and the row.
    DesignError
        Fewer observations than fitted joints, or joints the configurations and loads cannot
        determine (named, with what would determine them; :func:`joint_identifiability`).

    Warns
    -----
    IllConditionedWarning
        When the design determines every joint but its condition number exceeds
        ``CONDITION_WARN``.
    """
    kw = dict(
        joint_names=joint_names,
        fit=fit,
        fixed=fixed,
        nonnegative=nonnegative,
        absolute_sigma=absolute_sigma,
        config_index=config_index,
        labels=labels,
        links=links,
    )
    if not extra_noise:
        return _fit_once(jacobians, wrenches, displacements, cov, **kw)
    return _fit_with_extra_noise(jacobians, wrenches, displacements, cov, kw)


def _fit_with_extra_noise(jacobians, wrenches, displacements, cov, kw: dict) -> JointFit:
    """:func:`fit_joint_compliances` with ``extra_noise``: the translation noise s that makes the
    reduced chi-square 1, by bisection on s^2 (a note says when none does)."""
    absolute_sigma = kw["absolute_sigma"]
    if cov is None:
        raise InputError("extra_noise: True needs cov (the covariances the extra noise is added to)")
    C = as_float(cov, "cov")
    D = as_float(displacements, "displacements")
    if C.ndim == 2:
        C = np.einsum("mi,ij->mij", C**2, np.eye(C.shape[1]))
    d = D.shape[1] if D.ndim == 2 else 0
    P = np.diag([1.0, 1.0, 1.0, 0.0, 0.0, 0.0][:d])

    def fit_with(s2: float, quiet: bool = True) -> JointFit:
        if not quiet:
            return _fit_once(jacobians, wrenches, displacements, C + s2 * P, **kw)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return _fit_once(jacobians, wrenches, displacements, C + s2 * P, **kw)

    f0 = fit_with(0.0)
    if not (f0.dof > 0 and f0.reduced_chi2 > 1.0):
        return fit_with(0.0, quiet=False)
    hi = max(float(np.mean(f0.residuals[:, :3] ** 2)), 1e-300)
    cap = hi * EXTRA_NOISE_CAP
    while (chi2_hi := fit_with(hi).reduced_chi2) > 1.0:
        if hi >= cap:  # the translations weigh nothing any more: the misfit is in the rotations
            f = fit_with(0.0, quiet=False)
            note = (
                f"the displacements scatter more than their covariances say (chi2/dof = "
                f"{f0.reduced_chi2:.3g}), and no extra translation noise explains it: with "
                f"{1e3 * np.sqrt(hi):.3g} um of it per axis, chi2/dof is still {chi2_hi:.3g}, the "
                "rotations' misfit (their covariances too small, or the model wrong in rotation); "
                "the given covariances were kept"
                + ("" if absolute_sigma else ", the standard errors scaled by the scatter")
            )
            return replace(f, notes=(*f.notes, note))
        hi = min(4.0 * hi, cap)
    lo = 0.0
    for _ in range(60):  # bisection on s^2: the reduced chi-square falls as s grows
        mid = 0.5 * (lo + hi)
        if fit_with(mid).reduced_chi2 > 1.0:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-6 * hi:
            break
    s2 = 0.5 * (lo + hi)
    f = fit_with(s2, quiet=False)
    note = (
        f"the displacements scatter more than their covariances say (chi2/dof = {f0.reduced_chi2:.3g} "
        f"with them alone): {1e3 * np.sqrt(s2):.3g} um per axis of extra translation noise (robot "
        "jitter, vibration) was added to every displacement's covariance to make it 1"
    )
    return replace(f, extra_translation_std=float(np.sqrt(s2)), info=(note,))


def _fit_once(
    jacobians,
    wrenches,
    displacements,
    cov,
    *,
    joint_names,
    fit,
    fixed,
    nonnegative,
    absolute_sigma,
    config_index,
    labels,
    links=(),
) -> JointFit:
    """:func:`fit_joint_compliances` with the given covariances."""
    J, W, D, d, Linv, names, idx, fixed_values, B, kinds = _prepare(
        jacobians, wrenches, displacements, cov, joint_names, fit, fixed, links
    )
    M = J.shape[0]
    n = len(names)
    if cov is None and absolute_sigma:
        raise InputError("absolute_sigma: True needs cov (the covariances to take as exact)")
    configs, cidx = _config_groups(J, config_index)
    label_tuple, label_names, lidx = _label_groups(labels, M)
    types = _joint_types(J) + kinds
    fitted = tuple(names[j] for j in idx)
    p = idx.size
    n_obs = M * d
    if n_obs < p:
        raise DesignError(_too_few_message(M, d, fitted))
    rep, Aw = _report(J, W, Linv, d, names, types, idx, cidx, B)
    if not rep.determined:
        raise DesignError(rep.message)
    if rep.condition > CONDITION_WARN:
        _warn_ill_conditioned(rep, fitted)

    c_all = np.where(np.isnan(fixed_values), 0.0, fixed_values)
    full = _full_design(J, W, B)
    y, yw = _fixed_removed(D, full, c_all, np.setdiff1d(np.arange(n), idx), Linv)
    A = Aw[:, idx]
    norms = np.linalg.norm(A, axis=0)
    An = A / norms

    s = _least_squares(An, yw, norms, nonnegative, absolute_sigma, n_obs, [(names[j], types[j]) for j in idx])
    chi2, dof, free, notes = s.chi2, s.dof, s.free, s.notes
    red = chi2 / dof if dof > 0 else float("nan")
    values = _compliance_fields(c_all, idx, s.x / norms, s.std)
    by_label = None if label_tuple is None else (lidx, len(label_names))
    tables = _residual_fields(D, full, values["compliance"], d, Linv, (cidx, configs.shape[0]), by_label)
    p_value = chi2_sf(chi2, dof) if cov is not None and dof > 0 else float("nan")
    notes.extend(_misfit_notes(fitted, cov, dof, red, p_value, tables["residuals"], y))
    stiff = values["stiffness"][idx], values["stiffness_std"][idx]
    notes.extend(separation_notes(fitted, *stiff, s.correlation))
    return _frozen_fit(
        names=names,
        joint_types=types,
        fitted=fitted,
        **values,
        covariance=s.covariance,
        correlation=s.correlation,
        config_index=cidx,
        configs=configs,
        labels=label_tuple,
        label_names=label_names,
        **tables,
        chi2=chi2,
        dof=dof,
        reduced_chi2=red,
        p_value=p_value,
        condition=rep.condition,
        sensitivity=rep.sensitivity,
        identifiability=rep,
        active=tuple(fitted[k] for k in np.flatnonzero(~free)),
        absolute_sigma=bool(absolute_sigma),
        notes=tuple(notes),
    )


def _fixed_removed(D, full, c_all, known, Linv) -> tuple[np.ndarray, np.ndarray]:
    """The displacements less the fixed (``known``) joints' and links' deflection, y (M, d), and
    y whitened and stacked, yw (M d,)."""
    M, d = D.shape[0], Linv.shape[1]
    y = D - np.einsum(
        "mkj,mj->mk", full[:, :d, :][:, :, known], np.broadcast_to(c_all[known], (M, known.size))
    )
    return y, np.einsum("mab,mb->ma", Linv, y).reshape(-1)


@dataclass
class _Solution:
    """The weighted least-squares solution (:func:`_least_squares`)."""

    x: np.ndarray  # the scaled compliances (divided by the column norms)
    covariance: np.ndarray  # the compliances' covariance (scaled by chi2/dof unless absolute_sigma)
    correlation: np.ndarray
    std: np.ndarray
    chi2: float
    dof: int
    free: np.ndarray  # bool: not held at 0 by the bound
    notes: list[str]


def _least_squares(An, yw, norms, nonnegative, absolute_sigma, n_obs, joints) -> _Solution:
    """Solve the whitened, column-scaled system ``An x = yw`` (nonnegative: joints that come out
    negative held at 0); ``joints``: the fitted joints' (name, type), for the notes."""
    p = An.shape[1]
    x, cov_s = _solve(An, yw)
    notes: list[str] = []
    free = np.ones(p, dtype=bool)
    if nonnegative and np.any(x < 0):
        x, cov_s, free, held = _hold_negative_at_zero(An, yw, x, cov_s, norms, absolute_sigma, n_obs)
        notes.extend(_held_note(*joints[k], c, v) for k, c, v in held)
    rw = yw - An @ x
    chi2 = float(rw @ rw)
    dof = n_obs - int(np.count_nonzero(free))
    cov_s = _scaled(cov_s, chi2, dof, absolute_sigma)
    if not absolute_sigma and dof == 0:
        notes.append("no residual degree of freedom: standard errors unknown (give cov and absolute_sigma)")
    cov_c = cov_s / np.outer(norms, norms)
    std_fit = np.sqrt(np.diag(cov_c))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov_c / np.outer(std_fit, std_fit)
    return _Solution(x, cov_c, corr, std_fit, chi2, dof, free, notes)


def _compliance_fields(c_all, idx, c_fit, std_fit) -> dict[str, np.ndarray]:
    """Every joint's compliance (fitted or fixed) and stiffness, with standard errors (nan: not fitted)."""
    n = c_all.size
    compliance = c_all.copy()
    compliance[idx] = c_fit
    compliance_std = np.full(n, np.nan)
    compliance_std[idx] = std_fit
    with np.errstate(divide="ignore", invalid="ignore"):
        stiffness = np.where(compliance > 0, 1.0 / np.where(compliance > 0, compliance, 1.0), np.inf)
        stiffness_std = np.where(compliance > 0, compliance_std / compliance**2, np.nan)
    return dict(
        compliance=compliance, compliance_std=compliance_std, stiffness=stiffness, stiffness_std=stiffness_std
    )


def _residual_fields(D, full, compliance, d, Linv, by_config, by_label) -> dict[str, np.ndarray]:
    """The residuals (plain and whitened) and their RMS per configuration and per load case
    (``by_config``, ``by_label``: each row's index and the count; ``by_label`` None without labels)."""
    resid = (D - np.einsum("mkj,j->mk", full, compliance)[:, :d]).copy()
    nres = np.einsum("mab,mb->ma", Linv, resid)
    rms_c, nrms_c = _rms_table(*by_config, resid, nres)
    if by_label is None:
        rms_l, nrms_l = np.zeros((0, 2)), np.zeros(0)
    else:
        rms_l, nrms_l = _rms_table(*by_label, resid, nres)
    return dict(
        residuals=resid,
        normalized_residuals=nres,
        residual_rms_per_config=rms_c,
        normalized_rms_per_config=nrms_c,
        residual_rms_per_label=rms_l,
        normalized_rms_per_label=nrms_l,
    )


def _config_groups(J: np.ndarray, config_index) -> tuple[np.ndarray, np.ndarray]:
    """The configurations (ids) and each row's index into them: ``config_index``, or rows with
    identical Jacobians."""
    M = J.shape[0]
    if config_index is None:
        configs, cidx = _group_poses(J.reshape(M, -1))
        return np.arange(configs.shape[0]), cidx
    ci = np.asarray(config_index)
    if ci.shape != (M,) or not np.issubdtype(ci.dtype, np.integer):
        raise InputError(
            f"config_index: expected {M} integers (one per row), got shape {ci.shape}, {ci.dtype}"
        )
    return _group_poses(ci)


def _label_groups(labels, M: int) -> tuple[tuple[str, ...] | None, tuple[str, ...], np.ndarray]:
    """The rows' load-case labels (None without), the distinct labels and each row's index into them."""
    if labels is None:
        return None, (), np.zeros(M, dtype=int)
    if isinstance(labels, str) or len(labels) != M:
        got = 1 if isinstance(labels, str) else len(labels)
        raise InputError(f"labels: expected {M} load-case labels (one per row), got {got}")
    label_tuple = tuple(str(s) for s in labels)
    uniq, lidx = _group_poses(np.array(label_tuple))
    return label_tuple, tuple(str(s) for s in uniq), lidx


def _warn_ill_conditioned(rep: JointIdentifiability, fitted: tuple[str, ...]) -> None:
    """An :class:`IllConditionedWarning` naming the weakest combination of the fitted joints."""
    weak = rep.directions[-1] * np.sign(rep.directions[-1][np.argmax(np.abs(rep.directions[-1]))])
    combo = " ".join(
        f"{'-' if w < 0 else '+'} {abs(w):.2g} {s}" for w, s in zip(weak, fitted, strict=True) if abs(w) > 0.1
    ).lstrip("+ ")
    warnings.warn(
        f"joint-compliance fit of {_format_names(fitted)}: condition number {rep.condition:.3g} > "
        f"{CONDITION_WARN:g}; the estimates are strongly correlated and sensitive to noise (the "
        f"weakest combination, in scaled compliances: {combo})",
        IllConditionedWarning,
        stacklevel=3,
    )


def _scaled(cov_s: np.ndarray, chi2: float, dof: int, absolute_sigma: bool) -> np.ndarray:
    """The scaled parameters' covariance: as given (``absolute_sigma``), else times chi2/dof."""
    if absolute_sigma:
        return cov_s
    if dof > 0:
        return cov_s * (chi2 / dof)
    return np.full_like(cov_s, np.nan)


def _hold_negative_at_zero(An, yw, x, cov_s, norms, absolute_sigma, n_obs):
    """The nonnegative solution (bvls's free set, solved exactly): the scaled compliances, their
    covariance, which are free, and for each held at 0 (its index in the fitted ones) its
    unconstrained estimate and variance."""
    p = x.size
    r0 = yw - An @ x
    chi0 = float(r0 @ r0)
    cov_unc = _scaled(cov_s, chi0, n_obs - p, absolute_sigma) / np.outer(norms, norms)
    c_unc = x / norms
    from scipy import optimize  # on first use: 0.15 s that most commands never need

    res = optimize.lsq_linear(An, yw, bounds=(0.0, np.inf), method="bvls", tol=1e-14)
    free = res.active_mask == 0
    while True:
        # The exact solution on bvls's free set (a joint that still comes out negative
        # by rounding joins the bound).
        x = np.zeros(p)
        cov_s = np.full((p, p), np.nan)
        if not np.any(free):
            break
        xf, cf = _solve(An[:, free], yw)
        if np.all(xf >= 0):
            x[free] = xf
            cov_s[np.ix_(free, free)] = cf
            break
        free[np.flatnonzero(free)[int(np.argmin(xf))]] = False
    held = [(k, c_unc[k], cov_unc[k, k]) for k in np.flatnonzero(~free)]
    return x, cov_s, free, held


def _held_note(name: str, joint_type: str, c_unc: float, var_unc: float) -> str:
    unit = _UNITS[joint_type][0]
    return (
        f"compliance of {name} held at 0 (the unconstrained estimate was {c_unc:.3g} {unit} "
        f"± {np.sqrt(var_unc):.2g}): the data favour a rigid joint; its standard error is not "
        "given and the covariance covers the other joints"
    )


def _misfit_notes(fitted, cov, dof: int, red: float, p_value: float, resid, y) -> list[str]:
    """A note when the model does not explain the measurements: a chi-square test with ``cov``,
    else the residuals' RMS relative to the measurements'."""
    hint = (
        f"the model with joint compliances {_format_names(fitted)} fitted does not explain the measurements"
    )
    if cov is not None and dof > 0 and p_value < MISFIT_P:
        return [
            f"{hint} (chi2/dof = {red:.3g} over {dof} dof, p = {p_value:.2g}): the uncertainties are "
            "underestimated, or the model misses something (a link's compliance, backlash, a wrong "
            "Jacobian or load, a held joint's compliance)"
        ]
    if cov is None and dof > 0:
        rel = float(np.sqrt(np.mean(resid**2)) / max(float(np.sqrt(np.mean(y**2))), 1e-300))
        if rel > MISFIT_RELATIVE:
            return [f"{hint} (residual RMS {100 * rel:.3g} % of the measurements' RMS)"]
    return []


def _frozen_fit(**fields) -> JointFit:
    """The :class:`JointFit` of these fields, its arrays (and its identifiability's) read-only."""
    rep = fields["identifiability"]
    arrays = [fields[k] for k in _FIT_ARRAYS]
    arrays += [rep.singular_values, rep.directions, rep.inflation, rep.weakest]
    for a in arrays:
        a.setflags(write=False)
    return JointFit(**fields)


#: The :class:`JointFit` fields that are arrays (read-only).
_FIT_ARRAYS = (
    "compliance",
    "compliance_std",
    "stiffness",
    "stiffness_std",
    "covariance",
    "correlation",
    "residuals",
    "normalized_residuals",
    "config_index",
    "configs",
    "residual_rms_per_config",
    "normalized_rms_per_config",
    "residual_rms_per_label",
    "normalized_rms_per_label",
    "sensitivity",
)
