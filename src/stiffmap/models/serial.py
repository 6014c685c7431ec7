"""Serial robots from URDF: joint springs seen at the measured point (the virtual-joint model).

A serial arm is a :class:`~stiffmap.models.chain.Chain` (a URDF, a tip frame and an
offset, in mm) whose joints are springs: joint k turns (or slides) by
``dq_k = tau_k / k_k`` under the generalised force ``tau_k`` it carries. Links are rigid
(link compliances are not modelled yet; a stiff link is as a very stiff joint). With J
the 6 x n Jacobian of the measured point (:meth:`Chain.jacobian`: rows vx, vy, vz in mm
per joint unit, then wx, wy, wz in rad per joint unit, base frame), a wrench
``w = (F, M)`` at the point (N, N*mm, base frame) loads the joints with ``tau = J^T w``
and moves the point by

    d = J K_theta^-1 J^T w = C6 w,      d = (u mm, rotation vector rad), base frame,

the compliance ``C6`` (6 x 6: mm/N, mm/(N*mm) = 1/N and rad/(N*mm) blocks). Where J is
square and invertible, ``K6 = C6^-1 = J^-T K_theta J^-1`` (the issue's formula). The
stiffness a pure force at the point sees -- what the vision path measures, the ``K`` of
every :class:`~stiffmap.models.base.Mechanism` -- is ``K = (C6[:3, :3])^-1`` (N/mm): the
point is free to turn, so K is *not* the translational block of K6.

Units (``docs/conventions.md``): joint stiffnesses ``k_theta`` in N*mm/rad for revolute
joints and N/mm for prismatic ones (``inf`` for a rigid joint), joint coordinates rad
or mm, positions mm.

Singularities. The Jacobian is made dimensionless with a characteristic length L
(:attr:`SerialRobot.length`, default: the largest distance from the measured point to a
revolute joint's axis at ``q_seed``, about the arm's reach): rotation rows times L,
prismatic columns times L (a rad counts as L mm). Two measures in [0, 1]:

- *joint*: the inverse condition number ``s_min / s_max`` of that scaled 6 x n Jacobian
  (its min(6, n) singular values): 0 where joints lose independence, e.g. a wrist
  singularity (joints 4 and 6 of an arm aligned);
- *translation*: the same of its three translational rows over the compliant joints
  (finite k): 0 where the joints cannot move the point along some direction (arm
  stretched, or a planar arm along its normal), where K does not exist.

A configuration with either below ``singular_tol`` is flagged ``"singular: ..."``, the
reason naming the joints (from the null space of J) or the direction lost;
``ModelMap.conditioning`` is the smaller of the two.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from typing import ClassVar

import numpy as np

from ..errors import InputError
from .base import (
    SINGULAR_TOL,
    IKSolution,
    ModelMap,
    as_points,
    check_positive,
    model_map,
    static_error_of,
    stiffness_of,
)
from .chain import Chain
from .joint_fit import LinkColumns
from .links import LinkSpring, resolve_axis, spring_jacobians

__all__ = ["SerialRobot", "MATCH_TOL_MM", "RIGID_RATIO"]

#: A point within this distance (mm) of a configuration's measured point takes that
#: configuration. stiffmap's CSV files write positions with 6 significant digits (up to
#: 5 micrometres off at 1 m), so a position read back from one still finds its configuration.
MATCH_TOL_MM = 0.01

#: A compliance whose smallest principal value is below this fraction of its largest is not
#: inverted: the joint springs leave the point (almost) rigid along a direction.
RIGID_RATIO = 1e-12

#: Above this many remembered inverse-kinematics solutions the memo is cleared.
_MEMO_MAX = 100_000


def _compliances(J: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``C6 = J diag(c) J^T`` per configuration, exactly symmetric. J (M, 6, n) -> (M, 6, 6)."""
    C = np.einsum("mij,j,mkj->mik", J, c, J)
    return 0.5 * (C + np.swapaxes(C, 1, 2))


def _inverse_condition(A: np.ndarray, k: int) -> np.ndarray:
    """``s_k / s_1`` of each matrix of A (M, r, c) (0 when it has fewer than k singular values)."""
    if A.shape[0] == 0:
        return np.zeros(0)
    if min(A.shape[1:]) < k:
        return np.zeros(A.shape[0])
    s = np.linalg.svd(A, compute_uv=False)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(s[:, 0] > 0, s[:, k - 1] / np.where(s[:, 0] > 0, s[:, 0], 1.0), 0.0)


def _check_rigid(C: np.ndarray, index: np.ndarray, reasons: list[str]) -> np.ndarray:
    """Compliances C (M, d, d) that can be inverted; the others get a reason (at ``index``).

    A compliance whose smallest principal value is below :data:`RIGID_RATIO` times its
    largest leaves the point (almost) rigid along a direction: far stiffer joints than the
    others (a fit wandering to k = 1e300), not a stiffness to invert.
    """
    w, V = np.linalg.eigh(C)
    ok = w[:, 0] > RIGID_RATIO * w[:, -1]
    for a in np.flatnonzero(~ok):
        d = V[a][:, 0]
        along = _direction(d[:3]) + (
            " (with rotation)" if d.size > 3 and np.linalg.norm(d[3:]) > 1e-6 else ""
        )
        reasons[int(index[a])] = (
            f"singular: the joint springs leave the point almost rigid along {along} (principal "
            f"compliances {w[a, 0]:.2g} to {w[a, -1]:.2g}: ratio below {RIGID_RATIO:g})"
        )
    return ok


