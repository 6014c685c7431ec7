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
complement of range J_p). The built-in :class:`~stiffmap.models.delta.DeltaRobot` and
:class:`~stiffmap.models.prr3.PRR3` are the same assembly fed with closed-form columns;
:func:`legs_toml` writes either as a legs TOML (the package ships them as
``robots/delta.toml`` and ``robots/3prr.toml``), and :class:`LegRobot` read from it equals
the built-in model (tests: 1e-9 relative in K).

The TOML format is in ``docs/models.md`` ("Parallel robots from their legs").
"""

from __future__ import annotations

import json
import math
import re
import tempfile
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated, ClassVar, Literal

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError

from ..errors import InputError
from ..geometry import euler_from_matrix, matrix_from_euler
from ..io import read_text_file
from ..stiffness import MAX_POSITION_MM, MAX_ROTATION_RAD
from .base import (
    SINGULAR_TOL,
    IKSolution,
    LegMechanism,
    as_points,
    check_positive,
    constrained_directions,
)
from .chain import Chain, JointSpec
from .delta import DeltaRobot
from .prr3 import PRR3

__all__ = [
    "LegRobot",
    "LegStates",
    "LegJoint",
    "LegDescription",
    "legs_toml",
    "ROLES",
    "LIMIT_TOL",
    "STIFFNESS_RANGE",
    "MAX_TOML_BYTES",
]

#: The roles of a leg's joints.
ROLES = ("actuated", "passive", "spring")
#: How far (rad or mm) an inverse-kinematics solution may lie beyond a joint limit (roundoff).
LIMIT_TOL = 1e-9
#: Most steps of the inverse kinematics' continuation from a leg's seed.
MAX_STEPS = 100
#: A legs TOML larger than this is refused unread (the Delta's is 3 kB).
MAX_TOML_BYTES = 1024 * 1024
#: The stiffnesses a legs TOML may give (N*mm/rad or N/mm), besides inf (rigid).
STIFFNESS_RANGE = (1e-6, 1e12)

# ---------------------------------------------------------------------- descriptions


@dataclass(frozen=True)
class LegJoint:
    """One joint of a leg: its role and, for a leg given by joints, its kinematics.

    Attributes
    ----------
    name : str
    role : {"actuated", "passive", "spring"}
    stiffness : str or None
        The name of the parameter (``[params]``) that holds its stiffness: actuated and
        spring joints (N*mm/rad for a revolute joint, N/mm for a prismatic one).
    q0 : float or None
        Seed of the inverse kinematics, rad or mm (None: 0); not for spring joints.
    lower, upper : float or None
        Joint limits, rad or mm (None: none, or the URDF's); not for spring joints.
    type : {"revolute", "prismatic"} or None
        None for a URDF leg (its joints come from the URDF).
    axis, xyz_mm, rpy : tuple of 3 floats or None
        As :class:`~stiffmap.models.chain.JointSpec` (axis in the joint's frame; origin in
        the previous joint's frame, mm; roll, pitch, yaw in rad); None for a URDF leg.
    """

    name: str
    role: str
    stiffness: str | None = None
    q0: float | None = None
    lower: float | None = None
    upper: float | None = None
    type: str | None = None
    axis: tuple[float, float, float] | None = None
    xyz_mm: tuple[float, float, float] | None = None
    rpy: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class LegDescription:
    """One leg as the TOML describes it.

    Attributes
    ----------
    name : str
    attach_mm : tuple of dim floats (3 for dim = 6), mm
        The leg's joint on the platform relative to the tool point, base axes (for dim = 6
        in the platform's frame: the platform turns).
    joints : tuple of LegJoint
        Base first (a leg given by joints), or the roles of some of the URDF's joints
        (the others are passive, seed 0).
    tip_offset_mm : tuple of 3 floats, mm
        The platform joint in the last joint's frame (or in ``tip_frame``'s).
    urdf : str or None
        The leg's URDF (relative to the TOML's folder), or None.
    tip_frame : str or None
        The URDF frame carrying the platform joint.
    platform_joint : {"ball", "universal"} or None
        ``dim = 6``: the joint on the platform (None: a ball joint).
    platform_axes : tuple of two 3-tuples or None
        A universal platform joint's axes: the first in the frame of the leg's last joint (or
        ``tip_frame``), the second in the platform's frame.
    """

    name: str
    attach_mm: tuple[float, ...]
    joints: tuple[LegJoint, ...]
    tip_offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    urdf: str | None = None
    tip_frame: str | None = None
    platform_joint: str | None = None
    platform_axes: tuple[tuple[float, ...], ...] | None = None


# ---------------------------------------------------------------------- the TOML schema


def _number(v):
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ValueError("expected a number")
    return float(v)


def _vector(counts: tuple[int, ...], words: str, bound: float, unit: str):
    def check(v):
        if (
            not isinstance(v, list | tuple)
            or len(v) not in counts
            or any(isinstance(x, bool) or not isinstance(x, int | float) for x in v)
        ):
            raise ValueError(f"expected {words} numbers")
        if not all(math.isfinite(x) for x in v):
            raise ValueError(f"expected {words} finite numbers")
        if any(abs(x) > bound for x in v):
            raise ValueError(f"expected {words} numbers within +-{bound:g} {unit}".rstrip())
        return tuple(float(x) for x in v)

    return BeforeValidator(check)


def _bounded(v):
    v = _number(v)
    if math.isfinite(v) and abs(v) > MAX_POSITION_MM:
        raise ValueError(f"expected a number within +-{MAX_POSITION_MM:g} (rad or mm)")
    return v


_Num = Annotated[float, BeforeValidator(_number)]
_Coord = Annotated[float, BeforeValidator(_bounded)]
_Vec3 = Annotated[tuple[float, ...], _vector((3,), "three", MAX_POSITION_MM, "mm")]
_VecD = Annotated[tuple[float, ...], _vector((2, 3), "two or three", MAX_POSITION_MM, "mm")]
_Rpy = Annotated[tuple[float, ...], _vector((3,), "three", MAX_ROTATION_RAD * 16, "rad")]
_Axis = Annotated[tuple[float, ...], _vector((3,), "three", math.inf, "")]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


class _JointIn(_Strict):
    name: str = Field(min_length=1)
    role: Literal["actuated", "passive", "spring"]
    stiffness: str | None = None
    q0: _Coord | None = None
    lower: _Coord | None = None
    upper: _Coord | None = None
    type: Literal["revolute", "prismatic"] | None = None
    axis: _Axis | None = None
    xyz_mm: _Vec3 | None = None
    rpy: _Rpy | None = None


class _LegIn(_Strict):
    name: str | None = Field(default=None, min_length=1)
    attach_mm: _VecD
    tip_offset_mm: _Vec3 | None = None
    urdf: str | None = Field(default=None, min_length=1)
    tip_frame: str | None = Field(default=None, min_length=1)
    platform_joint: Literal["ball", "universal"] | None = None
    platform_axes: list[_Axis] | None = Field(default=None, min_length=2, max_length=2)
    joints: list[_JointIn] = Field(min_length=1)


class _RobotIn(_Strict):
    name: str | None = Field(default=None, min_length=1)
    dim: Literal[2, 3, 6]
    singular_tol: _Num = SINGULAR_TOL
    params: dict[str, _Num]
    legs: list[_LegIn] = Field(min_length=1)


_TABLES = {"": _RobotIn, "legs": _LegIn, "joints": _JointIn}


def _key(loc) -> str:
    """A pydantic location as the TOML's key: ``legs[2].joints[1].axis`` (tables numbered from 1)."""
    out = ""
    for x in loc:
        out += f"[{x + 1}]" if isinstance(x, int) else ("." if out else "") + str(x)
    return out


