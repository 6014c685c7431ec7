"""The built-in parallel robots as robot kinds: the Delta (``delta``), the planar 3PRR (``3prr``)
and any translational parallel robot described by its legs in a TOML (``legs``).

Each entry (:class:`~stiffmap.kinds.registry.RobotKind`) says how to build the model from a
description, its parameters' units, what is fitted by default, its position layouts and
its test-bed robot; the mechanisms themselves are in :mod:`stiffmap.models.delta`,
:mod:`stiffmap.models.prr3` and :mod:`stiffmap.models.legs`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from importlib.resources import files

import numpy as np

from ..errors import FieldError
from ..models.base import check_stiffness
from ..models.delta import DeltaRobot
from ..models.legs import LegRobot
from ..models.mobility import COORDINATES, Mobility, lower_mobility, pose_text, reachable_poses
from ..models.presets import paper48, prr3_points22
from ..models.prr3 import PRR3
from ..sim.robot import mechanism_robot, platform_robot
from ..sim.scene import hexapod_scene
from .registry import OwnSetup, RobotDescription, RobotKind, TestBed, allow_keys, float_params

__all__ = [
    "DELTA",
    "PRR3_KIND",
    "LEGS",
    "BUILTIN_LEGS",
    "HEXAPOD_TESTBED_K",
    "OWN_GRID_FRACTION",
    "OWN_GRID_TURN_DEG",
    "build_with_params",
    "legs_default_grid",
    "legs_default_poses",
]


def build_with_params(cls, description: RobotDescription):
    """``cls(**params)`` for a mechanism class whose parameters are its fields (``param_names``).

    Raises
    ------
    FieldError
        Field ``"params"``: an unknown name (the valid ones listed), a value that is not a
        number or that the mechanism refuses (its own message).
    """
    allow_keys(description)
    values = float_params(description.params, description.kind)
    valid = cls.param_names()
    bad = sorted(set(values) - set(valid))
    if bad:
        raise FieldError(
            "params",
            f"unknown {description.kind} parameter{'s' if len(bad) > 1 else ''} {', '.join(bad)}; "
            f"valid: {', '.join(valid)}",
        )
    try:
        return cls(**values)
    except (TypeError, ValueError) as e:
        raise FieldError("params", str(e)) from None


def _delta_robot(params: Mapping[str, float] | None = None, **kw):
    """The Delta as the test-bed's virtual robot (its 3x3 field; kw: VirtualRobot fields)."""
    return mechanism_robot(DeltaRobot().with_params(**(params or {})), **kw)


def _prr3(params: Mapping[str, float] | None = None):
    """The 3PRR of the test-bed's sensor campaigns."""
    return build_with_params(PRR3, RobotDescription(PRR3.name, dict(params or {})))


DELTA = RobotKind(
    name=DeltaRobot.name,
    summary="the Delta-type translational robot of the reference vision study",
    build=lambda d: build_with_params(DeltaRobot, d),
    dim=3,
    param_units={
        "base_radius": "mm",
        "platform_radius": "mm",
        "arm_length": "mm",
        "forearm_length": "mm",
        "k_theta": "N*mm/rad",
        "k_arm": "N/mm",
        "k_forearm": "N/mm",
    },
    default_fit=("k_theta",),
    # The reference study's largest load: 0.5 kg (its g = 9.81 m/s^2) down.
    default_load=(4.905, "-z"),
    positions={"paper48": paper48},
    testbed=TestBed(name=DeltaRobot.name, instrument="camera", positions="paper48", robot=_delta_robot),
)


def _prr3_grid(model) -> tuple[np.ndarray, float]:
    """The 3PRR's map in a sensor campaign's report: its workspace triangle, 41 x 36 points,
    and its vertical middle line (x = h/2), where the milling study measured."""
    h = model.params()["h"]
    X, Y = np.meshgrid(np.linspace(0.0, h, 41), np.linspace(0.0, h * np.sqrt(3) / 2, 36))
    return np.c_[X.ravel(), Y.ravel()], h / 2


