"""The built-in parallel robots written as legs TOMLs: :func:`legs_toml`.

The Delta (:class:`~stiffmap.models.delta.DeltaRobot`) and the 3PRR
(:class:`~stiffmap.models.prr3.PRR3`) are the virtual joint method's assembly fed with
closed-form columns; here each is described by its legs (joints from its geometry, seeds
from its closed-form inverse kinematics at a central pose), the legs TOML that
:class:`~stiffmap.models.legs.LegRobot` reads back to the same K (tests: 1e-9 relative).
"""

from __future__ import annotations

import math

import numpy as np

from .delta import DeltaRobot
from .legs import LegRobot
from .legs_file import LegDescription, LegJoint, legs_text
from .prr3 import PRR3

__all__ = ["legs_toml"]


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
stiffmap.models.legs_convert.legs_toml(DeltaRobot()); LegRobot.from_toml reads it.
Each leg: the actuator (k_theta, N*mm/rad), the arm's transverse compliance at the elbow
as a virtual prismatic spring (k_arm, N/mm), the elbow as a ball joint (three revolute
joints; limits +-90 deg on the first two: the elbow-out branch), the forearm's axial
compliance (k_forearm, N/mm). inf = rigid."""

_PRR3_HEADER = """\
The planar 3PRR of stiffmap.models.prr3 (PRR3) described by its legs, the virtual joint
method's input (docs/models.md, "Parallel robots from their legs"). Written by
stiffmap.models.legs_convert.legs_toml(PRR3()); LegRobot.from_toml reads it.
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
        return legs_text(None, 3, params, legs, model.singular_tol, _DELTA_HEADER)
    if isinstance(model, PRR3):
        params, legs = _prr3_description(model)
        return legs_text(None, 2, params, legs, model.singular_tol, _PRR3_HEADER)
    if isinstance(model, LegRobot):
        stiffnesses = dict(zip(model.param_keys, model.param_values, strict=True))  # links: their tables
        return legs_text(model.name, model.dim, stiffnesses, model.description, model.singular_tol)
    raise TypeError(f"legs_toml takes a DeltaRobot, a PRR3 or a LegRobot, got {type(model).__name__}")