def _problem(err: dict) -> str:
    loc = tuple(err["loc"])
    kind = err["type"]
    if kind == "extra_forbidden":
        table = next((str(x) for x in reversed(loc[:-1]) if isinstance(x, str)), "")
        known = ", ".join(_TABLES[table].model_fields) if table in _TABLES else ""
        return f"{_key(loc)}: unknown key" + (f" (expected one of {known})" if known else "")
    if kind == "missing":
        return f"{_key(loc)}: missing key"
    msg = err["msg"].removeprefix("Value error, ")
    if "input" in err and not isinstance(err["input"], dict):
        shown = repr(err["input"])
        msg += f", got {shown[:57] + '...' if len(shown) > 60 else shown}"
    return f"{_key(loc)}: {msg}"


_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def _check_platform_joint(lg: _LegIn, dim: int, where: str, fail) -> None:
    """``platform_joint`` and ``platform_axes``: dim = 6 only; a universal joint has two axes."""
    for key in ("platform_joint", "platform_axes"):
        if dim != 6 and getattr(lg, key) is not None:
            fail(f"{where}.{key}", f"only for dim = 6 (a platform that turns); dim = {dim} holds it")
    if lg.platform_joint == "universal" and lg.platform_axes is None:
        fail(
            f"{where}.platform_axes",
            "missing key: a universal platform joint gives its two axes (the leg's, the platform's)",
        )
    if lg.platform_joint != "universal" and lg.platform_axes is not None:
        fail(f"{where}.platform_axes", 'only for platform_joint = "universal"')
    for j, axis in enumerate(lg.platform_axes or (), start=1):
        if max(abs(x) for x in axis) == 0:
            fail(f"{where}.platform_axes[{j}]", "expected three numbers, not all zero")


