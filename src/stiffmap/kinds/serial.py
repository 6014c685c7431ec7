"""Serial robots read from a URDF as a robot kind (``urdf``): joint springs ``k1`` .. ``kn``.

The description: the URDF (a file, or the name of one that ships with stiffmap: ``arm6``,
the test-bed's six-joint arm), the frame carrying the measured point (``tip_frame``) and the
point in it (``tip_offset_mm``), the tool's orientation for inverse kinematics
(``tool_rpy_deg``) and its seed (``q_seed_deg``), the joint configurations of the
positions (``configurations_deg``, or a CSV file ``configs``), and the joint stiffnesses.

A description as published (docs/models.md): ``base_frame`` (the link the measurements are
expressed in, when not the URDF's root), a ``.xacro`` file with ``xacro_args`` and
``package_paths`` (where ``$(find PKG)`` looks), flexible links from a TOML (``links``).

Joint stiffnesses are ``k1`` .. ``kn`` (N*mm/rad; N/mm for a prismatic joint), in the URDF's
joint order; a mimic joint's own spring ``k(n+1)`` ... and the flexible links' parameters
(``E_<name>``, ``G_<name>``, ``f_<name>``) may be given too. The rule for ``k_theta``: one
number sets every joint (``k_theta=1e9``), then
``k<i>`` changes one; a list ``k_theta=K1,...,Kn`` -- the form of stiffmap before 0.x, kept
so that old command lines and files still work -- is read as ``k1`` .. ``kn``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, Strict

from ..errors import FieldError, InputError
from ..geometry import matrix_from_euler
from ..models import arm6
from ..models.chain import Chain
from ..models.io import read_configuration_rows
from ..models.presets import joint_stiffnesses_from_text
from ..models.robot_files import read_links_toml
from ..models.serial import SerialRobot
from ..sim.robot import serial_robot
from ..sim.scene import arm_scene
from .registry import RobotDescription, RobotKind, TestBed, allow_keys

__all__ = ["URDF_KIND", "BUILTIN_URDFS", "urdf_file", "UrdfKeys"]

#: URDFs that ship with stiffmap, by name: ``stiffmap model urdf arm6 ...`` needs no file.
BUILTIN_URDFS: dict[str, str] = {"arm6": arm6.URDF}

_Finite = Annotated[float, Strict(), Field(allow_inf_nan=False)]
_Angle = Annotated[_Finite, Field(ge=-3600.0, le=3600.0)]
_Coord = Annotated[_Finite, Field(ge=-1e6, le=1e6)]
_Name = Annotated[str, Strict(), Field(min_length=1, max_length=1000)]
_PathText = Annotated[str, Strict(), Field(min_length=1, max_length=4096)]


class UrdfKeys(BaseModel):
    """A URDF robot's own campaign.toml keys (``[robot]``), beside ``urdf``, ``params`` and ``fit``."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)

    tip_frame: Annotated[
        str,
        Strict(),
        Field(min_length=1, max_length=1000, description="the link that carries the measured point"),
    ]
    #: The measured point in that frame, mm.
    tip_offset_mm: Annotated[tuple[_Coord, _Coord, _Coord], Field(strict=False)] | None = None
    #: The tool's orientation (roll, pitch, yaw in degrees, base frame) for inverse kinematics.
    tool_rpy_deg: Annotated[tuple[_Angle, _Angle, _Angle], Field(strict=False)] | None = None
    #: The seed of inverse kinematics, degrees (mm for a prismatic joint).
    q_seed_deg: list[_Angle] | None = None
    #: The link the measurements are expressed in, when it is not the URDF's root.
    base_frame: _Name | None = None
    #: A xacro description's arguments, ``$(arg NAME)``.
    xacro_args: dict[_Name, Annotated[str, Strict(), Field(max_length=10000)]] | None = None
    #: Folders where a xacro description's ``$(find PKG)`` looks (before ROS_PACKAGE_PATH and
    #: the workspace the file lies in).
    package_paths: list[_PathText] | None = None
    #: The flexible links' TOML (``[[links]]``, docs/models.md).
    links: _PathText | None = None


def urdf_file(urdf) -> str:
    """The URDF file of ``urdf``: a path, or the name of one that ships with stiffmap
    (:data:`BUILTIN_URDFS`, when no file of that name exists)."""
    text = str(urdf)
    if text in BUILTIN_URDFS and not Path(text).exists():
        return BUILTIN_URDFS[text]
    return text


