"""Parallel robots described by their legs: the virtual joint method on kinematic chains.

A translational parallel robot -- its platform moves in d = 3 translations (or d = 2 in a
plane) while its orientation is held, as the Delta's parallelograms hold it -- is described
leg by leg. Each leg is a serial chain from the base to its joint on the platform
(:class:`~stiffmap.models.chain.Chain`, through Pinocchio): a list of joints in a TOML file,
or its own URDF. Every joint has a role:

- ``actuated``: a motor with its stiffness (N*mm/rad or N/mm); its coordinate is the
  robot's ``q``;
- ``spring``: a virtual joint standing for a link's compliance (an arm bending, a rod
  stretching), at rest (q = 0) in the kinematics;
- ``passive``: free (a pin, a ball joint as three revolute joints).

At a pose P, each leg's inverse kinematics (:meth:`Chain.inverse`, position only, from the
leg's seed ``q0``: the solution is on the seed's branch) puts its tip on the platform at
``P + attach_mm``; the leg's Jacobian there gives the columns of its spring joints ``J_s``
(d x s, with stiffnesses k) and of its passive joints ``J_p``, and the platform's stiffness
is the virtual joint method's assembly (:func:`~stiffmap.models.base.platform_stiffness`):

    C_leg = J_s diag(1/k) J_s^T,   K_leg = U (U^T C_leg U)^-1 U^T,   K = sum over legs of K_leg

with U an orthonormal basis of the directions the passive joints do not free (the
complement of range J_p). A leg's flexible links (``[[legs.links]]``: 6-D springs on its
links, :mod:`~stiffmap.models.links`) add their share to its compliance at the tip before
the assembly, ``C_leg = J_s diag(1/k) J_s^T + sum_l J_l C_l J_l^T`` (J_l the tip's motion per
twist of link l's spring; its translation rows for dim 2 and 3, all six for dim 6); their
parameters (``E_<name>``, ``G_<name>``, ``f_<name>``) follow ``[params]`` in ``params()``.
The built-in :class:`~stiffmap.models.delta.DeltaRobot` and
:class:`~stiffmap.models.prr3.PRR3` are the same assembly fed with closed-form columns;
:func:`~stiffmap.models.legs_convert.legs_toml` writes either as a legs TOML (the package ships them as
``robots/delta.toml`` and ``robots/3prr.toml``), and :class:`LegRobot` read from it equals
the built-in model (tests: 1e-9 relative in K).

The TOML format is in ``docs/models.md`` ("Parallel robots from their legs").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import ClassVar

import numpy as np

from ..errors import InputError
from .base import (
    IKSolution,
    LegMechanism,
    as_points,
    check_positive,
    constrained_directions,
    platform_stiffness,
)
from .chain import Chain, JointSpec
from .legs_chains import urdf_without_springs, without_springs
from .legs_file import ROLES, LegDescription, LegsFile, parse_legs_text, read_legs_file
from .links import LinkSpring, resolve_axis, spring_jacobians

__all__ = ["LegRobot", "LegStates", "LIMIT_TOL"]

#: How far (rad or mm) an inverse-kinematics solution may lie beyond a joint limit (roundoff).
LIMIT_TOL = 1e-9
#: Most steps of the inverse kinematics' continuation from a leg's seed.
MAX_STEPS = 100

# ---------------------------------------------------------------------- building the legs


@dataclass(frozen=True, eq=False)
class _Leg:
    """A leg ready to compute: its chains, roles, seed and limits."""

    name: str
    chain: Chain  # base to the platform joint, every joint
    ik_chain: Chain  # the same with the spring joints at rest removed
    roles: tuple[str, ...]  # of chain's joints
    stiffness: tuple[str | None, ...]
    free: np.ndarray  # indices (in chain) of ik_chain's joints
    q0: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    target: np.ndarray  # (3,): attach_mm, and for a planar robot the tip's z at the seed
    tip0: np.ndarray  # (3,) mm: the tip at the seed
    step_mm: float  # continuation step
    links: tuple[LinkSpring, ...] = ()  # flexible links: origin (link frame) and beam axis resolved

    def link_jacobians(self, q: np.ndarray) -> np.ndarray:
        """``J_s`` of the leg's flexible links at joint coordinates q (every joint), shape (S, 6, 6):
        the platform joint's motion (velocity, rotation; base frame) per twist of each spring."""
        if not self.links:
            return np.zeros((0, 6, 6))
        frames = [(lk.link, lk.rotation, lk.origin_mm) for lk in self.links]
        O, R = self.chain.link_poses(q[None], frames)
        return spring_jacobians(self.chain.forward(q)[0][None], O, R)[0]

    @property
    def columns(self) -> tuple[list[int], list[int], list[int]]:
        """Indices of the spring (actuated and spring), actuated and passive joints."""
        r = self.roles
        return (
            [i for i, x in enumerate(r) if x != "passive"],
            [i for i, x in enumerate(r) if x == "actuated"],
            [i for i, x in enumerate(r) if x == "passive"],
        )

    def solve(self, target: np.ndarray) -> tuple[np.ndarray | None, str]:
        """Joint coordinates of the IK chain with the tip at ``target``, on the seed's branch.

        :meth:`Chain.inverse` from the seed; when that does not converge or lands beyond a
        limit (on another branch), continuation: the tip moved from its seed position to the
        target in steps of ``step_mm`` (at most :data:`MAX_STEPS`), each solved from the previous
        solution.

        Returns
        -------
        q : ndarray or None
        why : str
            Why not (when None), in words.
        """
        res = self.ik_chain.inverse(target, q0=self.q0, max_iter=50)
        if res.converged and not self.beyond_limits(res.q):
            return res.q, ""
        n = min(max(2, math.ceil(float(np.linalg.norm(target - self.tip0)) / self.step_mm)), MAX_STEPS)
        q = self.q0
        for k in range(1, n + 1):
            on_path = self.tip0 + (k / n) * (target - self.tip0)
            res = self.ik_chain.inverse(on_path, q0=q, max_iter=30, tol_mm=1e-9 if k == n else 1e-6)
            way = f"{100 * (k - 1) / n:.0f} % of the way"
            if not res.converged:
                return None, (
                    f"cannot reach it from its seed (inverse kinematics stops {res.position_error_mm:.3g} "
                    f"mm away, {way})"
                )
            q = res.q
            out = self.beyond_limits(q)
            if out and k < n:
                return None, f"cannot reach it from its seed within its limits ({'; '.join(out)}, {way})"
            if out:
                return None, "; ".join(out)
        return q, ""

    def beyond_limits(self, q: np.ndarray) -> list[str]:
        out = []
        for k, v in enumerate(q):
            lo, hi = self.lower[k], self.upper[k]
            if v < lo - LIMIT_TOL or v > hi + LIMIT_TOL:
                j = int(self.free[k])
                unit, f = ("mm", 1.0) if self.chain.joint_types[j] == "prismatic" else ("deg", 180 / math.pi)
                out.append(
                    f"joint {self.chain.joint_names[j]} at {v * f:.6g} {unit} beyond its limits "
                    f"[{lo * f:.6g}, {hi * f:.6g}] {unit}"
                )
        return out


