"""Mechanism models: stiffness and static error of robots, evaluated over workspaces and fitted.

- :mod:`~stiffmap.models.base`: the :class:`Mechanism` protocol any robot model
  implements, and the :class:`ModelMap` / :class:`IKSolution` results;
- :mod:`~stiffmap.models.delta`: :class:`DeltaRobot`, a Delta-type translational robot;
- :mod:`~stiffmap.models.prr3`: :class:`PRR3`, the redundant planar 3PRR of the
  milling study (truss with flexible prismatic joints);
- :mod:`~stiffmap.models.legs`: :class:`LegRobot`, a translational parallel robot
  described by its legs in a TOML (virtual joint method; the Delta and the 3PRR are
  instances: ``robots/delta.toml``, ``robots/3prr.toml``); its file, the legs TOML, is read
  and written by :mod:`~stiffmap.models.legs_file`, the built-in robots converted to one by
  :mod:`~stiffmap.models.legs_convert` (:func:`legs_toml`), its legs' chains built by
  :mod:`~stiffmap.models.legs_chains`;
- :mod:`~stiffmap.models.legs6`: :class:`LegRobot6`, a parallel robot whose platform
  turns (``dim = 6``: hexapods, 3-RPS), its 6 x 6 stiffness (``robots/hexapod.toml``,
  ``robots/3rps.toml``);
- :mod:`~stiffmap.models.serial`: :class:`SerialRobot`, a serial arm read from a URDF
  (kinematics through :mod:`~stiffmap.models.chain`, Pinocchio) with joint springs;
- :mod:`~stiffmap.models.presets`: the reference studies' position layouts, grids, load
  directions and joint stiffnesses from text (the robot kinds by name are the registry's,
  :mod:`stiffmap.kinds`);
- :mod:`~stiffmap.models.fit`: parameter fits to stiffness matrices or static errors;
- :mod:`~stiffmap.models.joint_fit`: joint stiffnesses of a robot from measured deflections;
- :mod:`~stiffmap.models.io`: the files of ``stiffmap model`` and ``stiffmap fit``.

See ``docs/models.md``.
"""

from __future__ import annotations

from .base import SINGULAR_TOL, IKSolution, Mechanism, ModelMap, PoseError
from .delta import DeltaRobot
from .fit import ModelFit, fit_static_errors, fit_stiffness
from .joint_fit import (
    JointFit,
    JointIdentifiability,
    fit_joint_compliances,
    joint_deflections,
    joint_identifiability,
)
from .legs import LegRobot
from .legs6 import LegRobot6  # registers itself: LegRobot.from_toml of a dim = 6 file builds one
from .legs_convert import legs_toml
from .presets import paper48, prr3_points22
from .prr3 import PRR3
from .serial import SerialRobot

__all__ = [
    "Mechanism",
    "ModelMap",
    "IKSolution",
    "PoseError",
    "SINGULAR_TOL",
    "DeltaRobot",
    "PRR3",
    "SerialRobot",
    "LegRobot",
    "LegRobot6",
    "legs_toml",
    "paper48",
    "prr3_points22",
    "ModelFit",
    "fit_stiffness",
    "fit_static_errors",
    "JointFit",
    "JointIdentifiability",
    "fit_joint_compliances",
    "joint_deflections",
    "joint_identifiability",
]
