"""The registry of robot kinds: what stiffmap knows of each kind of robot, in one entry.

A *robot kind* (``delta``, ``3prr``, ``urdf``, ``legs``...) is a :class:`RobotKind`: how to
build its model (a :class:`~stiffmap.models.base.Mechanism`) from a
:class:`RobotDescription` -- the same description whether it comes from the command line
(``stiffmap model KIND [ROBOT] --param ...``) or from ``campaign.toml``'s ``[robot]``
section --, its parameters and their units, the parameters fitted by default, its
dimension, its default load and position layouts, the options and keys it takes beyond
``params`` and ``fit``, how a campaign fits it, and its test-bed (the virtual robot and
scene of ``stiffmap simulate``).

The campaign spec, the CLI (``model``, ``fit``, ``simulate``), the runners and the report
read this registry; none of them names a kind. Adding a kind is one entry
(:func:`register_robot_kind`) and the module of its mechanism (CONTRIBUTING.md, "a
mechanism"). ``tests/test_architecture.py`` checks that no module outside
:mod:`stiffmap.kinds` and the mechanisms' own modules names a kind.

Build a robot from options as a command would (:func:`robot_from_options`), or from a
description (:func:`build_robot`)::

    >>> from stiffmap.kinds import robot_from_options
    >>> robot_from_options("3prr", params=["kj=600"]).params()["kj"]
    600.0
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ValidationError

from ..errors import FieldError
from ..models.base import Mechanism

__all__ = [
    "RobotDescription",
    "RobotKind",
    "TestBed",
    "OwnSetup",
    "ROBOT_KINDS",
    "NO_ROBOT",
    "register_robot_kind",
    "registered",
    "robot_kind",
    "kind_names",
    "kind_of_file",
    "build_robot",
    "robot_from_options",
    "params_from_text",
    "float_params",
    "check_keys",
    "allow_keys",
]

#: ``robot.model`` of a campaign without a model.
NO_ROBOT = "none"


@dataclass(frozen=True)
class RobotDescription:
    """A robot as its user describes it: the same from the command line and from campaign.toml.

    Attributes
    ----------
    kind : str
        The kind's name (:data:`ROBOT_KINDS`).
    params : mapping of str to float or str
        Parameter values (N-mm-MPa, the kind's :attr:`RobotKind.param_units`); text as the
        command line gives it (``--param k1=2e7``) is converted by the kind.
    file : Path, optional
        The robot's description file for a kind described by one (:attr:`RobotKind.file`:
        a URDF, a legs TOML), resolved by the caller (the campaign folder, the working
        directory).
    keys : mapping of str to object
        The kind's own keys (:attr:`RobotKind.keys`), by their campaign.toml names
        (``tip_frame``, ``tip_offset_mm``...); absent keys take the kind's defaults.
    """

    kind: str
    params: Mapping[str, float | str] = field(default_factory=dict)
    file: Path | None = None
    keys: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class OwnSetup:
    """How the test-bed takes a user's own robot of a kind (:attr:`TestBed.own_setup`).

    Attributes
    ----------
    positions : ndarray, shape (n, 3) mm, or None
        Its positions when none are given (None: none by default).
    positions_text : str
        What those positions are, in words (the simulation's summary); without positions, why
        there are none by default.
    rotations : bool
        Its field holds rotations itself (a 6x6 field; :attr:`TestBed.rotations`).
    load_point_mm : (float, float, float)
        Where the loads act by default, tool frame, mm.
    notes : tuple of str
        What the user should know (default positions left out, and why).
    """

    positions: np.ndarray | None = None
    positions_text: str = ""
    rotations: bool = True
    load_point_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class TestBed:
    """A kind's robot on the virtual test-bed (``stiffmap simulate --robot NAME``).

    Attributes
    ----------
    name : str
        The name of ``--robot`` (``arm6`` for the test-bed's URDF arm).
    instrument : str
        What measures it: ``"camera"`` (rendered images of a vision campaign) or
        ``"sensor"`` (displacement-sensor recordings).
    positions : str
        The default position layout (a preset of the kind).
    robot : callable
        ``robot(params, **virtual_robot_fields)``: for a camera, the
        :class:`~stiffmap.sim.robot.VirtualRobot`; for a sensor, the mechanism.
    scene : callable, optional
        ``scene(camera or None) -> Scene``, the boards and camera around it (None: the
        reference set-up's demo scene).
    load_point_mm : (float, float, float)
        Where the loads act by default, tool frame, mm.
    rotations : bool
        Its field holds rotations itself (a 6x6 field): ``--rot-stiffness-nmm-per-rad`` is
        refused.
    campaign_name : str
        The simulated campaign's name when none is given.
    own : callable, optional
        A user's own robot of the kind on the test-bed (``stiffmap simulate --robot FILE``):
        ``own(model, description, **virtual_robot_fields)`` -> its virtual robot, seen by a
        camera; its positions are its model's configurations' measured points (or points
        given), the scene the demo's moved to look at them.
    own_setup : callable, optional
        ``own_setup(model) -> OwnSetup``: its default positions, field and load point (None:
        its configurations' measured points, a 6x6 field, loads at the measured point); a
        FieldError naming ``"robot"`` when such a robot cannot be simulated.
    """

    __test__ = False  # not a pytest test class

    name: str
    instrument: str
    positions: str
    robot: Callable[..., Any]
    scene: Callable[..., Any] | None = None
    load_point_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotations: bool = False
    campaign_name: str = "virtual test-bed"
    own: Callable[..., Any] | None = None
    own_setup: Callable[[Any], OwnSetup] | None = None


@dataclass(frozen=True)
class RobotKind:
    """One kind of robot: everything stiffmap needs to know of it.

    Attributes
    ----------
    name : str
        As on the command line and in ``campaign.toml`` (``robot.model``).
    summary : str
        One line for help texts.
    build : callable
        ``build(description: RobotDescription) -> Mechanism``; a wrong value raises
        :class:`~stiffmap.errors.FieldError` naming the field (``"params"``, a key), a file
        that cannot be read an :class:`~stiffmap.errors.InputError` naming it.
    dim : int or None
        Translational dimension of its tool (3, or 2 for a planar robot); None when its
        description says (a legs TOML).
    param_units : mapping of str to str
        Unit of each parameter (N-mm-MPa); :meth:`param_unit` also knows ``k1`` .. ``kn``
        when :attr:`joint_params` is set.
    default_fit : tuple of str or None
        Parameters fitted when none are named; None: the model's ``default_fit()`` when it
        has one, else every parameter of the model.
    default_load : (float, str) or None
        ``stiffmap model``'s force when none is given: magnitude (N) and direction.
    positions : mapping of str to callable
        Position layouts by name (``paper48``), the first the default; each returns an
        array (n, dim), mm.
    file : str or None
        What describes a robot of this kind, when a file does (``"URDF"``, ``"legs TOML"``):
        the ``ROBOT`` argument of ``stiffmap model`` and ``fit``, the campaign.toml key
        :attr:`file_key`.
    file_example : str
        How usage texts show that file (``ROBOT.urdf``).
    file_key : str or None
        The campaign.toml key of that file (``robot.urdf``, ``robot.legs``).
    file_suffixes : tuple of str
        The endings of its files (``.urdf``, ``.xacro``), lower case: ``stiffmap simulate
        --robot FILE`` takes a file so named as a robot of this kind (:func:`kind_of_file`).
    builtin_defaults : mapping of str to RobotDescription
        A shipped file's own parameters and keys (its springs, tool point, tool orientation,
        seed), by the file's name: what a command that offers them takes when the user names
        the file alone (``stiffmap compensate urdf arm6``; :func:`~stiffmap.kinds.robot_from_command`
        with ``builtin_defaults=True``).
    builtin_on_keys : callable, optional
        ``builtin_on_keys(own, file, given) -> RobotDescription``: a shipped file's defaults
        (``own``) fitted to the keys the command line gives (``given``), e.g. a serial arm's seed
        and springs on the joints of the chain ``--tip`` picks.
    builtin_files : mapping of str to str
        Files that ship with stiffmap, by name (``arm6``): a name without a file of that
        name is that file.
    keys : type of pydantic BaseModel, optional
        The kind's own campaign.toml keys beside ``model``, ``params``, ``fit`` and
        :attr:`file_key` (validated by it; their names are :class:`RobotDescription` keys).
    path_keys : tuple of str
        Its keys that name files or folders (a path, or a list of them): relative to the
        campaign folder in campaign.toml (:mod:`stiffmap.campaign.robot` resolves them), to
        the working directory on the command line.
    options : mapping of str to str
        The command-line options it takes beyond ``--param`` (option -> key), e.g.
        ``{"--tip": "tip_frame"}``; the others are refused for it.
    configurations : bool
        Its positions may be given as joint configurations (``--configs``,
        ``positions.q_deg``): a serial robot.
    joint_params : bool
        Its parameters are joint stiffnesses ``k1`` .. ``kn``: a fit of a campaign estimates
        them from the measured displacements (:func:`~stiffmap.models.joint_fit.fit_joint_compliances`),
        and ``robot.params`` must give every joint.
    takes_load_point : bool
        Its K depends on where the loads act (``loads.point_mm``): a serial robot's wrist turns.
    turning_platform : bool
        Its platform may be held turned (a legs TOML with ``dim = 6``: a hexapod, a 3-RPS):
        campaign.toml's ``positions.poses`` (x, y, z mm, roll, pitch, yaw deg) and a test-bed's
        positions with orientations (``roll_deg``, ``pitch_deg``, ``yaw_deg`` columns).
    report_grid : callable, optional
        ``report_grid(model) -> (points (n, dim) mm, middle line x (mm) or None)``: a planar
        kind's map in a sensor campaign's report.
    testbed : TestBed, optional
        Its robot on the virtual test-bed.
    """

    name: str
    summary: str
    build: Callable[[RobotDescription], Mechanism]
    dim: int | None = 3
    param_units: Mapping[str, str] = field(default_factory=dict)
    default_fit: tuple[str, ...] | None = None
    default_load: tuple[float, str] | None = None
    positions: Mapping[str, Callable[[], np.ndarray]] = field(default_factory=dict)
    file: str | None = None
    file_example: str = "ROBOT"
    file_key: str | None = None
    file_suffixes: tuple[str, ...] = ()
    builtin_files: Mapping[str, str] = field(default_factory=dict)
    builtin_defaults: Mapping[str, RobotDescription] = field(default_factory=dict)
    builtin_on_keys: Callable[[RobotDescription, str, Mapping[str, object]], RobotDescription] | None = None
    keys: type[BaseModel] | None = None
    path_keys: tuple[str, ...] = ()
    options: Mapping[str, str] = field(default_factory=dict)
    configurations: bool = False
    joint_params: bool = False
    takes_load_point: bool = False
    turning_platform: bool = False
    report_grid: Callable[[Mechanism], tuple[np.ndarray, float | None]] | None = None
    testbed: TestBed | None = None

    def param_unit(self, name: str) -> str:
        """The unit of parameter ``name`` ('' when unknown)."""
        if name in self.param_units:
            return self.param_units[name]
        if self.joint_params and name[:1] == "k" and name[1:].isdigit():
            return "N*mm/rad"
        if name.startswith(("E_", "G_")):  # a flexible link's moduli (models.links)
            return "MPa"
        return ""

    def builtin_file(self, name: str | Path) -> str | None:
        """The file that ships with stiffmap under ``name`` (None: none of that name, or a file
        of that name exists)."""
        text = str(name)
        if text in self.builtin_files and not Path(text).exists():
            return self.builtin_files[text]
        return None

    def fitted_names(self, model: Mechanism, fit: Sequence[str] | None = None) -> tuple[str, ...]:
        """The parameters to fit: ``fit`` (each item may be comma-separated), else the default
        (without the parameters the model holds infinite: rigid elements have nothing to fit).

        Raises
        ------
        FieldError
            Field ``"fit"``: a name that is not a parameter of ``model``.
        """
        valid = model.param_names() if hasattr(model, "param_names") else tuple(model.params())
        if self.default_fit is not None:
            default = list(self.default_fit)
        elif hasattr(model, "default_fit"):  # the model's own (a URDF robot: not a rigid mimic spring)
            default = list(model.default_fit())
        else:
            default = list(valid)
        # By default, not the rigid elements (inf: nothing to fit; a legs file's rigid arms).
        params = model.params()
        default = [n for n in default if not np.isinf(float(params.get(n, 0.0)))] or default
        names: list[str] = []
        for item in fit or default:
            names.extend(s.strip() for s in item.split(",") if s.strip())
        bad = [n for n in names if n not in valid]
        if bad:
            raise FieldError(
                "fit", f"unknown {self.name} parameter(s) {', '.join(bad)}; valid: {', '.join(valid)}"
            )
        return tuple(names)

    def default_positions(self) -> np.ndarray | None:
        """The first position layout (None: the kind has none)."""
        return next((np.asarray(fn(), dtype=np.float64) for fn in self.positions.values()), None)


#: Every robot kind, by name (``stiffmap.kinds`` registers the built-in ones on import).
ROBOT_KINDS: dict[str, RobotKind] = {}


def register_robot_kind(kind: RobotKind, *, replace: bool = False) -> RobotKind:
    """Add ``kind`` to :data:`ROBOT_KINDS` (``replace`` an entry of that name, else refused).

    Raises
    ------
    ValueError
        A kind of that name is registered already, or the name is ``"none"`` or a test-bed
        name is taken.
    """
    if kind.name == NO_ROBOT or not kind.name:
        raise ValueError(f"{kind.name!r} cannot name a robot kind")
    if kind.name in ROBOT_KINDS and not replace:
        raise ValueError(f"a robot kind {kind.name!r} is registered already")
    if kind.testbed is not None:
        taken = {k.testbed.name: k.name for k in ROBOT_KINDS.values() if k.testbed and k.name != kind.name}
        if kind.testbed.name in taken:
            raise ValueError(
                f"test-bed robot {kind.testbed.name!r} is the {taken[kind.testbed.name]}'s already"
            )
    ROBOT_KINDS[kind.name] = kind
    return kind


@contextmanager
def registered(kind: RobotKind) -> Iterator[RobotKind]:
    """``kind`` registered for the duration of a ``with`` block (tests, plug-ins tried out)."""
    register_robot_kind(kind)
    try:
        yield kind
    finally:
        ROBOT_KINDS.pop(kind.name, None)


def kind_names() -> tuple[str, ...]:
    """The registered kinds' names, in registration order."""
    return tuple(ROBOT_KINDS)


def robot_kind(name: str) -> RobotKind:
    """The kind called ``name``.

    Raises
    ------
    FieldError
        Field ``"kind"``: no such kind (the valid ones listed).
    """
    kind = ROBOT_KINDS.get(str(name).strip().lower())
    if kind is None:
        raise FieldError(
            "kind", f"unknown robot kind {name!r}; expected one of {', '.join(ROBOT_KINDS)}", value=name
        )
    return kind


def kind_of_file(path: str | Path) -> RobotKind | None:
    """The kind whose files end as ``path`` does (:attr:`RobotKind.file_suffixes`), or None."""
    name = str(path).lower()
    return next((k for k in ROBOT_KINDS.values() if any(name.endswith(x) for x in k.file_suffixes)), None)


def params_from_text(items: Sequence[str]) -> dict[str, str]:
    """``NAME=VALUE`` texts (comma-separated or repeated) as a mapping of texts.

    A part without ``=`` continues the previous value (``k_theta=1,2,3`` keeps ``"1,2,3"``:
    a list for a kind that reads one).

    Raises
    ------
    FieldError
        Field ``"params"``: a first part that is not ``NAME=VALUE``.

    Examples
    --------
    >>> params_from_text(["kj=600,kb=30", "h=800"])
    {'kj': '600', 'kb': '30', 'h': '800'}
    """
    out: dict[str, str] = {}
    key = None
    for item in items:
        for part in str(item).split(","):
            part = part.strip()
            if not part:
                continue
            if "=" in part:
                key, value = (x.strip() for x in part.split("=", 1))
                out[key] = value
            elif key is None:
                raise FieldError("params", f"{part!r} should look like NAME=VALUE", value=part)
            else:
                out[key] += "," + part
    return out


def float_params(given: Mapping[str, float | str], kind: str) -> dict[str, float]:
    """Parameter values as numbers.

    Raises
    ------
    FieldError
        Field ``"params"``: a value that is not one number (a list for a kind of single values).
    """
    out = {}
    for k, v in given.items():
        try:
            out[k] = float(v)
        except (TypeError, ValueError):
            why = "a list" if isinstance(v, str) and "," in v else "not a number"
            raise FieldError("params", f"{k}={v}: {v!r} is {why}", value=v) from None
    return out


def build_robot(description: RobotDescription) -> Mechanism:
    """The model of a robot described as :class:`RobotDescription` says.

    Raises
    ------
    FieldError
        A wrong value, naming its field (``"kind"``, ``"params"``, ``"file"``, a key of the
        kind): the caller words it as its option or key.
    InputError
        A file that cannot be read, naming it.
    """
    kind = robot_kind(description.kind)
    if kind.file is not None and description.file is None:
        raise FieldError("file", f"{kind.name} needs its {kind.file} file")
    if kind.file is None and description.file is not None:
        raise FieldError("file", f"{kind.name} takes no robot file")
    if description.file is not None and kind.builtin_file(description.file) is not None:
        description = replace(description, file=Path(kind.builtin_file(description.file)))
    return kind.build(description)


def robot_from_options(
    kind: str,
    file: str | Path | None = None,
    params: Sequence[str] | Mapping[str, float | str] = (),
    **keys: Any,
) -> Mechanism:
    """A robot from command-line style options: the public way to build any kind's model.

    Parameters
    ----------
    kind : str
        A registered kind (``delta``, ``3prr``, ``urdf``, ``legs``...).
    file : str or path, optional
        Its description file, for a kind described by one (a URDF or the name of one that
        ships with stiffmap, ``arm6``; a legs TOML).
    params : sequence of str or mapping
        ``NAME=VALUE`` texts (``["kj=600"]``, ``["k1=2e7,k2=1.6e7"]``) or a mapping.
    **keys
        The kind's own keys (:attr:`RobotKind.keys`), e.g. ``tip_frame="tool0"``.

    Returns
    -------
    Mechanism

    Raises
    ------
    FieldError, InputError
        As :func:`build_robot`.

    Examples
    --------
    The milling study's 3PRR with joint stiffness kj = 600 N/mm, and its stiffness at
    (400, 270) mm:

    >>> import numpy as np
    >>> m = robot_from_options("3prr", params=["kj=600"])
    >>> m.name, m.dim, m.params()["kj"]
    ('3prr', 2, 600.0)
    >>> np.diag(m.stiffness([400.0, 270.0])).round(1)  # N/mm along x and y
    array([ 754.6, 1046.9])
    """
    given = params_from_text(params) if not isinstance(params, Mapping) else dict(params)
    path = None if file is None else Path(file)
    return build_robot(RobotDescription(kind, given, path, {k: v for k, v in keys.items() if v is not None}))


def check_keys(kind: RobotKind, keys: Mapping[str, Any]) -> BaseModel | None:
    """The kind's own keys validated by its model (None when it has none).

    Raises
    ------
    FieldError
        Naming the first key that is wrong (or unknown to the kind).
    """
    if kind.keys is None:
        if keys:
            raise FieldError(next(iter(keys)), f"not a key of {kind.name}")
        return None
    try:
        return kind.keys.model_validate(dict(keys))
    except ValidationError as e:
        first = e.errors()[0]
        key = ".".join(str(x) for x in first["loc"]) or "keys"
        msg = first["msg"].removeprefix("Value error, ")
        raise FieldError(key, msg) from None


def allow_keys(description: RobotDescription, *names: str) -> None:
    """Refuse the keys of ``description`` other than ``names`` (FieldError naming the first)."""
    extra = [k for k in description.keys if k not in names]
    if extra:
        raise FieldError(extra[0], f"not a key of {description.kind}")