def _joint_stiffnesses(params: Mapping[str, float | str], robot: SerialRobot) -> dict[str, object]:
    """The parameters of ``params`` for :meth:`SerialRobot.with_params`: ``k_theta`` (k1 .. kn by
    the rule of the module docstring), then a mimic joint's spring or a link's parameter.

    Raises
    ------
    FieldError
        ``params``: no joint stiffness, a name the robot does not have, a value not a number.
    """
    n = robot.n
    coords = {"k_theta", *(f"k{i}" for i in range(1, n + 1))}
    others = set(robot.param_names()) - coords
    unknown = [k for k in params if k not in coords and k not in others]
    if unknown:
        valid = [f"k1..k{n}", *others] if n > 1 else ["k1", *others]
        raise FieldError(
            "params",
            f"unknown urdf parameter {unknown[0]!r}; valid: {', '.join(valid)} (one joint each: "
            f"{', '.join(robot.chain.joint_names)}), or k_theta (one value for all {n})",
        )
    items = [f"{k}={v}" for k, v in params.items() if k in coords]
    if not items:
        raise FieldError(
            "params",
            f"give the stiffness of every joint of {robot.chain.name}: k1=K1,...,k{n}=K{n} "
            f"(N*mm/rad; N/mm for prismatic joints), or k_theta=K for all; there is no default",
        )
    out: dict[str, object] = {}
    try:
        out["k_theta"] = joint_stiffnesses_from_text(items, robot.chain)
        for k, v in params.items():
            if k in others:
                out[k] = float(v)
    except FieldError:
        raise
    except ValueError as e:
        raise FieldError("params", str(e)) from None
    return out


def _xacro_args(value) -> dict[str, str] | None:
    """``xacro_args`` as a mapping: campaign.toml's table, or the command line's NAME=VALUE texts."""
    if value is None or isinstance(value, Mapping):
        return None if value is None else {str(k): str(v) for k, v in value.items()}
    out = {}
    for text in value:
        name, eq, v = str(text).partition("=")
        if not eq or not name.strip():
            raise FieldError("xacro_args", f"{text!r}: expected NAME=VALUE", value=text)
        out[name.strip()] = v
    return out


def _build(d: RobotDescription) -> SerialRobot:
    """The serial robot of a description (:class:`UrdfKeys`, ``configs`` or ``configurations_deg``)."""
    allow_keys(d, *UrdfKeys.model_fields, "configs", "configurations_deg")
    if not d.keys.get("tip_frame"):
        raise FieldError(
            "tip_frame", f"no tip frame: give the link of {d.file} that carries the measured point"
        )
    offset = d.keys.get("tip_offset_mm")
    offset = (0.0, 0.0, 0.0) if offset is None else offset  # '' is a wrong value, not none given
    rpy = d.keys.get("tool_rpy_deg")
    seed = d.keys.get("q_seed_deg")
    links = d.keys.get("links")
    chain = Chain.from_urdf(
        d.file,
        d.keys["tip_frame"],
        offset,
        base_frame=d.keys.get("base_frame"),
        xacro_args=_xacro_args(d.keys.get("xacro_args")),
        package_paths=list(d.keys.get("package_paths") or ()),
    )
    robot = SerialRobot(
        chain,
        1.0,
        links=() if links is None else read_links_toml(links),
        tool_rotation=None if rpy is None else matrix_from_euler(np.radians(rpy)),
        q_seed=None if seed is None else _radians(seed, chain, "q_seed_deg"),
    )
    params = _joint_stiffnesses(d.params, robot)
    Q = _configurations(d, robot)
    try:
        return robot.with_params(**params, configurations=Q)
    except ValueError as e:
        raise FieldError("params", str(e)) from None


def _radians(q, chain: Chain, field: str = "q_seed_deg") -> np.ndarray:
    """Joint values in degrees (mm for a prismatic joint) as rad (mm), by the chain's joint types."""
    a = np.asarray(q, dtype=float)
    if a.shape[-1:] != (chain.n,):
        raise FieldError(
            field,
            f"{a.shape[-1] if a.ndim else 0} joint values; the chain to {chain.tip_frame} has {chain.n} "
            f"joints ({', '.join(chain.joint_names)})",
        )
    rev = np.array([t != "prismatic" for t in chain.joint_types])
    return np.where(rev, np.radians(a), a)


def _configurations(d: RobotDescription, robot: SerialRobot) -> np.ndarray | None:
    """The joint configurations of the positions: a file (``configs``) or degrees, mm for a
    prismatic joint (rad, mm out)."""
    if d.keys.get("configs") is not None:
        return read_configuration_rows(d.keys["configs"], robot.chain)[0]
    q = d.keys.get("configurations_deg")
    if q is None:
        return None
    Q = np.asarray(q, dtype=float)
    if Q.ndim != 2 or Q.shape[1] != robot.n:
        raise FieldError(
            "configurations_deg",
            f"{Q.shape[-1] if Q.ndim else 0} joint values per position; {robot.chain.name} has "
            f"{robot.n} joints ({', '.join(robot.chain.joint_names)})",
        )
    return _radians(Q, robot.chain, "configurations_deg")