def _build_leg(desc: LegDescription, k: int, dim: int, base_dir: Path, source: str, robot: str) -> _Leg:
    where = f"legs[{k}]"
    label = f"{robot}: {where} ({desc.name})"
    given = {jt.name: jt for jt in desc.joints}
    if desc.urdf is None:
        specs = [
            JointSpec(jt.name, jt.type, jt.axis, jt.xyz_mm or (0.0,) * 3, jt.rpy or (0.0,) * 3)
            for jt in desc.joints
        ]
        chain = Chain.from_joints(specs, desc.tip_offset_mm, name=label)
        rigid, tip = without_springs(desc.joints, desc.tip_offset_mm)
        if not rigid:
            raise InputError(
                f"{where}: every joint is a spring; a leg needs actuated or passive joints", source=source
            )
        ik_chain = Chain.from_joints(rigid, tip, name=label)
    else:
        path = Path(desc.urdf)
        path = path if path.is_absolute() else base_dir / path
        try:
            chain = Chain.from_urdf(path, desc.tip_frame, desc.tip_offset_mm)
        except InputError as e:  # named in the URDF's terms; say which leg refers to it
            raise InputError(f"{where}.urdf: {e}", source=source) from None
        for j, jt in enumerate(desc.joints, start=1):
            if jt.name not in chain.joint_names:
                raise InputError(
                    f"{where}.joints[{j}].name: {jt.name!r} is not a joint moving {desc.tip_frame!r} in "
                    f"{path} (its joints: {', '.join(chain.joint_names)})",
                    source=source,
                )
        springs = {jt.name for jt in desc.joints if jt.role == "spring"}
        ik_chain = (
            urdf_without_springs(path, springs, desc.tip_frame, desc.tip_offset_mm) if springs else chain
        )
    roles = tuple(given[n].role if n in given else "passive" for n in chain.joint_names)
    stiffness = tuple(given[n].stiffness if n in given else None for n in chain.joint_names)
    free = np.array([i for i, r in enumerate(roles) if r != "spring"], dtype=int)
    names = [chain.joint_names[i] for i in free]  # = ik_chain.joint_names
    q0, lower, upper = [], [], []
    for i, n in zip(free, names, strict=True):
        jt = given.get(n)
        q0.append(0.0 if jt is None or jt.q0 is None else jt.q0)
        lower.append(chain.lower[i] if jt is None or jt.lower is None else jt.lower)
        upper.append(chain.upper[i] if jt is None or jt.upper is None else jt.upper)
    q0a = np.array(q0)
    tip0 = ik_chain.forward(q0a)[0]
    target = np.zeros(3)
    target[: len(desc.attach_mm)] = desc.attach_mm  # dim 2 or 3; dim 6: the platform frame
    if dim == 2:  # a planar robot: the leg's tip stays in its plane
        target[2] = tip0[2]
    # Continuation steps: a tenth of the leg's size (its joints' offsets and its tip's).
    if desc.urdf is None:
        size = sum(float(np.linalg.norm(jt.xyz_mm or (0.0, 0.0, 0.0))) for jt in desc.joints)
        size += float(np.linalg.norm(desc.tip_offset_mm))
    else:
        size = float(np.linalg.norm(tip0))
    lims = (np.array(lower), np.array(upper))
    links = _resolved_links(desc, chain, path if desc.urdf is not None else None)
    return _Leg(
        desc.name,
        chain,
        ik_chain,
        roles,
        stiffness,
        free,
        q0a,
        *lims,
        target,
        tip0,
        max(0.1 * size, 1.0),
        links,
    )


