"""A campaign's robot model, built from its spec's ``[robot]`` section through the registry.

The spec (:mod:`stiffmap.campaign.spec`) is data; this builds what it describes: the
model of the robot kind ``robot.model`` (:mod:`stiffmap.kinds`), its file (``robot.urdf``,
``robot.legs``) found in the campaign folder, the joint configurations of
``positions.q_deg``, and, for a kind whose K depends on where the loads act,
``loads.point_mm``. Wrong values are worded in campaign.toml's terms (``robot.params``).

:func:`check_robot` checks the whole section before anything is measured (``stiffmap run``
and ``stiffmap report``): the robot's file stays in the campaign folder (after symbolic
links; :mod:`stiffmap.campaign.paths`), it reads, the model builds (a URDF's ``tip_frame``,
parameter names and values), and the parameters to fit are the model's and can be fitted.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..errors import FieldError, InputError
from ..kinds import NO_ROBOT, RobotDescription, RobotKind, build_robot, robot_kind
from ..models.base import Mechanism
from .paths import campaign_file
from .spec import SPEC_NAME, CampaignSpec, RobotSpec

__all__ = [
    "robot_description",
    "robot_model",
    "campaign_model",
    "campaign_positions",
    "fitted_names",
    "robot_file",
    "check_robot",
]


def _kind(robot: RobotSpec) -> RobotKind:
    if robot.model == NO_ROBOT:
        raise ValueError("robot.model is 'none': the campaign has no model")
    return robot_kind(robot.model)


def _file(kind: RobotKind, robot: RobotSpec, root: Path | None) -> Path | None:
    """The kind's file named by ``robot.<file_key>``, in the campaign folder (or shipped with stiffmap)."""
    if kind.file_key is None:
        return None
    if root is None:
        raise ValueError(f"robot.model = {kind.name!r} needs the campaign folder to find its file")
    name = robot.keys[kind.file_key]
    path = Path(root) / name
    if not path.exists() and kind.builtin_file(name) is not None:
        return Path(kind.builtin_file(name))  # a file that ships with stiffmap (arm6)
    if not path.is_file():
        raise InputError(f"no such file (named by {SPEC_NAME} robot.{kind.file_key})", source=str(path))
    return path


def robot_description(
    robot: RobotSpec, root: Path | None = None, configurations_deg=None, **overrides: float
) -> RobotDescription:
    """The registry's description of the ``[robot]`` section (``overrides`` replace parameters)."""
    kind = _kind(robot)
    keys = {k: v for k, v in robot.keys.items() if k != kind.file_key}
    if root is not None:  # files and folders the kind's keys name: in the campaign folder
        for k in kind.path_keys:
            if keys.get(k) is not None:
                v = keys[k]
                keys[k] = [Path(root) / p for p in v] if isinstance(v, (list, tuple)) else Path(root) / v
    if configurations_deg is not None:
        keys["configurations_deg"] = np.asarray(configurations_deg, dtype=float)
    return RobotDescription(kind.name, {**robot.params, **overrides}, _file(kind, robot, root), keys)


def _spec_names(kind: RobotKind) -> Mapping[str, str]:
    names = {"params": "robot.params", "fit": "robot.fit", "configurations_deg": "positions.q_deg"}
    if kind.file_key:
        names["file"] = f"robot.{kind.file_key}"
    return names


def robot_model(robot: RobotSpec, root: Path | None = None, configurations_deg=None, **overrides: float):
    """The model of the ``[robot]`` section, with ``params`` (then ``overrides``) applied.

    Parameters
    ----------
    robot : RobotSpec
    root : Path, optional
        The campaign folder, where a kind's file is (needed for those kinds).
    configurations_deg : array_like, shape (n, joints), optional
        A serial robot's joint configurations at the positions (``positions.q_deg``).

    Raises
    ------
    ValueError
        ``robot.model`` is ``none``.
    InputError
        A wrong value named by its campaign.toml key (``campaign.toml: robot.params: ...``),
        a file that cannot be read named with the key that names it.
    """
    d = robot_description(robot, root, configurations_deg, **overrides)
    try:
        return build_robot(d)
    except FieldError as e:
        raise e.worded(_spec_names(robot_kind(d.kind))).with_source(SPEC_NAME) from None


