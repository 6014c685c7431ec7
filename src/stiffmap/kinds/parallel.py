"""The built-in parallel robots as robot kinds: the Delta (``delta``), the planar 3PRR (``3prr``)
and any translational parallel robot described by its legs in a TOML (``legs``).

Each entry (:class:`~stiffmap.kinds.registry.RobotKind`) says how to build the model from a
description, its parameters' units, what is fitted by default, its position layouts and
its test-bed robot; the mechanisms themselves are in :mod:`stiffmap.models.delta`,
:mod:`stiffmap.models.prr3` and :mod:`stiffmap.models.legs`.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..errors import FieldError
from ..models.delta import DeltaRobot
from ..models.legs import LegRobot
from ..models.presets import paper48, prr3_points22
from ..models.prr3 import PRR3
from ..sim.robot import mechanism_robot
from .registry import RobotDescription, RobotKind, TestBed, allow_keys, float_params

__all__ = ["DELTA", "PRR3_KIND", "LEGS", "build_with_params"]


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


def _legs(description: RobotDescription):
    """A parallel robot read from its legs TOML, with ``params`` overriding the file's."""
    allow_keys(description)
    model = LegRobot.from_toml(description.file)
    values = float_params(description.params, description.kind)
    if not values:
        return model
    try:
        return model.with_params(**values)
    except (TypeError, ValueError) as e:
        raise FieldError("params", str(e)) from None


LEGS = RobotKind(
    name="legs",
    summary="a translational parallel robot described by its legs in a TOML (virtual joint method)",
    build=_legs,
    dim=None,
    file="legs TOML",
    file_example="ROBOT.toml",
    file_key="legs",
)
