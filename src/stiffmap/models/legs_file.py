"""The legs TOML of a parallel robot: its schema, reading it into descriptions, writing it.

The I/O module of :mod:`stiffmap.models.legs` (docs/architecture.md: cores read files only
through their I/O modules): :func:`read_legs_file` reads and checks a legs TOML
(``docs/models.md``, "Parallel robots from their legs") into a :class:`LegsFile` -- plain
data, the robot's name, dimension, parameters and its legs (:class:`LegDescription`, each a
list of :class:`LegJoint` and its flexible links, ``[[legs.links]]``) --, which
:class:`~stiffmap.models.legs.LegRobot` builds the mechanism from; :func:`legs_text` writes
one back. Every problem is an :class:`~stiffmap.errors.InputError` naming the file and the key
(``legs[2].joints[1].axis: expected three numbers``), tables numbered from 1.
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError

from ..errors import InputError
from ..geometry import euler_from_matrix
from ..io import read_text_file
from ..stiffness import MAX_POSITION_MM, MAX_ROTATION_RAD
from .base import SINGULAR_TOL, STIFFNESS_RANGE
from .links import LinkSpring
from .robot_files import links_from_tables

__all__ = [
    "LegJoint",
    "LegDescription",
    "LegsFile",
    "read_legs_file",
    "parse_legs_text",
    "legs_text",
    "ROLES",
    "STIFFNESS_RANGE",
    "MAX_TOML_BYTES",
]

#: The roles of a leg's joints.
ROLES = ("actuated", "passive", "spring")
#: A legs TOML larger than this is refused unread (the Delta's is 3 kB).
MAX_TOML_BYTES = 1024 * 1024

# ---------------------------------------------------------------------- the data


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
    links : tuple of LinkSpring
        The leg's flexible links (``[[legs.links]]``; :mod:`~stiffmap.models.links`): each
        on the link a joint of the leg moves (``LinkSpring.link``: that joint's name, or for
        a URDF leg a URDF link).
    """

    name: str
    attach_mm: tuple[float, ...]
    joints: tuple[LegJoint, ...]
    tip_offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    urdf: str | None = None
    tip_frame: str | None = None
    platform_joint: str | None = None
    platform_axes: tuple[tuple[float, ...], ...] | None = None
    links: tuple[LinkSpring, ...] = ()


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
    links: list[Any] | None = None


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


def _fail_in(source: str):
    def fail(key: str, msg: str):
        raise InputError(f"{key}: {msg}", source=source)

    return fail


def _check_params(params: dict[str, float], fail) -> None:
    """``[params]``: names, and stiffnesses positive within :data:`STIFFNESS_RANGE` (or inf)."""
    for pname, value in params.items():
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


def _check_leg(lg: _LegIn, dim: int, where: str, fail) -> None:
    """A leg's own keys: ``attach_mm`` of the right length, its platform joint, URDF and tip frame."""
    if dim == 6 and len(lg.attach_mm) != 3:
        fail(
            f"{where}.attach_mm",
            f"expected 3 numbers (dim = 6: the leg's joint in the platform's frame, mm), "
            f"got {len(lg.attach_mm)}",
        )
    if dim != 6 and len(lg.attach_mm) != dim:
        fail(f"{where}.attach_mm", f"expected {dim} numbers (dim = {dim}), got {len(lg.attach_mm)}")
    _check_platform_joint(lg, dim, where, fail)
    if lg.urdf is not None and lg.tip_frame is None:
        fail(f"{where}.tip_frame", "missing key: a URDF leg names the frame of its platform joint")
    if lg.urdf is None and lg.tip_frame is not None:
        fail(
            f"{where}.tip_frame",
            "only for a URDF leg (urdf = ...); a leg given by joints ends at its last joint",
        )


def _check_joint_kinematics(jt: _JointIn, urdf: bool, jw: str, fail) -> _JointIn:
    """A joint's type, axis, xyz_mm, rpy: from the URDF (none given) or given (axis normalised)."""
    kin = {"type": jt.type, "axis": jt.axis, "xyz_mm": jt.xyz_mm, "rpy": jt.rpy}
    if urdf:
        for k, v in kin.items():
            if v is not None:
                fail(
                    f"{jw}.{k}",
                    "a URDF leg's joints take their kinematics from the URDF: give name, role, "
                    "stiffness, q0, lower, upper",
                )
        return jt
    for k in ("type", "axis"):
        if kin[k] is None:
            fail(f"{jw}.{k}", "missing key")
    big = max(abs(x) for x in jt.axis)
    if big == 0:
        fail(f"{jw}.axis", "expected three numbers, not all zero")
    return jt.model_copy(update={"axis": tuple(x / big for x in jt.axis)})