PRR3_KIND = RobotKind(
    name=PRR3.name,
    summary="the planar redundant 3PRR of the milling study (flexible prismatic joints)",
    build=lambda d: build_with_params(PRR3, d),
    dim=2,
    param_units={"h": "mm", "L": "mm", "area": "mm^2", "E": "MPa", "kj": "N/mm", "kb": "N/mm"},
    default_fit=("kj",),
    # The milling study's largest load: 50 kgf (its g = 9.81 m/s^2) along y.
    default_load=(490.5, "y"),
    positions={"points22": prr3_points22},
    report_grid=_prr3_grid,
    testbed=TestBed(
        name=PRR3.name,
        instrument="sensor",
        positions="points22",
        robot=_prr3,
        campaign_name="virtual test-bed (3PRR, LDV)",
    ),
)


_ROBOTS = files("stiffmap.models") / "robots"
#: Legs TOMLs that ship with stiffmap, by name: ``stiffmap model legs hexapod ...`` needs no file.
BUILTIN_LEGS: dict[str, str] = {
    name: str(_ROBOTS / f"{name}.toml") for name in ("hexapod", "3rps", "delta", "3prr", "delta_links")
}
#: The test-bed's hexapod (``stiffmap simulate --robot hexapod``): the shipped 6-UPS on spring
#: legs of six different stiffnesses (N/mm), soft enough that the reference study's loads move
#: its platform by about a millimetre, as they move the Delta's.
HEXAPOD_TESTBED_K = (9.0, 7.5, 11.0, 8.0, 10.5, 12.0)
#: Its positions (mm): the platform level, a 3 x 3 grid 40 mm apart at two heights.
HEXAPOD_TESTBED_POSITIONS = ";".join(
    f"{x:g},{y:g},{z:g}" for z in (280.0, 320.0) for y in (-40.0, 0.0, 40.0) for x in (-40.0, 0.0, 40.0)
)
#: Where its loads hang, from the tool point (the platform's centre), mm: 100 mm below it, so
#: that they turn the platform as well as move it.
HEXAPOD_LOAD_POINT_MM = (0.0, 0.0, -100.0)
_LEGS_NAME = "legs"


def _hexapod(params: Mapping[str, float] | None = None, **kw):
    """The test-bed's hexapod as a virtual robot (a 6x6 field: :func:`~stiffmap.sim.robot.platform_robot`)."""
    defaults = {f"k_leg{i}": k for i, k in enumerate(HEXAPOD_TESTBED_K, start=1)}
    model = LegRobot.from_toml(BUILTIN_LEGS["hexapod"]).with_params(**{**defaults, **(params or {})})
    return platform_robot(model, _LEGS_NAME, _LEGS_NAME, **kw)


def _legs(description: RobotDescription):
    """A parallel robot read from its legs TOML, with ``params`` overriding the file's."""
    allow_keys(description)
    model = LegRobot.from_toml(description.file)
    values = float_params(description.params, description.kind)
    if not values:
        return model
    try:
        for k, v in values.items():  # the file's [params] range, for the values that override them
            if k in model.param_keys:
                check_stiffness(k, v, "N*mm/rad or N/mm")
        return model.with_params(**values)
    except (TypeError, ValueError) as e:
        raise FieldError("params", str(e)) from None


#: A legs robot of one's own on the test-bed: its default grid's spacing, as a fraction of the
#: robot's size at home (:meth:`~stiffmap.models.legs.LegRobot.home`): the test-bed hexapod's
#: 40 mm of its 335 mm.
OWN_GRID_FRACTION = 0.12


def _round_spacing(mm: float) -> float:
    """``mm`` rounded to a half of its decade (40.2 -> 40, 32.3 -> 30, 3.6 -> 3.5), at least that half."""
    half = 10.0 ** math.floor(math.log10(mm)) / 2
    return max(round(mm / half), 1) * half


