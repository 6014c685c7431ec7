"""A robot from a command line's words: ``KIND [ROBOT] --param NAME=VALUE --tip FRAME ...``.

What ``stiffmap model``, ``stiffmap fit`` (and every command that takes a robot) share: the
kind's name, its description file (``ROBOT``), ``--param`` texts, the kind's own options
(:attr:`~stiffmap.kinds.registry.RobotKind.options`: ``--tip``, ``--tip-offset-mm`` for a
URDF robot) and, for a kind whose positions are joint configurations, ``--configs``. Every
problem is an :class:`~stiffmap.errors.InputError` in the command line's terms (the option
that is wrong): :func:`robot_from_command` is the one place that words the registry's
fields as options.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from ..errors import FieldError, InputError
from ..models.base import Mechanism
from .registry import ROBOT_KINDS, RobotDescription, RobotKind, build_robot, params_from_text, robot_kind

__all__ = [
    "robot_from_command",
    "description_from_command",
    "command_names",
    "refuse_options",
    "CONFIGS_OPTION",
]

#: The option giving a serial robot's joint configurations (a CSV file).
CONFIGS_OPTION = "--configs"


def command_names(kind: RobotKind) -> dict[str, str]:
    """The command line's names of the registry's fields for ``kind`` (for FieldError.worded)."""
    names = {"params": "--param", "fit": "--param-to-fit", "file": "ROBOT", "configs": CONFIGS_OPTION}
    names.update({key: opt for opt, key in kind.options.items()})
    return names


def refuse_options(kind: RobotKind, given: Mapping[str, object]) -> None:
    """Refuse an option (``given``: option -> value or None) that ``kind`` does not take."""
    for opt, v in given.items():
        if v is None or opt in kind.options or (opt == CONFIGS_OPTION and kind.configurations):
            continue
        owners = [
            k.name
            for k in ROBOT_KINDS.values()
            if opt in k.options or (opt == CONFIGS_OPTION and k.configurations)
        ]
        takers = " or ".join(f"'{o}'" for o in owners) or "no robot kind"
        raise InputError(f"{opt} is for {takers}, not {kind.name}")


def _option_value(text):
    """An option's text as the kind's key takes it: numbers ``x,y,z`` as a tuple, else the text;
    a repeatable option's texts as a list of texts."""
    if isinstance(text, (list, tuple)):
        return [str(t) for t in text]
    parts = str(text).split(",")
    try:
        return tuple(float(p) for p in parts) if len(parts) > 1 else str(text)
    except ValueError:
        return str(text)


def robot_from_command(
    kind_name: str,
    robot: str | Path | None,
    params: Sequence[str] = (),
    options: Mapping[str, str | None] | None = None,
    *,
    configs: str | Path | None = None,
    command: str = "model",
    builtin_defaults: bool = False,
    configs_required: bool = True,
) -> Mechanism:
    """The robot a command line describes, through the registry (any kind).

    Parameters
    ----------
    kind_name : str
        The robot kind (``delta``, ``3prr``, ``urdf``, ``legs``...).
    robot : str or path, optional
        ``ROBOT``: its description file, for a kind described by one.
    params : sequence of str
        ``--param`` texts, ``NAME=VALUE``.
    options : mapping of str to str or None
        The kind-specific options given (``{"--tip": "tool0", "--tip-offset-mm": None}``);
        an option ``kind`` does not take is refused when given.
    configs : str or path, optional
        ``--configs``: joint configurations, for a kind whose positions are configurations
        (required for it).
    command : str
        The command, for the usage in messages.
    builtin_defaults : bool
        For a file that ships with stiffmap (``urdf arm6``), take its own parameters when no
        ``--param`` is given and its keys for the options not given
        (:attr:`~stiffmap.kinds.registry.RobotKind.builtin_defaults`).
    configs_required : bool
        Whether a kind whose positions are joint configurations needs ``--configs`` (False for
        a command that reaches its points by inverse kinematics, ``stiffmap compensate``).

    Raises
    ------
    InputError
        In the command line's terms: an unknown kind, an option or file the kind does not
        take, a required one missing, a wrong value named by its option.
    """
    description = description_from_command(
        kind_name, robot, params, options, configs=configs, command=command,
        builtin_defaults=builtin_defaults, configs_required=configs_required,
    )  # fmt: skip
    try:
        return build_robot(description)
    except FieldError as e:
        raise e.worded(command_names(robot_kind(kind_name))) from None


def description_from_command(
    kind_name: str,
    robot: str | Path | None,
    params: Sequence[str] = (),
    options: Mapping[str, str | None] | None = None,
    *,
    configs: str | Path | None = None,
    command: str = "model",
    builtin_defaults: bool = False,
    configs_required: bool = True,
) -> RobotDescription:
    """The :class:`RobotDescription` of a command line (:func:`robot_from_command`, unbuilt).

    Raises
    ------
    InputError
        As :func:`robot_from_command`, but for the values the kind's builder checks.
    """
    try:
        kind = robot_kind(kind_name)
    except FieldError as e:
        raise InputError(e.reason) from None
    given = dict(options or {})
    refuse_options(kind, {**given, CONFIGS_OPTION: configs})
    usage = f"stiffmap {command} {kind.name} {kind.file_example}" if kind.file else ""
    if kind.file and robot is None:
        raise InputError(f"{kind.name} needs the robot's {kind.file} file: {usage} ...")
    if not kind.file and robot is not None:
        with_files = " and ".join(
            f"'stiffmap {command} {k.name} {k.file_example}'" for k in ROBOT_KINDS.values() if k.file
        )
        raise InputError(
            f"{robot}: a robot file is only for {with_files}; {kind.name} takes none "
            "(positions: --grid or --points)"
        )
    keys = {kind.options[opt]: _option_value(v) for opt, v in given.items() if v is not None}
    values = _params(kind, params)
    own = kind.builtin_defaults.get(str(robot)) if builtin_defaults and robot is not None else None
    if own is not None and kind.builtin_file(robot) is not None:
        if kind.builtin_on_keys is not None:
            own = kind.builtin_on_keys(own, kind.builtin_file(robot), keys)
        keys = {**own.keys, **keys}
        values = values or dict(own.params)
    _require(kind, keys, robot)
    if kind.configurations and configs_required and configs is None:
        raise InputError(
            f"{CONFIGS_OPTION} CONFIGS.csv is required for {kind.name}: the joint configurations "
            "(columns q1_deg..qn_deg in the robot's joint order)"
        )
    if kind.configurations and configs is not None:
        keys["configs"] = Path(configs)
    return RobotDescription(kind.name, values, None if robot is None else Path(robot), keys)


def _require(kind: RobotKind, keys: Mapping[str, object], robot) -> None:
    """The kind's required keys that have an option: ``--tip is required for urdf``."""
    if kind.keys is None:
        return
    for opt, key in kind.options.items():
        field = kind.keys.model_fields.get(key)
        if field is not None and field.is_required() and key not in keys:
            what = field.description or "required"
            raise InputError(f"{opt} is required for {kind.name}: {what} (of {robot})")


def _params(kind: RobotKind, items: Sequence[str]) -> dict[str, str]:
    """``--param`` texts as a mapping (InputError naming ``--param``)."""
    try:
        return params_from_text(items)
    except FieldError as e:
        raise e.worded(command_names(kind)) from None