def _check_joint_role(jt: _JointIn, params: dict[str, float], used: dict[str, str], jw: str, fail) -> None:
    """A joint's stiffness (by role; recorded in ``used``), and a spring's absent seed and limits."""
    if jt.role == "passive":
        if jt.stiffness is not None:
            fail(f"{jw}.stiffness", "a passive joint is free: no stiffness")
    else:
        if jt.stiffness is None:
            fail(f"{jw}.stiffness", f"missing key: an {jt.role} joint names its stiffness in [params]")
        if jt.stiffness not in params:
            known = ", ".join(params) or "none"
            fail(f"{jw}.stiffness", f"{jt.stiffness!r} is not in [params] ({known})")
        if jt.role == "actuated" or jt.stiffness not in used:
            used[jt.stiffness] = jt.role
    if jt.role == "spring":
        for k in ("q0", "lower", "upper"):
            if getattr(jt, k) is not None:
                fail(
                    f"{jw}.{k}", "a spring joint stays at rest (q = 0) in the kinematics: no q0, lower, upper"
                )
    lo = -math.inf if jt.lower is None else jt.lower
    hi = math.inf if jt.upper is None else jt.upper
    if math.isnan(lo) or math.isnan(hi) or lo > hi:
        fail(f"{jw}.upper", f"limits must satisfy lower <= upper, got [{lo!r}, {hi!r}]")
    if jt.q0 is not None and not (lo <= jt.q0 <= hi):
        fail(f"{jw}.q0", f"the seed {jt.q0!r} is outside the limits [{lo!r}, {hi!r}]")
    if jt.q0 is not None and not math.isfinite(jt.q0):
        fail(f"{jw}.q0", f"expected a finite number, got {jt.q0!r}")


def _leg_joints(lg: _LegIn, lname: str, params, used, where: str, fail) -> tuple[LegJoint, ...]:
    joints = []
    seen: set[str] = set()
    for j, jt in enumerate(lg.joints, start=1):
        jw = f"{where}.joints[{j}]"
        if jt.name in seen:
            fail(f"{jw}.name", f"joint {jt.name!r} is named twice in {lname}")
        seen.add(jt.name)
        jt = _check_joint_kinematics(jt, lg.urdf is not None, jw, fail)
        _check_joint_role(jt, params, used, jw, fail)
        joints.append(LegJoint(**jt.model_dump()))
    return tuple(joints)


#: The keys of a ``[[legs.links]]`` table (docs/models.md): as a links TOML's ``[[links]]``
#: (:func:`~stiffmap.models.robot_files.read_links_toml`), placed by the joint it follows.
LEG_LINK_KEYS = ("after", "link", "name", "xyz_mm", "rpy", "beam", "compliance")


def _leg_links(lg: _LegIn, lname: str, joints: tuple[LegJoint, ...], where: str, source: str, fail):
    """A leg's ``[[legs.links]]`` as LinkSpring (``link``: the joint's name, or a URDF link)."""
    if lg.links is None:
        return ()
    names = [jt.name for jt in joints]
    tables = []
    for i, t in enumerate(lg.links, start=1):
        lw = f"{where}.links[{i}]"
        if not isinstance(t, dict):
            fail(lw, "expected a table (after = JOINT, beam or compliance)")
        unknown = sorted(set(t) - set(LEG_LINK_KEYS))
        if unknown:
            fail(f"{lw}.{unknown[0]}", f"unknown key; valid: {', '.join(LEG_LINK_KEYS)}")
        own, other = ("link", "after") if lg.urdf is not None else ("after", "link")
        if other in t:
            fail(
                f"{lw}.{other}",
                "only for a leg given by joints (the joint the link follows)"
                if other == "after"
                else "only for a URDF leg; a leg given by joints names the joint it follows: after = ...",
            )
        after = t.get(own)
        if lg.urdf is None and not (isinstance(after, str) and after in names):
            fail(
                f"{lw}.after",
                f"expected the name of one of {lname}'s joints ({', '.join(names)}), the one moving the "
                f"link that bends, got {after!r}",
            )
        if not isinstance(after, str) or not after:
            fail(f"{lw}.link", f"expected the name of the URDF link that bends, got {after!r}")
        rest = {k: v for k, v in t.items() if k not in ("after", "link")}
        tables.append({"link": after, "name": re.sub(r"\W", "_", f"{lname}_{after}"), **rest})
    return links_from_tables(tables, source, f"{where}.links")


