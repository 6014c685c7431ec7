"""The registries of what stiffmap measures: robot kinds (one entry each).

``stiffmap.kinds`` sits between the campaign layer and the numerical cores: an entry
(:class:`RobotKind`) ties a kind's mechanism (:mod:`stiffmap.models`) to its test-bed robot
(:mod:`stiffmap.sim`), and the campaign spec, the runners, the command line and the report
read the entries instead of naming kinds. The built-in kinds (:mod:`.parallel`: ``delta``,
``3prr``, ``legs``; :mod:`.serial`: ``urdf``) are registered on import. The instruments a
campaign measures with are the campaign layer's registry
(:mod:`stiffmap.campaign.instruments`).

How to add a kind: CONTRIBUTING.md, "a mechanism"; ``docs/models.md``, "Robot kinds".
"""

from __future__ import annotations

from .options import (
    CONFIGS_OPTION,
    command_names,
    description_from_command,
    refuse_options,
    robot_from_command,
)
from .parallel import DELTA, LEGS, PRR3_KIND, build_with_params
from .positions import grid_from_text, kind_dim, position_presets, positions_from_text, preset_points
from .registry import (
    NO_ROBOT,
    ROBOT_KINDS,
    OwnSetup,
    RobotDescription,
    RobotKind,
    TestBed,
    allow_keys,
    build_robot,
    check_keys,
    float_params,
    kind_names,
    kind_of_file,
    params_from_text,
    register_robot_kind,
    registered,
    robot_from_options,
    robot_kind,
)
from .serial import BUILTIN_URDFS, URDF_KIND, urdf_file

for _kind in (DELTA, PRR3_KIND, URDF_KIND, LEGS):
    register_robot_kind(_kind, replace=True)

#: The test-bed robot of ``stiffmap simulate`` when none is named: the reference study's Delta.
DEFAULT_TESTBED = DELTA.testbed.name

__all__ = [
    "RobotKind",
    "DEFAULT_TESTBED",
    "RobotDescription",
    "TestBed",
    "OwnSetup",
    "ROBOT_KINDS",
    "NO_ROBOT",
    "register_robot_kind",
    "registered",
    "robot_kind",
    "kind_names",
    "build_robot",
    "robot_from_options",
    "robot_from_command",
    "description_from_command",
    "kind_of_file",
    "command_names",
    "refuse_options",
    "CONFIGS_OPTION",
    "build_with_params",
    "params_from_text",
    "float_params",
    "allow_keys",
    "check_keys",
    "position_presets",
    "preset_points",
    "positions_from_text",
    "grid_from_text",
    "kind_dim",
    "BUILTIN_URDFS",
    "urdf_file",
]