#: A shipped arm's keys that belong to its own tip frame (its tool): left out on another chain.
_OF_TIP = ("tip_offset_mm", "tool_rpy_deg")


def _on_chain(own: RobotDescription, file: str, given: Mapping[str, object]) -> RobotDescription:
    """A shipped arm's defaults (``own``) on the chain the command line picks (``--tip``,
    ``--base`` in ``given``): its seed and joint springs for that chain's joints, by name (a
    shorter chain, ``--tip link_5``, takes the first five of the six); without the seed (the
    chain's own default) and the springs (``--param`` then required) when a joint of that chain
    is not one of the arm's; never its tool's offset and orientation (:data:`_OF_TIP`, of its own
    tip frame: the point is the new tip frame's origin, held at the chain's orientation at the
    seed, unless ``--tip-offset-mm`` or ``--tool-rpy-deg`` say otherwise). Unchanged when the
    chain is the arm's or cannot be built (the build reports why)."""
    tip = given.get("tip_frame", own.keys["tip_frame"])
    base = given.get("base_frame", own.keys.get("base_frame"))
    if tip == own.keys["tip_frame"] and base == own.keys.get("base_frame"):
        return own
    try:
        arm = Chain.from_urdf(file, own.keys["tip_frame"], base_frame=own.keys.get("base_frame"))
        chain = Chain.from_urdf(file, str(tip), base_frame=None if base is None else str(base))
    except (InputError, FieldError):
        return own
    where = {name: i for i, name in enumerate(arm.joint_names)}
    keys = {k: v for k, v in own.keys.items() if k not in ("q_seed_deg", *_OF_TIP)}
    params = {k: v for k, v in own.params.items() if not (k[:1] == "k" and k[1:].isdigit())}
    if all(name in where for name in chain.joint_names):
        idx = [where[name] for name in chain.joint_names]
        if own.keys.get("q_seed_deg") is not None:
            keys["q_seed_deg"] = [own.keys["q_seed_deg"][i] for i in idx]
        springs = [own.params.get(f"k{i + 1}") for i in idx]
        if all(k is not None for k in springs):
            params.update({f"k{j}": k for j, k in enumerate(springs, start=1)})
    return RobotDescription(own.kind, params, own.file, keys)


def _own(model: SerialRobot, d: RobotDescription, **kw):
    """A user's own URDF robot on the test-bed: its model's 6x6 field, its files for the campaign."""
    return serial_robot(model, links_file=d.keys.get("links"), **kw)


def _arm6(params: Mapping[str, float] | None = None, **kw):
    """stiffmap's six-joint arm as the test-bed's virtual robot (a 6x6 field)."""
    return serial_robot(arm6.model().with_params(**(params or {})), **kw)


URDF_KIND = RobotKind(
    name=SerialRobot.name,
    summary="a serial robot from its URDF, with a spring at every joint (k1 .. kn)",
    build=_build,
    dim=3,
    file="URDF",
    file_example="ROBOT.urdf",
    file_key="urdf",
    file_suffixes=(".urdf", ".xacro"),
    builtin_files=BUILTIN_URDFS,
    builtin_on_keys=_on_chain,
    builtin_defaults={
        "arm6": RobotDescription(
            SerialRobot.name,
            {f"k{i}": k for i, k in enumerate(arm6.K_THETA, start=1)},
            None,
            {
                "tip_frame": arm6.TIP_FRAME,
                "tip_offset_mm": arm6.TIP_OFFSET_MM,
                "tool_rpy_deg": (0.0, 180.0, 0.0),  # arm6.TOOL_ROTATION: the tool pointing down
                "q_seed_deg": list(arm6.Q_SEED_DEG),
            },
        )
    },
    keys=UrdfKeys,
    path_keys=("package_paths", "links"),
    options={
        "--tip": "tip_frame",
        "--tip-offset-mm": "tip_offset_mm",
        "--base": "base_frame",
        "--xacro-arg": "xacro_args",
        "--package-path": "package_paths",
        "--links": "links",
    },
    positions={"arm20": arm6.positions20},
    configurations=True,
    joint_params=True,
    takes_load_point=True,
    testbed=TestBed(
        name="arm6",
        instrument="camera",
        positions="arm20",
        robot=_arm6,
        scene=arm_scene,
        load_point_mm=arm6.LOAD_POINT_MM,
        rotations=True,
        own=_own,
    ),
)