def _check_link_names(legs: tuple[LegDescription, ...], params: dict[str, float], fail) -> None:
    """Links of one name share their parameters: the same kind and values; none a [params] name."""
    first: dict[str, LinkSpring] = {}
    for lk in (lk for lg in legs for lk in lg.links):
        table = lk.where.rsplit(": ", 1)[-1]
        for p in lk.param_names():
            if p in params:
                fail(f"{table}.name", f"its parameter {p} is also in [params]: name the link otherwise")
        other = first.setdefault(lk.name, lk)
        if other is not lk and (other.param_names() != lk.param_names() or other.params() != lk.params()):
            fail(
                f"{table}.name",
                f"{lk.name!r} is also {other.where.rsplit(': ', 1)[-1]}'s name: links of one name share "
                f"their parameters ({', '.join(lk.param_names())}), so they need the same kind and values",
            )


def _geometry(leg: LegDescription) -> tuple:
    """What places a leg and what acts in it: its platform joint, its URDF, its joints' kinematics
    and roles (not their stiffnesses, seeds or limits). One URDF's chain listed as several legs,
    each with another joint actuated, is several legs: a Cartesian stage as three."""
    joints = tuple((j.name, j.role, j.type, j.axis, j.xyz_mm, j.rpy) for j in leg.joints)
    return (
        leg.attach_mm,
        leg.tip_offset_mm,
        leg.urdf,
        leg.tip_frame,
        leg.platform_joint,
        leg.platform_axes,
        joints,
    )


def _check_distinct(legs: list[LegDescription], fail) -> None:
    """Two legs in the same place (a leg copied and not edited) would make the model count one
    leg twice, or a platform singular everywhere: refused, naming both."""
    seen: dict[tuple, int] = {}
    for i, leg in enumerate(legs, start=1):
        first = seen.setdefault(_geometry(leg), i)
        if first != i:
            fail(
                f"legs[{i}]",
                f"leg {leg.name!r} is in the same place as legs[{first}] ({legs[first - 1].name!r}): "
                "the same attach_mm, tip_offset_mm and joints (a copied leg not edited?)",
            )


def _check_used(params: dict[str, float], used: dict[str, str], fail) -> None:
    for pname in params:
        if pname not in used:
            fail(f"params.{pname}", "no joint refers to it")
        if used[pname] == "actuated" and math.isinf(params[pname]):
            fail(f"params.{pname}", "an actuated joint's stiffness must be finite")
    if "actuated" not in used.values():
        fail("legs", 'no actuated joint: give at least one joint role = "actuated"')


def _descriptions(data: dict, source: str, default_name: str):
    """Validate a parsed legs TOML: (name, dim, singular_tol, params, legs), else InputError."""
    try:
        spec = _RobotIn.model_validate(data)
    except ValidationError as e:
        raise InputError("; ".join(dict.fromkeys(_problem(x) for x in e.errors())), source=source) from None
    fail = _fail_in(source)
    _check_params(spec.params, fail)
    used: dict[str, str] = {}
    legs = []
    leg_names: set[str] = set()
    for i, lg in enumerate(spec.legs, start=1):
        where = f"legs[{i}]"
        _check_leg(lg, spec.dim, where, fail)
        lname = lg.name or f"leg{i}"
        if lname in leg_names:
            fail(f"{where}.name", f"leg {lname!r} is named twice")
        leg_names.add(lname)
        joints = _leg_joints(lg, lname, spec.params, used, where, fail)
        legs.append(
            LegDescription(
                name=lname,
                attach_mm=lg.attach_mm,
                joints=joints,
                tip_offset_mm=lg.tip_offset_mm or (0.0, 0.0, 0.0),
                urdf=lg.urdf,
                tip_frame=lg.tip_frame,
                platform_joint=lg.platform_joint,
                platform_axes=None if lg.platform_axes is None else tuple(lg.platform_axes),
                links=_leg_links(lg, lname, joints, where, source, fail),
            )
        )
    _check_used(spec.params, used, fail)
    _check_distinct(legs, fail)
    _check_link_names(tuple(legs), spec.params, fail)
    tol = spec.singular_tol
    if not (0 <= tol < 1):
        fail("singular_tol", f"expected a number in [0, 1), got {tol!r}")
    return spec.name or default_name, spec.dim, tol, dict(spec.params), tuple(legs)