def _resolved_links(desc: LegDescription, chain: Chain, urdf: Path | None) -> tuple[LinkSpring, ...]:
    """The leg's flexible links on its chain: each spring's origin (default: where its link ends)
    and beam axis set; a URDF link off the leg's chain named (InputError)."""
    out = []
    for lk in desc.links:
        if lk.link not in chain.link_names:
            raise InputError(
                f"{lk.where}.link: {lk.link!r} is not a link of {urdf} between its root and "
                f"{desc.tip_frame!r} (the leg's links: {', '.join(chain.link_names)})"
            )
        if lk.origin_mm is None:
            lk = replace(lk, origin_mm=chain.link_end(lk.link))
        out.append(resolve_axis(lk, lk.origin_mm))
    return tuple(out)


# ---------------------------------------------------------------------- the robot


def _link_value(name: str, value) -> float:
    """A flexible link's parameter: a positive finite number (E_, G_ in MPa; f_ a factor), else ValueError."""
    unit = "a factor" if name.startswith("f_") else "MPa"
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive finite number ({unit}), got {value!r}")
    return v


def unreachable_as_nan(
    legs, joints: list[np.ndarray], reasons: list[str], arrays
) -> tuple[np.ndarray, np.ndarray]:
    """The actuated coordinates of every pose and which poses all legs reach.

    Parameters
    ----------
    legs : sequence
        The legs, each with ``roles`` (one per joint: "actuated", "passive" or "spring").
    joints : list of ndarray, each (N, n_k)
        Each leg's joint coordinates (rad or mm) per pose; set to NaN in place where a pose is
        unreachable.
    reasons : list of str
        Per pose: "" when reachable, else why not.
    arrays : sequence of ndarray, each (N, ...)
        Per-pose arrays (the legs' Jacobian columns) set to NaN in place where unreachable.

    Returns
    -------
    q : ndarray, shape (N, n_actuated)
        The legs' actuated coordinates side by side, leg after leg (NaN where unreachable).
    reachable : ndarray of bool, shape (N,)
    """
    reachable = np.array([r == "" for r in reasons], dtype=bool)
    for jk in joints:
        jk[~reachable] = np.nan
    for arr in arrays:
        arr[~reachable] = np.nan
    act = [[j for j, r in enumerate(lg.roles) if r == "actuated"] for lg in legs]
    return np.concatenate([joints[k][:, a] for k, a in enumerate(act)], axis=1), reachable