def campaign_model(spec: CampaignSpec, root: Path, **overrides: float) -> Mechanism:
    """The campaign's robot model: with the configurations of ``positions.q_deg`` (if any), and
    for a kind whose K depends on where the loads act, the K of forces hung at
    ``loads.point_mm`` (what the campaign identifies)."""
    q = None if spec.positions is None else spec.positions.q_deg
    model = robot_model(spec.robot, root, configurations_deg=q, **overrides)
    kind = robot_kind(spec.robot.model)
    if kind.takes_load_point and spec.loads is not None and spec.loads.point_mm is not None:
        model = model.with_params(load_offset_mm=spec.loads.point_mm)
    return model


def campaign_positions(spec: CampaignSpec, root: Path) -> np.ndarray:
    """The positions, shape (n, 3) mm: as given, or where ``positions.q_deg`` puts the measured
    point of the serial robot (``root``: the campaign folder, where its file is)."""
    if spec.positions.q_deg is None:
        return spec.positions.resolve()
    model = robot_model(spec.robot, root, configurations_deg=spec.positions.q_deg)
    return model.chain.forward_many(model.configurations)[0]


def fitted_names(spec: CampaignSpec, model: Mechanism) -> tuple[str, ...]:
    """The parameters to fit: ``robot.fit``, or the kind's default (InputError naming robot.fit)."""
    kind = robot_kind(spec.robot.model)
    try:
        return kind.fitted_names(model, spec.robot.fit)
    except FieldError as e:
        raise e.worded(_spec_names(kind)).with_source(SPEC_NAME) from None


def robot_file(spec: CampaignSpec, root: Path, *, allow_outside: bool = False) -> Path | None:
    """The robot's file (``robot.urdf``, ``robot.legs``), refused when it leads outside the
    campaign folder (an absolute path, ``..``, a symbolic link out) unless ``allow_outside``.

    Returns
    -------
    Path or None
        None for a kind without a file; a file shipped with stiffmap (``arm6``) as is.

    Raises
    ------
    InputError
        ``campaign.toml: key 'robot.urdf': '/x/arm.urdf' is an absolute path, outside the
        campaign directory; ... (give --allow-outside-paths to read it anyway)``.
    """
    kind = spec.robot.kind
    if kind is None or kind.file_key is None or kind.file_key not in spec.robot.keys:
        return None
    name = str(spec.robot.keys[kind.file_key])
    if not (Path(root) / name).exists() and kind.builtin_file(name) is not None:
        return Path(kind.builtin_file(name))
    return campaign_file(Path(root), name, f"robot.{kind.file_key}", allow_outside=allow_outside)


def check_robot(spec: CampaignSpec, root: Path, *, allow_outside: bool = False) -> None:
    """The ``[robot]`` section checked whole, before anything is measured.

    Its file stays in the campaign folder (:func:`robot_file`) and reads, the model builds
    with ``robot.params`` (a URDF's ``tip_frame``, its joints' parameters), and every
    parameter to fit (``robot.fit``, or the kind's default) is the model's, with a positive
    finite starting value.

    Raises
    ------
    InputError
        Naming the file, or ``campaign.toml`` and its key.
    """
    if spec.robot.kind is None:
        return
    robot_file(spec, root, allow_outside=allow_outside)
    try:
        model = campaign_model(spec, root)
    except InputError:
        raise
    except ValueError as e:
        raise InputError(f"robot: {e}", source=str(Path(root) / SPEC_NAME)) from None
    names = fitted_names(spec, model)
    params = model.params()
    for n in names:
        v = float(params.get(n, np.nan))
        if not (np.isfinite(v) and v > 0):
            rigid = " (inf: a rigid element, which has nothing to fit)" if np.isinf(v) else ""
            raise InputError(
                f"key 'robot.fit': cannot fit {n}: its starting value {v:g} is not a positive finite "
                f"number{rigid}; leave it out of robot.fit, or give it a value in robot.params",
                source=str(Path(root) / SPEC_NAME),
            )