def _resolved_links(chain: Chain, links) -> tuple[LinkSpring, ...]:
    """Flexible links checked against the chain, each spring's origin and beam axis set."""
    out: list[LinkSpring] = []
    seen: dict[str, str] = {}
    for lk in links or ():
        if not isinstance(lk, LinkSpring):
            raise TypeError(f"links must be LinkSpring objects, got {type(lk).__name__}")
        where = lk.where or f"link {lk.link!r}"
        if lk.link not in chain.link_names:
            raise InputError(
                f"{where}: link {lk.link!r} is not on the chain from {chain.base_frame!r} to "
                f"{chain.tip_frame!r} of {chain.source}: it does not carry the measured point "
                f"(the chain's links: {', '.join(chain.link_names)})"
            )
        if lk.name in seen:
            raise InputError(f"{where}: name {lk.name!r} is already used by {seen[lk.name]}")
        seen[lk.name] = where.rsplit(": ", 1)[-1]  # the table, its file said once
        if lk.origin_mm is None:
            lk = replace(lk, origin_mm=chain.link_end(lk.link))
        out.append(resolve_axis(lk, lk.origin_mm))
    return tuple(out)


def _names(names: Sequence[str]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _direction(u: np.ndarray) -> str:
    u = u / np.linalg.norm(u)
    k = int(np.argmax(np.abs(u)))
    u = u if u[k] > 0 else -u
    return "(" + ", ".join(f"{v + 0.0:.3g}" for v in u) + ")"


@dataclass(frozen=True, eq=False)
class SerialRobot:
    """A serial robot whose joints are springs: stiffness of its measured point (Mechanism "urdf").

    Build it with :meth:`from_urdf` (or from a :class:`Chain`). Implements the
    :class:`~stiffmap.models.base.Mechanism` protocol (``dim`` 3): positions of the
    measured point (mm, base frame) in, K (N/mm) out; a position is taken to the joint
    configuration that puts the point there (:meth:`configurations_for`). The joint-space
    API takes configurations directly: :meth:`compliance6`, :meth:`stiffness6`,
    :meth:`stiffness3`, :meth:`deflection`, :meth:`evaluate_configurations`.

    Attributes
    ----------
    chain : Chain
        The kinematics (mm), from the base to the measured point.
    k_theta : tuple of float, length n + m
        Joint stiffnesses in the chain's joint order: N*mm/rad (revolute), N/mm
        (prismatic); positive, ``inf`` for a rigid joint. A scalar is taken for every joint.
        Then one per mimic joint of the chain (:attr:`Chain.mimics`, m of them): a spring of
        its own, rigid (``inf``, the default when only n values are given) unless given.
    links : tuple of LinkSpring
        Flexible links (:mod:`~stiffmap.models.links`): each adds ``J_s C_s J_s^T`` to the
        compliance; their parameters (``E_<name>``, ``G_<name>``, ``f_<name>``) follow the
        joints' in :meth:`params`.
    configurations : ndarray, shape (m, n), optional
        Given joint configurations (rad or mm); their measured points are the positions
        they stand for.
    tool_rotation : ndarray, shape (3, 3), optional
        The tip frame's orientation (tip to base) held by inverse kinematics for a position
        that is not a configuration's. Default: the orientation of the configuration it
        starts from (the nearest one; the same for all when the configurations share one
        orientation, the usual map), else the orientation at ``q_seed``.
    q_seed : ndarray, shape (n,), optional
        Start of inverse kinematics when there are no configurations (default zeros,
        clipped into the joint limits); with configurations, the nearest one's is used.
    singular_tol : float
        Threshold of the singularity measures (module docstring).
    match_tol_mm : float
        A point this close (mm) to a configuration's measured point takes that
        configuration (default :data:`MATCH_TOL_MM`).
    length_mm : float, optional
        The characteristic length L of the singularity measures (default: the largest
        distance from the measured point to a revolute joint's axis at ``q_seed``).
    load_offset_mm : array_like, shape (3,), mm, optional
        Where the forces of the maps act, from the measured point (base axes). None (default):
        at the point, and the maps' K is ``(C6[:3, :3])^-1``. Given r: a force F there also
        applies r x F, the point moves by ``(C_tt + C_tr [r]x) F``, and the maps' K is the
        inverse of that (not symmetric in general): the K a campaign identifies from forces
        hung at ``loads.point_mm`` (docs/campaigns.md).
    """

    chain: Chain
    k_theta: tuple[float, ...]
    links: tuple[LinkSpring, ...] = ()
    configurations: np.ndarray | None = None
    tool_rotation: np.ndarray | None = None
    q_seed: np.ndarray | None = None
    singular_tol: float = SINGULAR_TOL
    match_tol_mm: float = MATCH_TOL_MM
    length_mm: float | None = None
    load_offset_mm: tuple[float, float, float] | None = None

    name: ClassVar[str] = "urdf"
    dim: ClassVar[int] = 3

    def __post_init__(self) -> None:
        if self.load_offset_mm is not None:
            r = np.asarray(self.load_offset_mm, dtype=float)
            if r.shape != (3,) or not np.all(np.isfinite(r)):
                raise InputError(
                    f"load_offset_mm must be three finite numbers (mm), got {self.load_offset_mm!r}"
                )
            object.__setattr__(self, "load_offset_mm", tuple(float(v) for v in r))
        ch = self.chain
        if not isinstance(ch, Chain):
            raise TypeError(f"chain must be a stiffmap.models.chain.Chain, got {type(ch).__name__}")
        n = ch.n
        object.__setattr__(self, "k_theta", self._checked_k(self.k_theta))
        object.__setattr__(self, "links", _resolved_links(ch, self.links))
        tol = float(self.singular_tol)
        if not (0 <= tol < 1):
            raise ValueError(f"singular_tol must be in [0, 1), got {self.singular_tol!r}")
        object.__setattr__(self, "singular_tol", tol)
        object.__setattr__(self, "match_tol_mm", check_positive("match_tol_mm", self.match_tol_mm, "mm"))
        seed = (
            np.clip(np.zeros(n), ch.lower, ch.upper)
            if self.q_seed is None
            else ch.check_q(self.q_seed, "q_seed").copy()
        )
        seed.setflags(write=False)
        object.__setattr__(self, "q_seed", seed)
        Q = self.configurations
        if Q is not None:
            Q = np.asarray(Q, dtype=np.float64)
            if Q.ndim == 1:
                Q = Q[None, :]
            if Q.ndim != 2 or Q.shape[0] == 0:
                raise InputError(
                    f"configurations must have shape (m, {n}) (rad or mm), "
                    f"got {np.shape(self.configurations)}",
                    source=ch.source,
                )
            Q = np.array([ch.check_q(q, f"configuration {i + 1}") for i, q in enumerate(Q)])
            Q.setflags(write=False)
            object.__setattr__(self, "configurations", Q)
            Pc, Rc = ch.forward_many(Q)
            Pc.setflags(write=False)
        else:
            Pc, Rc = np.zeros((0, 3)), np.zeros((0, 3, 3))
        object.__setattr__(self, "_config_points", Pc)
        object.__setattr__(self, "_config_rotations", Rc)
        object.__setattr__(self, "_seed_rotation", ch.forward(seed)[1])
        if self.tool_rotation is not None:
            R = np.array(self.tool_rotation, dtype=np.float64)
            if (
                R.shape != (3, 3)
                or not np.all(np.isfinite(R))
                or not np.allclose(R.T @ R, np.eye(3), atol=1e-6)
                or np.linalg.det(R) < 0
            ):
                raise ValueError(f"tool_rotation must be a 3x3 rotation matrix, got {self.tool_rotation!r}")
            R.setflags(write=False)
            object.__setattr__(self, "tool_rotation", R)
        if self.length_mm is None:
            J = ch.jacobian(seed)
            rev = [i for i, t in enumerate(ch.joint_types) if t == "revolute"]
            L = max([1.0, *(float(np.linalg.norm(J[:3, i])) for i in rev)])
        else:
            L = check_positive("length_mm", self.length_mm, "mm")
        object.__setattr__(self, "length_mm", L)
        object.__setattr__(self, "_memo", {})

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_urdf(
        cls,
        path,
        tip_frame: str,
        tip_offset_mm=(0.0, 0.0, 0.0),
        *,
        k_theta,
        links=(),
        base_frame: str | None = None,
        xacro_args=None,
        package_paths=(),
        configurations=None,
        tool_rotation=None,
        q_seed=None,
        singular_tol: float = SINGULAR_TOL,
        match_tol_mm: float = MATCH_TOL_MM,
        length_mm: float | None = None,
    ) -> SerialRobot:
        """A serial robot from its URDF (metres, turned into mm once).

        Parameters
        ----------
        path : path-like
            The URDF file.
        tip_frame : str
            The link (frame) that carries the measured point.
        tip_offset_mm : array_like, shape (3,), mm
            The measured point in that frame.
        k_theta : float or sequence of n (or n + m) floats
            Joint stiffnesses, N*mm/rad (revolute) or N/mm (prismatic), in the chain's
            joint order (:attr:`Chain.joint_names`; then its mimic joints'); one value is
            taken for every joint.
        links : sequence of LinkSpring
            Flexible links (:func:`~stiffmap.models.robot_files.read_links_toml`).
        base_frame, xacro_args, package_paths
            As :meth:`Chain.from_urdf`.
        configurations, tool_rotation, q_seed, singular_tol, match_tol_mm, length_mm
            As the attributes.

        Raises
        ------
        InputError
            Naming the file: it does not parse, the tip frame is missing (the links are
            listed), k_theta or a configuration has the wrong length.
        """
        chain = Chain.from_urdf(
            path,
            tip_frame,
            tip_offset_mm,
            base_frame=base_frame,
            xacro_args=xacro_args,
            package_paths=package_paths,
        )
        return cls(
            chain,
            k_theta,
            links=tuple(links),
            configurations=configurations,
            tool_rotation=tool_rotation,
            q_seed=q_seed,
            singular_tol=singular_tol,
            match_tol_mm=match_tol_mm,
            length_mm=length_mm,
        )

    # ------------------------------------------------------------------ parameters

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.chain.n

    @property
    def n_springs(self) -> int:
        """Number of joint springs: the n coordinates', then the m mimic joints'."""
        return self.chain.n + len(self.chain.mimics)

    @property
    def spring_names(self) -> tuple[str, ...]:
        """The joints holding the springs k1 ... k(n+m): coordinates, then mimic joints."""
        return self.chain.joint_names + self.chain.mimic_names

    def _spring_type(self, i: int) -> str:
        ch = self.chain
        return ch.joint_types[i] if i < ch.n else ch.mimics[i - ch.n].type

    def _checked_k(self, k) -> tuple[float, ...]:
        """k_theta as n + m checked stiffnesses (one value: every coordinate; mimic springs rigid
        unless given)."""
        ch = self.chain
        n, m = ch.n, len(ch.mimics)
        if np.ndim(k) == 0:
            k = (k,) * n
        k = tuple(k)
        if len(k) == n:
            k = k + (math.inf,) * m
        if len(k) != n + m:
            also = (
                f" (then {m} for its mimic joints {', '.join(ch.mimic_names)}, rigid if left out)"
                if m
                else ""
            )
            raise InputError(
                f"k_theta has {len(k)} value(s); {ch.name} has {n} joints ({', '.join(ch.joint_names)}): "
                f"give {n} joint stiffnesses (N*mm/rad, N/mm for prismatic) or one for all{also}",
                source=ch.source,
            )
        names = self.spring_names
        return tuple(
            check_positive(f"k{i + 1} ({names[i]})", v, self._unit(i), allow_inf=True)
            for i, v in enumerate(k)
        )

    @property
    def length(self) -> float:
        """The characteristic length L (mm) of the singularity measures."""
        return float(self.length_mm)

    def _unit(self, i: int) -> str:
        return "N/mm" if self._spring_type(i) == "prismatic" else "N*mm/rad"

    def joint_param_names(self) -> tuple[str, ...]:
        """``("k1", ..., "k(n+m)")``: the n coordinates' springs, then the m mimic joints'."""
        return tuple(f"k{i + 1}" for i in range(self.n_springs))

    def link_param_names(self) -> tuple[str, ...]:
        """The flexible links' parameters (``E_<name>``, ``G_<name>``, ``f_<name>``)."""
        return tuple(nm for lk in self.links for nm in lk.param_names())

    def param_names(self) -> tuple[str, ...]:
        """Joint springs ``k1 ... k(n+m)`` (1-based, the chain's joint order, then its mimic
        joints), then the flexible links' parameters."""
        return self.joint_param_names() + self.link_param_names()

    def params(self) -> dict[str, float]:
        """The joint stiffnesses by name (N*mm/rad, N/mm for prismatic joints), then the links'
        parameters (MPa, or a dimensionless stiffness factor)."""
        out = dict(zip(self.joint_param_names(), self.k_theta, strict=True))
        for lk in self.links:
            out.update(lk.params())
        return out

    def default_fit(self) -> tuple[str, ...]:
        """The parameters a fit takes by default: every finite joint spring and every link parameter."""
        ks = [nm for nm, v in zip(self.joint_param_names(), self.k_theta, strict=True) if math.isfinite(v)]
        return tuple(ks) + self.link_param_names()

    def with_params(self, **params) -> SerialRobot:
        """A copy with some joint stiffnesses (or other attributes) changed.

        Parameters
        ----------
        **params
            ``k1=...``, ..., ``kn=...`` (one joint each), ``k_theta=`` a sequence of n
            values or one for all (applied before the single ``k<i>``), or any other
            attribute (``singular_tol``, ``configurations``, ...).

        Raises
        ------
        ValueError
            An unknown name (the valid ones are listed), a non-positive stiffness.
        """
        names = self.joint_param_names()
        link_names = self.link_param_names()
        other = {f.name for f in fields(self)} - {"chain", "k_theta"}
        bad = sorted(set(params) - set(names) - set(link_names) - other - {"k_theta"})
        if bad:
            raise ValueError(
                f"unknown urdf parameter(s) {', '.join(bad)}; valid: {', '.join(names + link_names)}, "
                f"k_theta (the {self.n} joint stiffnesses of {self.chain.name})"
            )
        k = list(self.k_theta)
        if "k_theta" in params:
            v = params["k_theta"]
            given = self._checked_k(v) if np.ndim(v) else (v,) * self.n
            k[: len(given)] = given
        for i, nm in enumerate(names):
            if nm in params:
                k[i] = params[nm]
        rest = {key: v for key, v in params.items() if key in other}
        if any(nm in params for nm in link_names):
            for nm in link_names:
                if nm in params:
                    check_positive(nm, params[nm], "")
            rest["links"] = tuple(lk.with_params(params) for lk in rest.get("links", self.links))
        new = replace(self, k_theta=tuple(k), **rest)
        if not (set(rest) - {"links"}):  # same kinematics: share the remembered inverse kinematics
            object.__setattr__(new, "_memo", self._memo)
        return new

    def describe(self) -> str:
        """One line: the robot, its joints, the measured point and the joint stiffnesses."""
        ch = self.chain
        ks = ", ".join(f"{v:g}" for v in self.k_theta)
        units = (
            "N/mm"
            if all(t == "prismatic" for t in ch.joint_types)
            else "N*mm/rad" + (", N/mm for prismatic" if "prismatic" in ch.joint_types else "")
        )
        off = ", ".join(f"{v:g}" for v in ch.tip_offset_mm)
        extra = ""
        if ch.held_joints:
            extra += f"; base frame {ch.base_frame} (held above it: {', '.join(ch.held_joints)})"
        if ch.mimics:
            extra += "; mimic joints " + ", ".join(
                f"{m.name} (follows {ch.joint_names[m.leader]})"
                if m.leader is not None
                else f"{m.name} (held)"
                for m in ch.mimics
            )
        if self.links:
            extra += "; flexible links " + ", ".join(
                f"{lk.link} ({', '.join(f'{k}={v:g}' for k, v in lk.params().items())})" for lk in self.links
            )
        return (
            f"urdf {ch.name} ({ch.source}): {ch.n} joints {', '.join(ch.joint_names)}; measured point "
            f"{ch.tip_frame} + ({off}) mm; k_theta = ({ks}) {units}{extra}"
        )

    # ------------------------------------------------------------------ kinematics

    def _configs(self, q) -> tuple[np.ndarray, bool]:
        """Configurations as (M, n) float, checked; single is True for one of shape (n,)."""
        Q = np.asarray(q, dtype=np.float64)
        single = Q.ndim == 1
        if single:
            Q = Q[None, :]
        if Q.ndim != 2 or Q.shape[1] != self.n:
            raise InputError(
                f"configurations must have shape (M, {self.n}) or ({self.n},) (rad or mm): "
                f"{self.chain.name} has {self.n} joints ({', '.join(self.chain.joint_names)}); "
                f"got shape {np.shape(q)}",
                source=self.chain.source,
            )
        bad = ~np.all(np.isfinite(Q), axis=1)
        if np.any(bad):
            i = int(np.argmax(bad))
            raise InputError(
                f"configuration {i + 1} is not finite: {Q[i].tolist()}", source=self.chain.source
            )
        return Q, single

    def _solve(self, p: np.ndarray) -> tuple[np.ndarray, str]:
        """Joint coordinates of one point, or NaN and the reason."""
        key = p.tobytes()
        hit = self._memo.get(key)
        if hit is not None:
            return hit
        ch = self.chain
        Qc, Pc = self.configurations, self._config_points
        if Qc is not None:
            d = np.linalg.norm(Pc - p, axis=1)
            j = int(np.argmin(d))
        if Qc is not None and d[j] <= self.match_tol_mm:
            near = np.flatnonzero(d <= self.match_tol_mm)
            other = [int(i) for i in near if np.max(np.abs(Qc[i] - Qc[j])) > 1e-9]
            if other:
                res = (
                    np.full(self.n, np.nan),
                    f"unreachable: ambiguous: configurations {j + 1} and {other[0] + 1} both put the "
                    "point here with different joint coordinates; a position cannot tell them apart",
                )
            else:
                res = (Qc[j].copy(), "")
        else:
            if Qc is not None:
                q0, R0, start = Qc[j], self._config_rotations[j], f"configuration {j + 1}"
            else:
                q0, R0, start = self.q_seed, self._seed_rotation, "q_seed"
            R = R0 if self.tool_rotation is None else self.tool_rotation
            r = ch.inverse(p, R, q0=q0, length_mm=self.length)
            if not r.converged:
                res = (
                    np.full(self.n, np.nan),
                    f"unreachable: inverse kinematics from {start} holding the tool orientation did not "
                    f"converge ({r.position_error_mm:.3g} mm and {r.rotation_error_rad:.3g} rad left "
                    f"after {r.iterations} iterations)",
                )
            else:
                res = (r.q, "")
        q, why = res
        if not why:
            beyond = ch.beyond_limits(q)
            if beyond:
                res = (np.full(self.n, np.nan), "unreachable: " + "; ".join(beyond))
        if len(self._memo) > _MEMO_MAX:
            self._memo.clear()
        self._memo[key] = res
        return res

    def configurations_for(self, points) -> IKSolution:
        """The joint configuration of each position of the measured point.

        A point within ``match_tol_mm`` of a given configuration's measured point takes
        that configuration; any other is solved by :meth:`Chain.inverse` from the nearest
        configuration (or ``q_seed``), holding ``tool_rotation`` (default: the orientation of
        that configuration). A point is
        unreachable when inverse kinematics does not converge, when its configuration
        puts a joint beyond its limits, or when two different configurations share it.

        Parameters
        ----------
        points : array_like, shape (N, 3) or (3,), mm, base frame

        Returns
        -------
        IKSolution
            ``q`` (N, n) rad or mm (NaN where unreachable), ``reachable``, ``reasons``.
        """
        P, _ = as_points(points, 3)
        out = [self._solve(p) for p in P]
        Q = np.array([q for q, _ in out]).reshape(-1, self.n)
        reasons = tuple(r for _, r in out)
        return IKSolution(Q, np.array([not r for r in reasons], dtype=bool), reasons)

    def inverse_kinematics(self, points) -> IKSolution:
        """:meth:`configurations_for` (the :class:`Mechanism` protocol's name)."""
        return self.configurations_for(points)

    # ------------------------------------------------------------------ stiffness

    @property
    def compliances(self) -> np.ndarray:
        """Joint compliances ``1 / k`` (rad/(N*mm) or mm/N; 0 for a rigid joint), shape (n + m,)."""
        return 1.0 / np.asarray(self.k_theta)

    @property
    def has_k6(self) -> bool:
        """Whether K6 can exist: six compliant joint springs, or a flexible link."""
        return bool(self.links) or int(np.count_nonzero(np.isfinite(self.k_theta))) >= 6

    def spring_jacobians(self, q) -> np.ndarray:
        """Every joint spring's column at configurations: the coordinates' then the mimic joints'.

        Parameters
        ----------
        q : array_like, shape (n,) or (M, n)

        Returns
        -------
        ndarray, shape (M, 6, n + m)
        """
        Q, _ = self._configs(q)
        J = self.chain.jacobian_many(Q)
        if self.chain.mimics:
            J = np.concatenate([J, self.chain.mimic_jacobian_many(Q)], axis=2)
        return J

    def link_jacobians(self, q) -> np.ndarray:
        """``J_s`` of the flexible links' springs at configurations (:func:`links.spring_jacobians`).

        Returns
        -------
        ndarray, shape (M, S, 6, 6)
            The measured point's motion (base frame) from each spring's twist (spring frame).
        """
        Q, _ = self._configs(q)
        if not self.links:
            return np.zeros((Q.shape[0], 0, 6, 6))
        frames = [(lk.link, lk.rotation, lk.origin_mm) for lk in self.links]
        O, R = self.chain.link_poses(Q, frames)
        P, _ = self.chain.forward_many(Q)
        return spring_jacobians(P, O, R)

    def link_columns(self, q) -> tuple[LinkColumns, ...]:
        """The flexible links' parameters as the joint fit takes them (:class:`LinkColumns`).

        For each parameter p of each link (``E_<name>``, ``G_<name>``: a beam's moduli, kind
        "modulus"; ``f_<name>``: a given compliance's factor, kind "factor"), the point's
        compliance per unit of ``1/p``: ``J_s B_p J_s^T`` at each configuration.

        Parameters
        ----------
        q : array_like, shape (n,) or (M, n)

        Returns
        -------
        tuple of LinkColumns
            In :meth:`link_param_names` order, bases of shape (M, 6, 6).
        """
        Js = self.link_jacobians(q)
        out = []
        for s, lk in enumerate(self.links):
            kind = "modulus" if lk.beam is not None else "factor"
            for name, B in zip(lk.param_names(), lk.basis(), strict=True):
                basis = np.einsum("mij,jk,mlk->mil", Js[:, s], B, Js[:, s])
                out.append(LinkColumns(name, 0.5 * (basis + np.swapaxes(basis, 1, 2)), kind))
        return tuple(out)

    def _compliance(self, Q: np.ndarray, J: np.ndarray) -> np.ndarray:
        """C6 (M, 6, 6) at configurations Q with their spring columns J (M, 6, n + m)."""
        C = _compliances(J, self.compliances)
        if self.links:
            Js = self.link_jacobians(Q)
            Cs = np.array([lk.matrix() for lk in self.links])
            C = C + np.einsum("msij,sjk,mslk->mil", Js, Cs, Js)
            C = 0.5 * (C + np.swapaxes(C, 1, 2))
        return C

    def compliance6(self, q) -> np.ndarray:
        """Compliance of the measured point, ``C6 = J K_theta^-1 J^T + sum_s J_s C_s J_s^T``.

        Parameters
        ----------
        q : array_like, shape (n,) or (M, n)
            Joint configurations (rad or mm).

        Returns
        -------
        ndarray, shape (6, 6) or (M, 6, 6)
            Maps a wrench (F N, M N*mm) at the point to its displacement (u mm, rotation
            vector rad), base frame: blocks mm/N, 1/N (twice) and rad/(N*mm).
        """
        Q, single = self._configs(q)
        C = self._compliance(Q, self.spring_jacobians(Q))
        return C[0] if single else C

    def deflection(self, q, wrench) -> np.ndarray:
        """Displacement of the measured point under a wrench: ``C6 w``.

        Parameters
        ----------
        q : array_like, shape (n,) or (M, n)
        wrench : array_like, shape (6,) or (M, 6)
            (Fx, Fy, Fz N, Mx, My, Mz N*mm) at the measured point, base frame.

        Returns
        -------
        ndarray, shape (6,) or (M, 6)
            (u mm, rotation vector rad), base frame.
        """
        Q, single = self._configs(q)
        W = np.asarray(wrench, dtype=np.float64)
        if W.shape == (6,):
            W = np.broadcast_to(W, (Q.shape[0], 6))
        if W.shape != (Q.shape[0], 6) or not np.all(np.isfinite(W)):
            raise ValueError(
                f"wrench must be 6 finite numbers (N, N*mm) or ({Q.shape[0]}, 6), got {np.shape(wrench)}"
            )
        d = np.einsum("mij,mj->mi", self._compliance(Q, self.spring_jacobians(Q)), W)
        return d[0] if single else d

    def _scaled(self, J: np.ndarray) -> np.ndarray:
        """The dimensionless Jacobian: rotation rows and prismatic columns times L."""
        Js = J.copy()
        Js[:, 3:] *= self.length
        pris = [i for i in range(J.shape[2]) if self._spring_type(i) == "prismatic"]
        Js[:, :, pris] *= self.length
        return Js

    def _measures(self, J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joint and translation measures (module docstring) of spring columns (M, 6, n + m).

        The joint measure looks at the n coordinates; the translation measure at every
        compliant spring, and is 1 with a flexible link (its 6-D spring moves the point in
        every direction).
        """
        Js = self._scaled(J)
        soft = np.isfinite(np.asarray(self.k_theta))
        joint = _inverse_condition(Js[:, :, : self.n], min(6, self.n))
        if self.links:
            return joint, np.ones(J.shape[0])
        trans = _inverse_condition(Js[:, :3][:, :, soft], 3)
        return joint, trans

    def singularity_measures(self, q) -> tuple[np.ndarray, np.ndarray]:
        """Joint and translation singularity measures of configurations, in [0, 1] (module docstring).

        Parameters
        ----------
        q : array_like, shape (n,) or (M, n)

        Returns
        -------
        joint, translation : ndarray, shape (M,)
        """
        return self._measures(self.spring_jacobians(q))

    def _joint_reason(self, J: np.ndarray, value: float) -> str:
        """Which joints lose the tip's motion at one configuration (J, 6 x (n + m)), in words."""
        ch = self.chain
        Js = self._scaled(J[None, :, : self.n])[0]
        tol = self.singular_tol
        if self.n > 6:
            U, _, _ = np.linalg.svd(Js)
            u = U[:, -1]
            what = (
                f"the joints cannot move the tip along {_direction(u[:3])} mm"
                if np.linalg.norm(u[:3]) >= np.linalg.norm(u[3:])
                else f"the joints cannot turn the tip about {_direction(u[3:])}"
            )
        else:
            nrm = np.linalg.norm(Js, axis=0)
            Jn = Js / np.where(nrm > 0, nrm, 1.0)
            v = np.linalg.svd(Jn)[2][-1]
            idle = [ch.joint_names[i] for i in np.flatnonzero(nrm == 0)]
            inv = [i for i in np.flatnonzero(np.abs(v) > 0.1 * np.max(np.abs(v)))]
            names = [ch.joint_names[i] for i in inv]
            if idle:
                one = len(idle) == 1
                verb = "does" if one else "do"
                what = f"{'joint' if one else 'joints'} {_names(idle)} {verb} not move the tip"
            elif len(names) == 2:
                what = f"joints {_names(names)} move the tip alike"
            else:
                what = (
                    f"the motions of joints {_names(names)} are dependent "
                    "(one is a combination of the others)"
                )
            if (
                self.n == 6
                and all(ch.joint_types[i] == "revolute" for i in range(6))
                and inv
                and min(inv) >= 3
            ):
                what += " (wrist singularity)"
        return f"{what}; inverse condition {value:.2g} < {tol:g}"

    def _translation_reason(self, J: np.ndarray, value: float) -> str:
        soft = np.isfinite(np.asarray(self.k_theta))  # over the n + m springs
        Jt = J[:3][:, soft]
        who = "joints" if np.all(soft) else "compliant joints (finite k)"
        if Jt.shape[1] == 0:
            return (
                "every joint is rigid: the point cannot move "
                f"(translation measure {value:.2g} < {self.singular_tol:g})"
            )
        U, _, _ = np.linalg.svd(self._scaled(J[None])[0][:3][:, soft])
        return (
            f"the {who} cannot move the point along {_direction(U[:, -1])}: its stiffness there is "
            f"infinite in a joint-spring model (translation measure {value:.2g} < {self.singular_tol:g})"
        )

    def _map(self, P: np.ndarray, Q: np.ndarray, reachable: np.ndarray, reasons: list[str]) -> ModelMap:
        """The map of positions P (N, 3) at configurations Q (N, n) (NaN where unreachable)."""
        N = P.shape[0]
        J = np.full((N, 6, self.n_springs), np.nan)
        if np.any(reachable):
            J[reachable] = self.spring_jacobians(Q[reachable])
        joint = np.full(N, np.nan)
        trans = np.full(N, np.nan)
        if np.any(reachable):
            joint[reachable], trans[reachable] = self._measures(J[reachable])
        tol = self.singular_tol
        valid = reachable.copy()
        for i in np.flatnonzero(reachable & ((joint < tol) | (trans < tol))):
            parts = []
            if joint[i] < tol:
                parts.append(self._joint_reason(J[i], joint[i]))
            if trans[i] < tol:
                parts.append(self._translation_reason(J[i], trans[i]))
            reasons[i] = "singular: " + "; ".join(parts)
            valid[i] = False
        K = np.full((N, 3, 3), np.nan)
        if np.any(valid):
            idx = np.flatnonzero(valid)
            C6 = self._compliance(Q[idx], J[idx])
            C = C6[:, :3, :3]
            ok = _check_rigid(C, idx, reasons)
            valid[idx[~ok]] = False
            if np.any(ok):
                if self.load_offset_mm is None:
                    Kv = np.linalg.inv(C[ok])
                    K[idx[ok]] = 0.5 * (Kv + np.swapaxes(Kv, 1, 2))
                else:  # forces off the point: C_tt + C_tr [r]x (the class docstring)
                    r = self.load_offset_mm
                    S = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
                    K[idx[ok]] = np.linalg.inv(C[ok] + C6[ok][:, :3, 3:] @ S)
        cond = np.where(reachable, np.fmin(joint, trans), np.nan)
        return model_map(self.name, self.params(), P, K, valid, reasons, Q, cond)

    def evaluate(self, points) -> ModelMap:
        """Stiffness map over positions of the measured point, flagging unreachable and singular ones.

        Parameters
        ----------
        points : array_like, shape (N, 3) or (3,), mm, base frame

        Returns
        -------
        ModelMap
            K = ``(C6[:3, :3])^-1`` (N/mm, base frame; the stiffness a pure force at the
            point sees), ``q`` the joint coordinates (rad or mm), ``conditioning`` the
            smaller singularity measure (module docstring).
        """
        P, _ = as_points(points, 3)
        ik = self.configurations_for(P)
        return self._map(P, ik.q, ik.reachable, list(ik.reasons))

    def evaluate_configurations(self, q) -> ModelMap:
        """The map at given joint configurations (their measured points are the map's points).

        A configuration with a joint beyond its limits is unreachable (named); singular
        ones are flagged as in :meth:`evaluate`.

        Parameters
        ----------
        q : array_like, shape (M, n) or (n,), rad or mm

        Returns
        -------
        ModelMap
        """
        Q, _ = self._configs(q)
        Q = Q.copy()
        P, _ = self.chain.forward_many(Q)
        reasons = ["" for _ in range(Q.shape[0])]
        for i, q in enumerate(Q):
            beyond = self.chain.beyond_limits(q)
            if beyond:
                reasons[i] = "unreachable: " + "; ".join(beyond)
        reachable = np.array([not r for r in reasons], dtype=bool)
        return self._map(P, Q, reachable, reasons)

    def _check_configs(self, q, need6: bool) -> tuple[np.ndarray, np.ndarray, bool]:
        """C6 (or C3) of configurations where K6 (or K3) exists, else InputError naming the first."""
        Q, single = self._configs(q)
        J = self.spring_jacobians(Q)
        joint, trans = self._measures(J)
        soft = int(np.count_nonzero(np.isfinite(np.asarray(self.k_theta))))
        tol = self.singular_tol
        for i in range(Q.shape[0]):
            where = "" if single else f"configuration {i + 1}: "
            if need6 and not self.has_k6:
                raise InputError(
                    f"{where}K6 needs six compliant joints; {self.chain.name} has {soft}: its compliance "
                    "C6 is singular (use compliance6, or stiffness3 for the force stiffness)",
                    source=self.chain.source,
                )
            bad = []
            if need6 and not self.links and joint[i] < tol:
                bad.append(self._joint_reason(J[i], joint[i]))
            if trans[i] < tol:
                bad.append(self._translation_reason(J[i], trans[i]))
            if bad:
                raise InputError(f"{where}singular: " + "; ".join(bad), source=self.chain.source)
        C = self._compliance(Q, J)
        C = C if need6 else C[:, :3, :3]
        reasons = ["" for _ in range(Q.shape[0])]
        # C6 mixes mm/N and rad/(N*mm): its rotations are taken times L (as the singularity
        # measures are), so that the rigidity ratio compares springs, not units
        S = np.diag([1.0, 1.0, 1.0, *([self.length] * 3)]) if need6 else np.eye(3)
        ok = _check_rigid(S @ C @ S, np.arange(Q.shape[0]), reasons)
        if not ok.all():
            i = int(np.flatnonzero(~ok)[0])
            where = "" if single else f"configuration {i + 1}: "
            raise InputError(where + reasons[i], source=self.chain.source)
        return Q, C, single

    def stiffness6(self, q) -> np.ndarray:
        """``K6 = C6^-1`` (= J^-T K_theta J^-1 for six joints), where J has rank 6.

        Parameters
        ----------
        q : array_like, shape (n,) or (M, n)

        Returns
        -------
        ndarray, shape (6, 6) or (M, 6, 6)
            Over (u mm, rotation vector rad) -> (F N, M N*mm): blocks N/mm, N/rad,
            N (mm per mm) and N*mm/rad.

        Raises
        ------
        InputError
            Fewer than six compliant joints, or a singular configuration (named).
        """
        _, C, single = self._check_configs(q, need6=True)
        K = np.linalg.inv(C)
        K = 0.5 * (K + np.swapaxes(K, 1, 2))
        return K[0] if single else K

    def past_joint_singularity(self, q) -> np.ndarray | None:
        """K at a configuration singular for its joints only (joint measure below
        ``singular_tol``, translation measure at or above it), else None.

        There the joints lose their independence (a wrist singularity: joints 4 and 6 aligned)
        but the point still moves every way, so ``K = (C6[:3, :3])^-1`` exists and is well
        conditioned. K6 = C6^-1 is not given there: it grows without bound as the configuration
        nears the singularity, and within ``singular_tol`` of it (inverse condition 1e-3) its
        value hangs on the Jacobian's last digits (a Jacobian by central differences, good to
        1e-10, moves it by 1e-6 at 1e-4).

        Parameters
        ----------
        q : array_like, shape (n,)

        Returns
        -------
        ndarray, shape (3, 3), N/mm, or None
            None where the configuration is not singular for its joints alone, or where K does
            not exist either (:meth:`stiffness3` refuses it: a translation singularity, a
            compliance almost rigid).
        """
        joint, trans = self.singularity_measures(q)
        if not (joint[0] < self.singular_tol <= trans[0]):
            return None
        try:
            return self.stiffness3(q)
        except InputError:
            return None

    def stiffness3(self, q) -> np.ndarray:
        """``K = (C6[:3, :3])^-1`` (N/mm): the stiffness a pure force at the point sees.

        Parameters
        ----------
        q : array_like, shape (n,) or (M, n)

        Returns
        -------
        ndarray, shape (3, 3) or (M, 3, 3), N/mm, base frame

        Raises
        ------
        InputError
            Where the compliant joints cannot move the point in every direction (named).
        """
        _, C, single = self._check_configs(q, need6=False)
        K = np.linalg.inv(C)
        K = 0.5 * (K + np.swapaxes(K, 1, 2))
        return K[0] if single else K

    def stiffness(self, points) -> np.ndarray:
        """K (N/mm) at positions of the measured point (:meth:`evaluate`).

        Parameters
        ----------
        points : array_like, shape (N, 3) or (3,), mm

        Returns
        -------
        ndarray, shape (N, 3, 3) or (3, 3), N/mm

        Raises
        ------
        PoseError
            Naming the first unreachable or singular position.
        """
        return stiffness_of(self, points)

    def static_error(self, points, force) -> np.ndarray:
        """Static error ``u = K^-1 F`` (mm) of the measured point under a force F (N).

        Parameters
        ----------
        points : array_like, shape (N, 3) or (3,), mm
        force : array_like, shape (3,) or (N, 3), N

        Returns
        -------
        ndarray, shape (N, 3) or (3,), mm
        """
        return static_error_of(self, points, force)

    def __repr__(self) -> str:
        m = 0 if self.configurations is None else self.configurations.shape[0]
        return f"SerialRobot({self.chain!r}, k_theta={list(self.k_theta)}, configurations={m})"