@dataclass(frozen=True)
class LegStates:
    """Every leg of a :class:`LegRobot` at many poses.

    Attributes
    ----------
    q : ndarray, shape (N, n_actuated)
        Actuated joint coordinates (rad or mm), leg after leg; NaN where unreachable.
    joints : tuple of ndarray, shapes (N, n_joints of the leg)
        Every joint's coordinate of each leg (springs 0); NaN where that leg cannot reach.
    reachable : ndarray of bool, shape (N,)
    reasons : tuple of str
        ``"unreachable: ..."`` naming the legs, ``""`` where reachable.
    springs, actuated, passive : ndarray, shapes (N, legs, dim, s), (N, legs, dim, a), (N, legs, dim, p)
        The legs' joint columns at their platform joints (mm per rad or per mm, base frame),
        padded with zero columns; NaN where unreachable.
    links : ndarray, shape (N, legs, S, 6, 6)
        ``J_s`` of each leg's flexible links (:func:`~stiffmap.models.links.spring_jacobians`:
        the platform joint's velocity and rotation per twist of the link's spring), padded with
        zeros; NaN where unreachable.
    """

    q: np.ndarray
    joints: tuple[np.ndarray, ...]
    reachable: np.ndarray
    reasons: tuple[str, ...]
    springs: np.ndarray
    actuated: np.ndarray
    passive: np.ndarray
    links: np.ndarray


#: The LegRobot subclass of each dim that has one (registered by ``_FOR_DIM``).
_BY_DIM: dict[int, type] = {}