@dataclass(frozen=True)
class LegsFile:
    """A legs TOML's content, checked: what :class:`~stiffmap.models.legs.LegRobot` is built from.

    Attributes
    ----------
    name : str
        ``name``, or the file's stem.
    dim : int
        2 or 3.
    singular_tol : float
    params : dict of str to float
        ``[params]``: the stiffnesses (N*mm/rad or N/mm, inf rigid).
    legs : tuple of LegDescription
    source : str
        The file (for messages).
    base_dir : Path
        The file's folder (legs' URDFs are relative to it).
    """

    name: str
    dim: int
    singular_tol: float
    params: dict[str, float]
    legs: tuple[LegDescription, ...]
    source: str
    base_dir: Path


def parse_legs_text(
    text: str, *, source: str = "legs.toml", base_dir=".", default_name: str = "legs"
) -> LegsFile:
    """Check a legs TOML text (``source`` names it in messages); InputError naming the key."""
    try:
        data = tomllib.loads(text.removeprefix("\ufeff"))
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"not valid TOML: {e}", source=source) from None
    except RecursionError:
        raise InputError("not valid TOML: arrays or tables nested too deeply", source=source) from None
    except ValueError:  # an integer of thousands of digits
        raise InputError("not a usable TOML file: a number has thousands of digits", source=source) from None
    if "legs" not in data and {"kind", "robot"} <= data.keys():  # every key would be listed
        raise InputError(
            "a campaign.toml (kind, [robot]), not a legs TOML: that has dim, [params] and [[legs]] "
            "(docs/models.md, 'Parallel robots from their legs')",
            source=source,
        )
    name, dim, tol, params, legs = _descriptions(data, source, default_name)
    return LegsFile(name, dim, tol, params, legs, source, Path(base_dir))


def read_legs_file(path) -> LegsFile:
    """Read and check a legs TOML (``docs/models.md``); URDF paths in it are relative to its folder.

    Raises
    ------
    InputError
        Naming the file and the key (``legs[2].joints[1].axis: expected three numbers``),
        tables numbered from 1; a file of more than :data:`MAX_TOML_BYTES`.
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
    return parse_legs_text(
        read_text_file(p, "legs TOML file"), source=str(p), base_dir=p.parent, default_name=p.stem
    )


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


def legs_text(
    name: str | None,
    dim: int,
    params: dict[str, float],
    legs: tuple[LegDescription, ...],
    singular_tol: float,
    header: str = "",
) -> str:
    """The legs TOML of a robot's name, dimension, parameters and legs (``header``: a comment).

    :func:`parse_legs_text` reads it back.
    """
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
        for lk in lg.links:
            out += _link_lines(lk, "link" if lg.urdf is not None else "after")
    return "\n".join(out) + "\n"


_BEAM_FIELDS = ("length_mm", "E_MPa", "G_MPa", "area_mm2", "Iy_mm4", "Iz_mm4", "J_mm4")


def _link_lines(lk: LinkSpring, locator: str) -> list[str]:
    """A ``[[legs.links]]`` table (a given compliance written at its stiffness factor: C / f)."""
    out = ["", "[[legs.links]]", f"{locator} = {json.dumps(lk.link)}", f"name = {json.dumps(lk.name)}"]
    if lk.origin_mm is not None:
        out.append(f"xyz_mm = {_vec(lk.origin_mm)}")
    R = np.asarray(lk.rotation, dtype=float)
    if not np.array_equal(R, np.eye(3)):
        out.append(f"rpy = {_vec(euler_from_matrix(R))}")
    if lk.beam is None:
        C = np.asarray(lk.compliance, dtype=float) / lk.factor  # entries to 1e-15 and below: all digits
        rows = ", ".join("[" + ", ".join(repr(float(v)) for v in r) + "]" for r in C)
        return [*out, f"compliance = [{rows}]"]
    out += ["", "[legs.links.beam]"]
    out += [f"{k} = {_num(getattr(lk.beam, k))}" for k in _BEAM_FIELDS]
    if lk.beam.shear_factor is not None:
        out.append(f"shear_factor = {_num(lk.beam.shear_factor)}")
    if lk.beam.axis is not None:
        out.append(f"axis = {json.dumps(lk.beam.axis)}")
    return out