def legs_default_grid(model) -> tuple[np.ndarray, np.ndarray, float]:
    """The test-bed's grid about a legs robot's home: 3 x 3 x 2 positions, the platform level.

    x and y at the home's and one spacing either side, z half a spacing below and above it
    (x fastest, then y, then z: the test-bed hexapod's order); the spacing is
    :data:`OWN_GRID_FRACTION` of the robot's size, rounded (40 mm for the shipped hexapod,
    whose grid is then the test-bed's ``HEXAPOD_TESTBED_POSITIONS``).

    Returns
    -------
    points : ndarray, shape (18, 3), mm
    home : ndarray, shape (3,), mm
    spacing : float, mm
    """
    home, size = model.home()
    home = np.round(home, 6) + 0.0  # the seeds' roundoff (1e-13 mm) left out
    s = _round_spacing(OWN_GRID_FRACTION * size)
    steps = [(x, y, z) for z in (-s / 2, s / 2) for y in (-s, 0.0, s) for x in (-s, 0.0, s)]
    return home + np.array(steps), home, s


#: A platform of lower mobility (a 3-RPS) on the test-bed: its default grid turns it this far
#: either side of level (deg), as the turned test-bed hexapod's poses (about 10 deg keep both
#: boards in view of its scene).
OWN_GRID_TURN_DEG = 8.0
#: The coordinates a lower-mobility grid steps three times (the first two its platform
#: controls, in this order) and twice (z when it controls it).
_THREE_LEVELS = (0, 1, 3, 4, 5)


def legs_default_poses(model, mobility: Mobility) -> tuple[np.ndarray, str]:
    """The test-bed's grid of a platform of lower mobility: 3 x 3 x 2 poses in the coordinates it controls.

    The two first of x, y, roll, pitch, yaw it controls at the home's value and one step
    either side (:func:`legs_default_grid`'s spacing for x and y, :data:`OWN_GRID_TURN_DEG`
    for a turn), the fastest first; z (when it controls it, else the next free coordinate)
    half a step below and above; the coordinates that follow solved at each pose
    (:func:`~stiffmap.models.mobility.reachable_poses`). For the shipped 3-RPS: roll and pitch
    at -8, 0, 8 deg, z 235 and 265 mm, x, y and yaw solved.

    Returns
    -------
    poses : ndarray, shape (n, 6)
        x, y, z (mm), roll, pitch, yaw (rad); n = 18 for three free coordinates or more.
    where : str
        The grid in words (the simulation's summary).
    """
    _, home, s = legs_default_grid(model)
    three = [j for j in _THREE_LEVELS if j in mobility.free]
    two = 2 if 2 in mobility.free else (three[2] if len(three) > 2 else None)
    axes = [(j, 3) for j in three[:2]] + ([(two, 2)] if two is not None else [])
    step = {j: (s if j < 3 else np.radians(OWN_GRID_TURN_DEG)) for j, _ in axes}
    levels = [step[j] * (np.array([-1.0, 0.0, 1.0]) if n == 3 else np.array([-0.5, 0.5])) for j, n in axes]
    mesh = np.meshgrid(*levels[::-1], indexing="ij") if axes else []  # the first axis fastest
    poses = np.tile(np.r_[home, 0.0, 0.0, 0.0], (mesh[0].size if axes else 1, 1))
    for (j, _), v in zip(axes[::-1], mesh, strict=True):
        poses[:, j] += v.ravel()
    poses, _ = reachable_poses(model, poses, mobility)
    words = [
        f"{COORDINATES[j]} "
        + ", ".join(f"{v:g}" for v in (lv + home[j] if j < 3 else np.degrees(lv)))
        + (" mm" if j < 3 else " deg")
        for (j, _), lv in zip(axes, levels, strict=True)
    ]
    dims = " x ".join(str(n) for _, n in axes)
    where = (
        f"a {dims} grid about the home position {_mm(home)} mm ({'; '.join(words)}); "
        f"{mobility.describe(model.name)}, solved at each pose"
    )
    return poses, where