@dataclass(frozen=True, eq=False)
class LegRobot(LegMechanism):
    """A translational parallel robot described by its legs (virtual joint method).

    Build it with :meth:`from_toml` (or :meth:`from_toml_text`); the module docstring
    says what it computes. A :class:`~stiffmap.models.base.Mechanism`: ``evaluate``,
    ``stiffness``, ``static_error``, ``inverse_kinematics`` (``q``: the actuated joints,
    leg after leg), ``singularity_measures``, ``params`` (the ``[params]`` stiffnesses),
    ``with_params``.

    Singularity measures, in [0, 1]: *serial*, the smallest over the legs of the sine of
    the angle between a leg's actuated joints' columns (normalised) and the directions it
    holds (the smallest singular value of ``U_h^T A``; the Delta's ``|n.t|/a``, the 3PRR's
    ``n.u``); a leg with no compliance along a direction it holds is flagged singular too;
    *parallel*, the inverse condition number of all the legs' held directions stacked (the
    Delta's forearm directions, the 3PRR's rods).

    Attributes
    ----------
    name : str
    dim : int
        2 (planar: points (x, y)) or 3.
    description : tuple of LegDescription
    param_keys, param_values : tuple
        The ``[params]`` stiffnesses (N*mm/rad or N/mm; inf rigid) in file order.
    singular_tol : float
    source : str
        The file it was read from (messages).
    """

    name: str
    dim: int
    description: tuple[LegDescription, ...]
    param_keys: tuple[str, ...]
    param_values: tuple[float, ...]
    singular_tol: float
    source: str
    _legs: tuple[_Leg, ...]

    _LABEL: ClassVar[str] = "legs robot"
    _PARALLEL_SINGULARITY: ClassVar[str] = "the legs' held directions nearly lose one"
    #: A subclass for the legs TOML of one ``dim`` (:class:`~stiffmap.models.legs6.LegRobot6`
    #: for 6) says so here; :meth:`from_legs_file` builds it for such a file.
    _FOR_DIM: ClassVar[int | None] = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls._FOR_DIM is not None:
            _BY_DIM[cls._FOR_DIM] = cls

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_toml(cls, path) -> LegRobot:
        """Read a legs TOML (``docs/models.md``; :func:`~stiffmap.models.legs_file.read_legs_file`);
        URDF paths in it are relative to its folder.

        Raises
        ------
        InputError
            Naming the file and the key (``legs[2].joints[1].axis: expected three numbers``),
            tables numbered from 1; a URDF's problems name the URDF.
        """
        return cls.from_legs_file(read_legs_file(path))

    @classmethod
    def from_toml_text(
        cls, text: str, *, source: str = "legs.toml", base_dir=".", default_name: str = "legs"
    ) -> LegRobot:
        """:meth:`from_toml` of a TOML text (``source`` names it in messages)."""
        return cls.from_legs_file(
            parse_legs_text(text, source=source, base_dir=base_dir, default_name=default_name)
        )

    @classmethod
    def from_legs_file(cls, f: LegsFile) -> LegRobot:
        """The robot a checked legs TOML describes (its legs' chains built, URDFs read)."""
        built = tuple(
            _build_leg(d, k, f.dim, f.base_dir, f.source, f.name) for k, d in enumerate(f.legs, start=1)
        )
        cls = _BY_DIM.get(f.dim, cls) if cls is LegRobot else cls  # dim 6: a platform that turns
        return cls(
            f.name, f.dim, f.legs, tuple(f.params), tuple(f.params.values()), f.singular_tol, f.source, built
        )

    def __post_init__(self) -> None:
        self._check_singular_tol()
        actuated = {
            s for lg in self._legs for r, s in zip(lg.roles, lg.stiffness, strict=True) if r == "actuated"
        }
        vals = []
        for k, v in zip(self.param_keys, self.param_values, strict=True):
            vals.append(check_positive(k, v, "N*mm/rad or N/mm", allow_inf=k not in actuated))
        object.__setattr__(self, "param_values", tuple(vals))

    # ------------------------------------------------------------------ parameters

    def param_names(self) -> tuple[str, ...]:
        """The ``[params]`` names, then the flexible links' (``with_params``, fitting, ``--param``)."""
        return self.param_keys + tuple(self.link_params())

    def link_params(self) -> dict[str, float]:
        """The flexible links' parameters (``E_<name>``, ``G_<name>`` MPa; ``f_<name>``), leg after
        leg; links of one name share theirs."""
        out: dict[str, float] = {}
        for lg in self._legs:
            for lk in lg.links:
                out.update({k: v for k, v in lk.params().items() if k not in out})
        return out

    def default_fit(self) -> tuple[str, ...]:
        """What a fit takes when none are named: every ``[params]`` stiffness and the links' ``E_``
        and ``f_`` (not ``G_``: torsion and shear, which ball-jointed legs seldom load; name it)."""
        return self.param_keys + tuple(n for n in self.link_params() if not n.startswith("G_"))

    def params(self) -> dict[str, float]:
        """The stiffnesses of ``[params]`` (N*mm/rad or N/mm), then the links' parameters."""
        return dict(zip(self.param_keys, self.param_values, strict=True)) | self.link_params()

    def with_params(self, **params) -> LegRobot:
        """A copy with some stiffnesses, link parameters (or ``singular_tol``) changed; unknown names
        raise ValueError, a link parameter that is not positive and finite too."""
        linked = self.link_params()
        bad = sorted(set(params) - set(self.param_keys) - set(linked) - {"singular_tol"})
        if bad:
            raise ValueError(
                f"unknown parameter(s) {', '.join(bad)} of {self.name}; "
                f"valid: {', '.join(self.param_names())}"
            )
        tol = params.pop("singular_tol", self.singular_tol)
        vals = tuple(params.get(k, v) for k, v in zip(self.param_keys, self.param_values, strict=True))
        new = {k: _link_value(k, params[k]) for k in linked if k in params}
        if not new:
            return replace(self, param_values=vals, singular_tol=tol)
        legs = tuple(replace(lg, links=tuple(lk.with_params(new) for lk in lg.links)) for lg in self._legs)
        desc = tuple(replace(d, links=tuple(lk.with_params(new) for lk in d.links)) for d in self.description)
        return replace(self, param_values=vals, singular_tol=tol, description=desc, _legs=legs)

    @property
    def chains(self) -> tuple[Chain, ...]:
        """Each leg's chain, base to its platform joint (every joint, springs included)."""
        return tuple(lg.chain for lg in self._legs)

    @property
    def roles(self) -> tuple[tuple[str, ...], ...]:
        """Each leg's joints' roles, in its chain's order."""
        return tuple(lg.roles for lg in self._legs)

    def home(self) -> tuple[np.ndarray, float]:
        """Where the legs' seeds put the tool point, and the robot's size there.

        Returns
        -------
        point : ndarray, shape (3,), mm
            The tool point (the platform level) at the legs' seeds ``q0``: the mean over the
            legs of their platform joint there less its ``attach_mm`` (the legs agree when the
            seeds are one assembly's; ``z`` is the plane's for a planar robot).
        size : float, mm
            The mean distance from the base frame's origin to the legs' platform joints there.
        """
        tips = np.array([lg.tip0 for lg in self._legs])
        point = np.mean(tips - np.array([lg.target for lg in self._legs]), axis=0)
        return point, float(np.mean(np.linalg.norm(tips, axis=1)))

    def describe(self) -> str:
        """One line: the legs and the parameters."""
        ps = ", ".join(f"{k}={v:g}" for k, v in self.params().items())
        nlinks = sum(len(lg.links) for lg in self._legs)
        ps += f", {nlinks} flexible link{'s' if nlinks > 1 else ''}" if nlinks else ""
        legs = ", ".join(f"{lg.name} ({lg.chain.n} joints)" for lg in self._legs)
        return f"{self.name}: {len(self._legs)} legs [{legs}], dim {self.dim}, {ps} (from {self.source})"

    # ------------------------------------------------------------------ kinematics

    def legs(self, points) -> LegStates:
        """Inverse kinematics of every leg and its joint columns, at many poses.

        Parameters
        ----------
        points : array_like, shape (N, dim) or (dim,), mm

        Returns
        -------
        LegStates
        """
        P, _ = as_points(points, self.dim)
        n, d, nl = P.shape[0], self.dim, len(self._legs)
        counts = {r: max(sum(x == r for x in lg.roles) for lg in self._legs) for r in ROLES}
        ns = max(sum(x != "passive" for x in lg.roles) for lg in self._legs)
        springs = np.full((n, nl, d, ns), np.nan)
        actuated = np.full((n, nl, d, counts["actuated"]), np.nan)
        passive = np.full((n, nl, d, counts["passive"]), np.nan)
        links = np.full((n, nl, max(len(lg.links) for lg in self._legs), 6, 6), np.nan)
        joints = [np.full((n, lg.chain.n), np.nan) for lg in self._legs]
        reasons = [""] * n
        for i, p in enumerate(P):
            bad = []
            for k, lg in enumerate(self._legs):
                target = lg.target.copy()
                target[:d] += p
                qf, why = lg.solve(target)
                if qf is None:
                    sep = " " if why.startswith("cannot") else ": "
                    bad.append(f"leg {k + 1} ({lg.name}){sep}{why}")
                    continue
                q = np.zeros(lg.chain.n)
                q[lg.free] = qf
                joints[k][i] = q
                J = lg.chain.jacobian(q)[:d]
                for arr, cols in zip((springs, actuated, passive), lg.columns, strict=True):
                    arr[i, k, :, : len(cols)] = J[:, cols]
                    arr[i, k, :, len(cols) :] = 0.0
                links[i, k] = 0.0
                links[i, k, : len(lg.links)] = lg.link_jacobians(q)
            if bad:
                reasons[i] = "unreachable: " + "; ".join(bad)
        arrays = (springs, actuated, passive, links)
        q, reachable = unreachable_as_nan(self._legs, joints, reasons, arrays)
        return LegStates(q, tuple(joints), reachable, tuple(reasons), *arrays[:3], links)

    def inverse_kinematics(self, points) -> IKSolution:
        """The actuated joints' coordinates (rad or mm) of many poses, leg after leg.

        Parameters
        ----------
        points : array_like, shape (N, dim) or (dim,), mm

        Returns
        -------
        IKSolution
            NaN where unreachable; ``reasons`` names the legs (out of reach from their
            seed, or beyond a joint limit).
        """
        st = self.legs(points)
        return IKSolution(st.q, st.reachable, st.reasons)

    def _unreachable_reasons(self, P: np.ndarray, st: LegStates) -> list[str]:
        return list(st.reasons)

    def _joint_coordinates(self, st: LegStates) -> np.ndarray:
        return st.q

    def _link_compliance(self, st: LegStates) -> np.ndarray | None:
        """Each leg's flexible links at its platform joint, ``sum_s J_s C_s J_s^T`` (N, legs, 6, 6);
        None without links."""
        S = st.links.shape[2]
        if S == 0:
            return None
        Cs = np.zeros((len(self._legs), S, 6, 6))
        for i, lg in enumerate(self._legs):
            for s, lk in enumerate(lg.links):
                Cs[i, s] = lk.matrix()
        C = np.einsum("nlsij,lsjk,nlsmk->nlim", st.links, Cs, st.links)
        return 0.5 * (C + np.swapaxes(C, -1, -2))

    def _assemble(self, st: LegStates, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
        """K of the valid poses (:func:`platform_stiffness`, the links' compliance at each leg's tip)."""
        C = self._link_compliance(st)
        d = self.dim
        K, rigid = platform_stiffness(*self._leg_joints(st), valid, None if C is None else C[..., :d, :d])
        return K, rigid, {}

    def _leg_joints(self, st: LegStates) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        values = self.params()
        k = np.full(st.springs.shape[1::2], np.inf)  # (legs, s): padding is rigid
        for i, lg in enumerate(self._legs):
            ks = [values[s] for r, s in zip(lg.roles, lg.stiffness, strict=True) if r != "passive"]
            k[i, : len(ks)] = ks
        return st.springs, k, st.passive

    # ------------------------------------------------------------------ singularities

    def _leg_serial(self, st: LegStates, rows: np.ndarray) -> np.ndarray:
        """Per-leg serial measure at some poses, shape (len(rows), legs)."""
        U, held = constrained_directions(st.passive[rows])
        A = st.actuated[rows]
        norm = np.linalg.norm(A, axis=-2, keepdims=True)
        B = (np.swapaxes(U, -1, -2) @ (A / np.where(norm > 0, norm, 1.0))) * held[..., :, None]
        s = np.linalg.svd(B, compute_uv=False)  # (rows, legs, min(d, a)), descending
        n_act = np.array([sum(r == "actuated" for r in lg.roles) for lg in self._legs])
        m = np.minimum(np.count_nonzero(held, axis=-1), n_act)
        v = np.take_along_axis(s, np.maximum(m - 1, 0)[..., None], axis=-1)[..., 0]
        return np.where(m == 0, 1.0, np.minimum(v, 1.0))

    def _measures(self, st: LegStates) -> tuple[np.ndarray, np.ndarray]:
        """Serial and parallel singularity measures (class docstring), NaN where unreachable."""
        n = st.reachable.shape[0]
        serial, parallel = np.full(n, np.nan), np.full(n, np.nan)
        ok = st.reachable
        if np.any(ok):
            serial[ok] = self._leg_serial(st, ok).min(axis=1)
            U, held = constrained_directions(st.passive[ok])
            Z = U * held[..., None, :]  # held directions as columns, zero elsewhere
            Z = np.swapaxes(Z, 1, 2).reshape(Z.shape[0], self.dim, -1)
            sv = np.linalg.svd(Z, compute_uv=False)
            parallel[ok] = np.where(sv[:, 0] > 0, sv[:, -1] / np.where(sv[:, 0] > 0, sv[:, 0], 1.0), 0.0)
        return serial, parallel

    def _serial_singularity(self, st: LegStates, i: int) -> str:
        per_leg = self._leg_serial(st, np.array([i]))[0]
        k = int(np.argmin(per_leg))
        return f"leg {k + 1} ({self._legs[k].name}) nearly cannot drive a direction it holds"