def _descriptions(data: dict, source: str, default_name: str):
    """Validate a parsed legs TOML: (name, dim, singular_tol, params, legs), else InputError."""
    try:
        spec = _RobotIn.model_validate(data)
    except ValidationError as e:
        raise InputError("; ".join(dict.fromkeys(_problem(x) for x in e.errors())), source=source) from None

    def fail(key: str, msg: str):
        raise InputError(f"{key}: {msg}", source=source)

    for pname, value in spec.params.items():
        if not _NAME.match(pname):
            fail(f"params.{pname}", "a parameter name is letters, digits and _ (not starting with a digit)")
        if math.isnan(value) or value <= 0:
            fail(f"params.{pname}", f"a stiffness must be positive (or inf for rigid), got {value!r}")
        if math.isfinite(value) and not (STIFFNESS_RANGE[0] <= value <= STIFFNESS_RANGE[1]):
            fail(
                f"params.{pname}",
                f"a stiffness between {STIFFNESS_RANGE[0]:g} and {STIFFNESS_RANGE[1]:g} N*mm/rad or N/mm "
                f"(or inf for rigid), got {value!r}",
            )
    used: dict[str, str] = {}
    legs = []
    leg_names: set[str] = set()
    for i, lg in enumerate(spec.legs, start=1):
        where = f"legs[{i}]"
        if spec.dim == 6 and len(lg.attach_mm) != 3:
            fail(
                f"{where}.attach_mm",
                f"expected 3 numbers (dim = 6: the leg's joint in the platform's frame, mm), "
                f"got {len(lg.attach_mm)}",
            )
        if spec.dim != 6 and len(lg.attach_mm) != spec.dim:
            fail(
                f"{where}.attach_mm",
                f"expected {spec.dim} numbers (dim = {spec.dim}), got {len(lg.attach_mm)}",
            )
        _check_platform_joint(lg, spec.dim, where, fail)
        lname = lg.name or f"leg{i}"
        if lname in leg_names:
            fail(f"{where}.name", f"leg {lname!r} is named twice")
        leg_names.add(lname)
        if lg.urdf is not None and lg.tip_frame is None:
            fail(f"{where}.tip_frame", "missing key: a URDF leg names the frame of its platform joint")
        if lg.urdf is None and lg.tip_frame is not None:
            fail(
                f"{where}.tip_frame",
                "only for a URDF leg (urdf = ...); a leg given by joints ends at its last joint",
            )
        joints = []
        seen: set[str] = set()
        for j, jt in enumerate(lg.joints, start=1):
            jw = f"{where}.joints[{j}]"
            if jt.name in seen:
                fail(f"{jw}.name", f"joint {jt.name!r} is named twice in {lname}")
            seen.add(jt.name)
            kin = {"type": jt.type, "axis": jt.axis, "xyz_mm": jt.xyz_mm, "rpy": jt.rpy}
            if lg.urdf is not None:
                for k, v in kin.items():
                    if v is not None:
                        fail(
                            f"{jw}.{k}",
                            "a URDF leg's joints take their kinematics from the URDF: give name, role, "
                            "stiffness, q0, lower, upper",
                        )
            else:
                for k in ("type", "axis"):
                    if kin[k] is None:
                        fail(f"{jw}.{k}", "missing key")
                big = max(abs(x) for x in jt.axis)
                if big == 0:
                    fail(f"{jw}.axis", "expected three numbers, not all zero")
                jt = jt.model_copy(update={"axis": tuple(x / big for x in jt.axis)})
            if jt.role == "passive":
                if jt.stiffness is not None:
                    fail(f"{jw}.stiffness", "a passive joint is free: no stiffness")
            else:
                if jt.stiffness is None:
                    fail(
                        f"{jw}.stiffness", f"missing key: an {jt.role} joint names its stiffness in [params]"
                    )
                if jt.stiffness not in spec.params:
                    known = ", ".join(spec.params) or "none"
                    fail(f"{jw}.stiffness", f"{jt.stiffness!r} is not in [params] ({known})")
                if jt.role == "actuated" or jt.stiffness not in used:
                    used[jt.stiffness] = jt.role
            if jt.role == "spring":
                for k in ("q0", "lower", "upper"):
                    if getattr(jt, k) is not None:
                        fail(
                            f"{jw}.{k}",
                            "a spring joint stays at rest (q = 0) in the kinematics: no q0, lower, upper",
                        )
            lo = -math.inf if jt.lower is None else jt.lower
            hi = math.inf if jt.upper is None else jt.upper
            if math.isnan(lo) or math.isnan(hi) or lo > hi:
                fail(f"{jw}.upper", f"limits must satisfy lower <= upper, got [{lo!r}, {hi!r}]")
            if jt.q0 is not None and not (lo <= jt.q0 <= hi):
                fail(f"{jw}.q0", f"the seed {jt.q0!r} is outside the limits [{lo!r}, {hi!r}]")
            if jt.q0 is not None and not math.isfinite(jt.q0):
                fail(f"{jw}.q0", f"expected a finite number, got {jt.q0!r}")
            joints.append(LegJoint(**jt.model_dump()))
        legs.append(
            LegDescription(
                name=lname,
                attach_mm=lg.attach_mm,
                joints=tuple(joints),
                tip_offset_mm=lg.tip_offset_mm or (0.0, 0.0, 0.0),
                urdf=lg.urdf,
                tip_frame=lg.tip_frame,
                platform_joint=lg.platform_joint,
                platform_axes=None if lg.platform_axes is None else tuple(lg.platform_axes),
            )
        )
    for pname in spec.params:
        if pname not in used:
            fail(f"params.{pname}", "no joint refers to it")
        if used[pname] == "actuated" and math.isinf(spec.params[pname]):
            fail(f"params.{pname}", "an actuated joint's stiffness must be finite")
    if "actuated" not in used.values():
        fail("legs", 'no actuated joint: give at least one joint role = "actuated"')
    tol = spec.singular_tol
    if not (0 <= tol < 1):
        fail("singular_tol", f"expected a number in [0, 1), got {tol!r}")
    return spec.name or default_name, spec.dim, tol, dict(spec.params), tuple(legs)