def _own_legs(model, description: RobotDescription, **kw):
    """A user's own legs TOML on the test-bed (:func:`~stiffmap.sim.robot.platform_robot`)."""
    return platform_robot(model, _LEGS_NAME, _LEGS_NAME, **kw)


def _own_legs_setup(model) -> OwnSetup:
    """A legs robot of one's own on the test-bed: its default grid (the positions the legs reach),
    and for ``dim = 6`` the loads hung as for the test-bed hexapod.

    Raises
    ------
    FieldError
        ``robot``: a planar robot (``dim = 2``), legs given by URDFs.
    """
    if model.dim == 2:
        raise FieldError(
            "robot",
            f"{{robot}} {model.source}: dim = 2, a planar robot: the test-bed simulates planar robots as "
            f"displacement-sensor recordings of its own 3PRR ({{robot}} {PRR3_KIND.testbed.name}); a "
            "legs TOML of dim = 6 or dim = 3 is simulated as seen by a camera",
        )
    if any(d.urdf for d in model.description):
        raise FieldError(
            "robot",
            f"{{robot}} {model.source}: legs given by URDFs cannot be simulated yet (the campaign would need "
            "their files); describe each leg by its joints (docs/models.md)",
        )
    grid, home, s = legs_default_grid(model)
    turns = model.dim == 6
    load_point = HEXAPOD_LOAD_POINT_MM if turns else (0.0, 0.0, 0.0)
    where = f"a 3 x 3 x 2 grid {s:g} mm apart about the home position {_mm(home)} mm" + (
        ", the platform level" if turns else ""
    )
    mobility = lower_mobility(model) if turns else None
    if mobility is not None:
        grid, where = legs_default_poses(model, mobility)
    m = model.evaluate(np.c_[grid, np.zeros((len(grid), 3))] if turns and grid.shape[1] == 3 else grid)
    out = np.flatnonzero(~m.valid)
    first = f"position {out[0] + 1} {pose_text(grid[out[0]])}: {m.reasons[out[0]]}" if out.size else ""
    if out.size == len(grid):  # positions must be given: say why the default does not do
        why = f"no position of the default grid ({where}) suits {model.name} ({first})"
        return OwnSetup(None, why, turns, load_point)
    notes = ()
    if out.size:
        notes = (
            f"{out.size} of the default grid's {len(grid)} positions left out (positions "
            f"{', '.join(str(i + 1) for i in out)}: the robot model has no stiffness there; {first}; "
            f"--select numbers the {len(grid) - out.size} kept)",
        )
    return OwnSetup(
        positions=grid[m.valid],
        positions_text=where + (f", {out.size} out of reach left out" if out.size else ""),
        rotations=turns,
        load_point_mm=load_point,
        notes=notes,
    )


def _mm(p) -> str:
    return "(" + ", ".join(f"{v:g}" for v in p) + ")"


LEGS = RobotKind(
    name=_LEGS_NAME,
    summary="a parallel robot described by its legs in a TOML (virtual joint method; dim = 6: a "
    "platform that turns, a hexapod)",
    build=_legs,
    dim=None,
    file="legs TOML",
    file_example="ROBOT.toml",
    file_key=_LEGS_NAME,
    file_suffixes=(".toml",),
    builtin_files=BUILTIN_LEGS,
    turning_platform=True,
    testbed=TestBed(
        name="hexapod",
        instrument="camera",
        positions=HEXAPOD_TESTBED_POSITIONS,
        robot=_hexapod,
        scene=hexapod_scene,
        load_point_mm=HEXAPOD_LOAD_POINT_MM,
        rotations=True,
        campaign_name="virtual test-bed (hexapod)",
        own=_own_legs,
        own_setup=_own_legs_setup,
    ),
)