# ---------------------------------------------------------------------- writing


def _num(v: float) -> str:
    """A float as TOML, 15 significant digits (roundoff below 1e-12 written as 0)."""
    v = float(v)
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    if abs(v) < 1e-12:
        return "0.0"
    t = f"{v:.15g}"
    return t if any(c in t for c in ".e") else t + ".0"


def _vec(v) -> str:
    return "[" + ", ".join(_num(x) for x in v) + "]"


def _toml_text(
    name: str | None,
    dim: int,
    params: dict[str, float],
    legs: tuple[LegDescription, ...],
    singular_tol: float,
    header: str = "",
) -> str:
    out = [f"# {line}".rstrip() for line in header.splitlines()]
    if out:
        out.append("")
    if name is not None:
        out.append(f"name = {json.dumps(name)}")
    out += [f"dim = {dim}", f"singular_tol = {_num(singular_tol)}", "", "[params]"]
    out += [f"{k} = {_num(v)}" for k, v in params.items()]
    for lg in legs:
        out += ["", "[[legs]]", f"name = {json.dumps(lg.name)}", f"attach_mm = {_vec(lg.attach_mm)}"]
        if lg.urdf is not None:
            out += [f"urdf = {json.dumps(lg.urdf)}", f"tip_frame = {json.dumps(lg.tip_frame)}"]
        out.append(f"tip_offset_mm = {_vec(lg.tip_offset_mm)}")
        if lg.platform_joint is not None:
            out.append(f"platform_joint = {json.dumps(lg.platform_joint)}")
        if lg.platform_axes is not None:
            out.append("platform_axes = [" + ", ".join(_vec(a) for a in lg.platform_axes) + "]")
        for jt in lg.joints:
            out += ["", "[[legs.joints]]", f"name = {json.dumps(jt.name)}"]
            if jt.type is not None:
                out.append(f"type = {json.dumps(jt.type)}")
            for k in ("axis", "xyz_mm", "rpy"):
                if getattr(jt, k) is not None:
                    out.append(f"{k} = {_vec(getattr(jt, k))}")
            out.append(f"role = {json.dumps(jt.role)}")
            if jt.stiffness is not None:
                out.append(f"stiffness = {json.dumps(jt.stiffness)}")
            for k in ("q0", "lower", "upper"):
                if getattr(jt, k) is not None:
                    out.append(f"{k} = {_num(getattr(jt, k))}")
    return "\n".join(out) + "\n"


def _yaw(phi: float) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_y(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _delta_description(m: DeltaRobot) -> tuple[dict, tuple[LegDescription, ...]]:
    """The Delta's legs: actuator, arm spring, elbow ball (y, x, z), forearm spring."""
    R, r, a, b = m.base_radius, m.platform_radius, m.arm_length, m.forearm_length
    seed = m.forward_kinematics([0.5, 0.5, 0.5])  # a central pose on the z axis
    L = m.legs(seed)
    legs, h = [], math.pi / 2
    for i, phi in enumerate(m.leg_angles):
        th = float(L.theta[0, i])
        # Ball joint: n = R_leg Ry(theta) Ry(alpha) Rx(beta) (-z), so n.t = a cos(alpha) cos(beta):
        # alpha, beta within +-90 deg is the elbow-out branch (and keeps the ball's lock, n along
        # the actuator axis, out of reach).
        v = (_yaw(phi) @ _rot_y(th)).T @ L.n[0, i]
        alpha, beta = math.atan2(-v[0], -v[2]), math.asin(max(-1.0, min(1.0, v[1])))
        e = (math.cos(phi), math.sin(phi), 0.0)
        joints = (
            LegJoint(
                "actuator",
                "actuated",
                "k_theta",
                th,
                None,
                None,
                "revolute",
                (0.0, 1.0, 0.0),
                (R * e[0], R * e[1], 0.0),
                (0.0, 0.0, phi),
            ),
            LegJoint("arm", "spring", "k_arm", type="prismatic", axis=(0.0, 0.0, -1.0), xyz_mm=(a, 0.0, 0.0)),
            LegJoint("elbow_y", "passive", None, alpha, -h, h, "revolute", (0.0, 1.0, 0.0)),
            LegJoint("elbow_x", "passive", None, beta, -h, h, "revolute", (1.0, 0.0, 0.0)),
            LegJoint("elbow_z", "passive", q0=0.0, type="revolute", axis=(0.0, 0.0, 1.0)),
            LegJoint("forearm", "spring", "k_forearm", type="prismatic", axis=(0.0, 0.0, -1.0)),
        )
        legs.append(LegDescription(f"leg{i + 1}", (r * e[0], r * e[1], 0.0), joints, (0.0, 0.0, -b)))
    params = {"k_theta": m.k_theta, "k_arm": m.k_arm, "k_forearm": m.k_forearm}
    return params, tuple(legs)


def _prr3_description(m: PRR3) -> tuple[dict, tuple[LegDescription, ...]]:
    """The 3PRR's legs: slider, bearing spring, pin, rod spring, pin at the tool."""
    V, u = m.vertices, m.rail_directions
    l0 = min(max(m.rail_length - m.L, 0.0), m.rail_length)  # the centre's slider position
    legs = []
    for i in range(3):
        gamma = math.atan2(u[i, 1], u[i, 0])
        joints = (
            LegJoint(
                "slider",
                "actuated",
                "kj",
                l0,
                0.0,
                m.rail_length,
                "prismatic",
                (1.0, 0.0, 0.0),
                (float(V[i, 0]), float(V[i, 1]), 0.0),
                (0.0, 0.0, gamma),
            ),
            LegJoint("bearing", "spring", "kb", type="prismatic", axis=(0.0, 1.0, 0.0)),
            LegJoint(
                "pin_slider", "passive", None, 0.0, -math.pi / 2, math.pi / 2, "revolute", (0.0, 0.0, 1.0)
            ),
            LegJoint("rod", "spring", "k_rod", type="prismatic", axis=(1.0, 0.0, 0.0)),
            LegJoint(
                "pin_tool", "passive", q0=0.0, type="revolute", axis=(0.0, 0.0, 1.0), xyz_mm=(m.L, 0.0, 0.0)
            ),
        )
        legs.append(LegDescription(f"leg{i + 1}", (0.0, 0.0), joints))
    params = {"kj": m.kj, "kb": m.kb, "k_rod": m.E * m.area / m.L}
    return params, tuple(legs)


_DELTA_HEADER = """\
The Delta robot of stiffmap.models.delta (DeltaRobot) described by its legs, the virtual
joint method's input (docs/models.md, "Parallel robots from their legs"). Written by
stiffmap.models.legs.legs_toml(DeltaRobot()); LegRobot.from_toml reads it.
Each leg: the actuator (k_theta, N*mm/rad), the arm's transverse compliance at the elbow
as a virtual prismatic spring (k_arm, N/mm), the elbow as a ball joint (three revolute
joints; limits +-90 deg on the first two: the elbow-out branch), the forearm's axial
compliance (k_forearm, N/mm). inf = rigid."""

_PRR3_HEADER = """\
The planar 3PRR of stiffmap.models.prr3 (PRR3) described by its legs, the virtual joint
method's input (docs/models.md, "Parallel robots from their legs"). Written by
stiffmap.models.legs.legs_toml(PRR3()); LegRobot.from_toml reads it.
Each leg: the slider on its rail (kj, N/mm; limits the rail), the bearing across the rail
(kb), the pin at the slider (limits +-90 deg: the rod leans towards the centre), the rod's
axial stiffness (k_rod = E area / L, N/mm), the pin at the tool."""


def legs_toml(model: DeltaRobot | PRR3 | LegRobot) -> str:
    """The legs TOML that describes a robot with its current parameters.

    Parameters
    ----------
    model : DeltaRobot, PRR3 or LegRobot
        A built-in model (its legs' joints written from its geometry, the seeds from its
        closed-form inverse kinematics at a central pose) or a :class:`LegRobot` (its
        description, with its current parameters).

    Returns
    -------
    str
        TOML text (``LegRobot.from_toml_text`` reads it back). The package's
        ``robots/delta.toml`` and ``robots/3prr.toml`` are this for the default models.
    """
    if isinstance(model, DeltaRobot):
        params, legs = _delta_description(model)
        return _toml_text(None, 3, params, legs, model.singular_tol, _DELTA_HEADER)
    if isinstance(model, PRR3):
        params, legs = _prr3_description(model)
        return _toml_text(None, 2, params, legs, model.singular_tol, _PRR3_HEADER)
    if isinstance(model, LegRobot):
        return _toml_text(model.name, model.dim, model.params(), model.description, model.singular_tol)
    raise TypeError(f"legs_toml takes a DeltaRobot, a PRR3 or a LegRobot, got {type(model).__name__}")


# ---------------------------------------------------------------------- building the legs


def _placement(xyz, rpy) -> tuple[np.ndarray, np.ndarray]:
    return matrix_from_euler(np.asarray(rpy, dtype=float)), np.asarray(xyz, dtype=float)


def _without_springs(joints: tuple[LegJoint, ...], tip) -> tuple[list[JointSpec], np.ndarray]:
    """The leg's joints with its springs at rest folded into the next joint's origin (or the tip)."""
    Rp, tp = np.eye(3), np.zeros(3)
    out = []
    for jt in joints:
        R, t = _placement(jt.xyz_mm or (0.0, 0.0, 0.0), jt.rpy or (0.0, 0.0, 0.0))
        R, t = Rp @ R, Rp @ t + tp
        if jt.role == "spring":
            Rp, tp = R, t
            continue
        out.append(JointSpec(jt.name, jt.type, jt.axis, tuple(t), tuple(euler_from_matrix(R))))
        Rp, tp = np.eye(3), np.zeros(3)
    return out, Rp @ np.asarray(tip, dtype=float) + tp


def _urdf_without_springs(path: Path, springs: set[str], tip_frame: str, tip) -> Chain:
    """The URDF's chain with its spring joints turned fixed (at rest), read through a temporary copy."""
    root = ET.fromstring(read_text_file(path, "URDF file"))
    for j in root.iter("joint"):
        if j.get("name") in springs:
            j.set("type", "fixed")
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / path.name
        p.write_text(ET.tostring(root, encoding="unicode"), encoding="utf-8")
        return Chain.from_urdf(p, tip_frame, tip)


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
        rigid, tip = _without_springs(desc.joints, desc.tip_offset_mm)
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
            _urdf_without_springs(path, springs, desc.tip_frame, desc.tip_offset_mm) if springs else chain
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
    return _Leg(
        desc.name, chain, ik_chain, roles, stiffness, free, q0a, *lims, target, tip0, max(0.1 * size, 1.0)
    )


# ---------------------------------------------------------------------- the robot


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
    """

    q: np.ndarray
    joints: tuple[np.ndarray, ...]
    reachable: np.ndarray
    reasons: tuple[str, ...]
    springs: np.ndarray
    actuated: np.ndarray
    passive: np.ndarray


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
    #: for 6) says so here; :meth:`from_toml` builds it for such a file.
    _FOR_DIM: ClassVar[int | None] = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls._FOR_DIM is not None:
            _BY_DIM[cls._FOR_DIM] = cls

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_toml(cls, path) -> LegRobot:
        """Read a legs TOML (``docs/models.md``); URDF paths in it are relative to its folder.

        Raises
        ------
        InputError
            Naming the file and the key (``legs[2].joints[1].axis: expected three numbers``),
            tables numbered from 1; a URDF's problems name the URDF.
        """
        p = Path(path)
        try:
            size = p.stat().st_size
        except OSError:
            size = 0  # read_text_file says why it cannot be read
        if size > MAX_TOML_BYTES:
            raise InputError(
                f"{size} bytes; a legs TOML of more than {MAX_TOML_BYTES} bytes is not one", source=str(p)
            )
        return cls.from_toml_text(
            read_text_file(p, "legs TOML file"), source=str(p), base_dir=p.parent, default_name=p.stem
        )

    @classmethod
    def from_toml_text(
        cls, text: str, *, source: str = "legs.toml", base_dir=".", default_name: str = "legs"
    ) -> LegRobot:
        """:meth:`from_toml` of a TOML text (``source`` names it in messages)."""
        try:
            data = tomllib.loads(text.removeprefix("\ufeff"))
        except tomllib.TOMLDecodeError as e:
            raise InputError(f"not valid TOML: {e}", source=source) from None
        except RecursionError:
            raise InputError("not valid TOML: arrays or tables nested too deeply", source=source) from None
        except ValueError:  # an integer of thousands of digits
            raise InputError(
                "not a usable TOML file: a number has thousands of digits", source=source
            ) from None
        name, dim, tol, params, legs = _descriptions(data, source, default_name)
        built = tuple(
            _build_leg(d, k, dim, Path(base_dir), source, name) for k, d in enumerate(legs, start=1)
        )
        cls = _BY_DIM.get(dim, cls) if cls is LegRobot else cls  # dim 6: a platform that turns
        return cls(name, dim, legs, tuple(params), tuple(params.values()), tol, source, built)

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
        """The ``[params]`` names (``with_params``, fitting, ``--param``)."""
        return self.param_keys

    def params(self) -> dict[str, float]:
        """The stiffnesses of ``[params]`` (N*mm/rad or N/mm)."""
        return dict(zip(self.param_keys, self.param_values, strict=True))

    def with_params(self, **params) -> LegRobot:
        """A copy with some stiffnesses (or ``singular_tol``) changed; unknown names raise ValueError."""
        bad = sorted(set(params) - set(self.param_keys) - {"singular_tol"})
        if bad:
            raise ValueError(
                f"unknown parameter(s) {', '.join(bad)} of {self.name}; valid: {', '.join(self.param_keys)}"
            )
        tol = params.pop("singular_tol", self.singular_tol)
        vals = tuple(params.get(k, v) for k, v in zip(self.param_keys, self.param_values, strict=True))
        return replace(self, param_values=vals, singular_tol=tol)

    @property
    def chains(self) -> tuple[Chain, ...]:
        """Each leg's chain, base to its platform joint (every joint, springs included)."""
        return tuple(lg.chain for lg in self._legs)

    @property
    def roles(self) -> tuple[tuple[str, ...], ...]:
        """Each leg's joints' roles, in its chain's order."""
        return tuple(lg.roles for lg in self._legs)

    def describe(self) -> str:
        """One line: the legs and the parameters."""
        ps = ", ".join(f"{k}={v:g}" for k, v in self.params().items())
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
            if bad:
                reasons[i] = "unreachable: " + "; ".join(bad)
        reachable = np.array([r == "" for r in reasons], dtype=bool)
        for k in range(nl):
            joints[k][~reachable] = np.nan
        for arr in (springs, actuated, passive):
            arr[~reachable] = np.nan
        q = np.concatenate(
            [
                joints[k][:, [j for j, r in enumerate(lg.roles) if r == "actuated"]]
                for k, lg in enumerate(self._legs)
            ],
            axis=1,
        )
        return LegStates(q, tuple(joints), reachable, tuple(reasons), springs, actuated, passive)

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
