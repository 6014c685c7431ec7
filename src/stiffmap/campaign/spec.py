"""The campaign spec, ``campaign.toml``: what was measured, how, and where the files are.

A campaign is a directory (DESIGN.md section 4)::

    CAMPAIGN/
      campaign.toml        # this spec
      camera.json          # calibrated camera (vision campaigns), or
      rig.json             # several calibrated cameras ([cameras], stiffmap calibrate-rig)
      images/...           # raw images, never modified
      stiffmap.db          # results (written by ``stiffmap run``)
      report/              # derived report

This module holds the schema (pydantic models, one per table) and reading it:
:func:`load_spec`, :func:`parse_spec`. Every problem is reported with the key
(``targets.fixed.square_mm``) and the line of ``campaign.toml`` it is on
(:mod:`stiffmap.campaign.spec_errors`). Writing a spec, with every key
explained, and the commented example ``stiffmap init DIR`` writes are in
:mod:`stiffmap.campaign.spec_writer`.

Values are taken for what TOML says they are: a number where a number belongs
(``true`` or ``"9.81"`` is refused, not converted), an integer where a count
belongs. Numbers must be finite and physically plausible (:data:`LIMITS`): a
coordinate of 1e300 mm or a board square of 1e-300 mm is a typing mistake,
reported with its key, not a computation that overflows later.
"""

from __future__ import annotations

import difflib
import re
import string
import tomllib
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    Strict,
    ValidationError,
    field_validator,
    model_validator,
)

from ..errors import FieldError, InputError
from ..geometry import as_transform
from ..kinds import (
    NO_ROBOT,
    ROBOT_KINDS,
    RobotDescription,
    RobotKind,
    build_robot,
    check_keys,
    preset_points,
    robot_kind,
)
from ..loads import LoadCase, load_from_mass, with_friction
from ..loads import preset as load_preset
from ..rig import CAMERA_FIELD
from ..sensors.recording import parse_channel_map
from ..targets import parse_board_size
from .spec_errors import validation_message

__all__ = [
    "CampaignSpec",
    "CaptureSpec",
    "load_spec",
    "parse_spec",
    "SPEC_NAME",
    "DEFAULT_UNLOADED",
    "DEFAULT_LOADED",
    "LIMITS",
    "MAX_SPEC_BYTES",
]

SPEC_NAME = "campaign.toml"
DEFAULT_UNLOADED = "images/p{position:02d}/l{load:02d}_r{repeat:02d}_unloaded.png"
DEFAULT_LOADED = "images/p{position:02d}/l{load:02d}_r{repeat:02d}_loaded.png"

#: campaign.toml larger than this is refused (the reference study's spec is a few kB).
MAX_SPEC_BYTES = 16 * 1024 * 1024

#: What campaign.toml may hold (physical plausibility and sizes; docs/campaigns.md "Limits").
LIMITS = {
    "coordinate_mm": 1e6,  # 1 km: positions, points, translations of fixed2base and mobile2tcp
    "force_n": 1e7,
    "mass_kg": 1e6,
    "g": (1.0, 100.0),  # m/s^2
    "square_mm": (0.01, 1000.0),
    "board_side": (3, 200),  # inner corners per side (the corner detector needs 3 or more)
    "repeats": 1000,
    "positions": 10_000,
    "loads": 1000,
    "images": 200_000,  # image files a campaign names
    "recordings": 10_000,
    "model_param": (1e-6, 1e12),  # |value| of a non-zero robot.params entry, in its own unit
    "time_s": 1e7,
    "scale_um_per_v": (1e-6, 1e9),
    "range_v": (0.02, 1e4),
    "load_n_per_v": (1e-9, 1e9),
    "window_s": (1e-6, 1e6),
    "threshold_sigma": (0.01, 1e6),
    "text": 1000,  # characters of a name or a label
    "path": 4096,  # characters of a file name or pattern
    "name_component": 255,  # bytes of one folder or file name (the file systems' limit)
    "format_width": 64,  # width or precision in a file-name pattern's {position:...}
}


def _number(v):
    """Refuse a bool where a number belongs (TOML's ``true`` is not 1)."""
    if isinstance(v, bool):
        raise ValueError(f"expected a number, got {str(v).lower()}")
    return v


def _between(lo: float, hi: float, unit: str):
    def check(v: float) -> float:
        if not lo <= v <= hi:
            raise ValueError(f"must be between {lo:g} and {hi:g} {unit}".rstrip())
        return v

    return AfterValidator(check)


def _positive_up_to(hi: float, unit: str):
    def check(v: float) -> float:
        if not 0 < v <= hi:
            raise ValueError(f"must be a positive number of {unit}, at most {hi:g}")
        return v

    return AfterValidator(check)


Finite = Annotated[float, BeforeValidator(_number), Strict(), Field(allow_inf_nan=False)]
Coord = Annotated[Finite, _between(-LIMITS["coordinate_mm"], LIMITS["coordinate_mm"], "mm")]
ForceN = Annotated[Finite, _between(-LIMITS["force_n"], LIMITS["force_n"], "N")]
MassKg = Annotated[Finite, _positive_up_to(LIMITS["mass_kg"], "kg")]
NonNegMassKg = Annotated[Finite, _between(0.0, LIMITS["mass_kg"], "kg")]
TimeS = Annotated[Finite, _between(0.0, LIMITS["time_s"], "s")]
Count = Annotated[int, Strict()]
Text = Annotated[str, Strict(), Field(max_length=LIMITS["text"])]


def _check_path_text(v: str, what: str = "file name") -> str:
    """A file name (or a pattern's fixed part) that the file system can hold."""
    if not v.strip():
        raise ValueError(f"empty {what}")
    if len(v) > LIMITS["path"]:
        raise ValueError(f"{what} of {len(v)} characters; at most {LIMITS['path']}")
    bad = next((c for c in v if ord(c) < 32 or ord(c) == 127), None)
    if bad is not None:
        raise ValueError(f"{what} {v[:60]!r} holds the control character {bad!r}")
    for part in re.split(r"[\\/]", v):
        try:
            n = len(part.encode("utf-8"))
        except UnicodeEncodeError:
            raise ValueError(f"{what} {v[:60]!r} is not valid Unicode text") from None
        if n > LIMITS["name_component"]:
            raise ValueError(
                f"{what} {v[:60]!r}...: one of its folder or file names is {n} bytes long; "
                f"file systems allow {LIMITS['name_component']}"
            )
    return v


FileName = Annotated[str, Strict(), AfterValidator(_check_path_text)]


class _Spec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


def _check_transform(v: list[list[float]], name: str) -> list[list[float]]:
    a = np.asarray(v, dtype=float)
    if a.shape != (4, 4):
        raise ValueError(f"must be a 4x4 matrix (4 rows of 4 numbers), got shape {a.shape}")
    if np.abs(a[:3, 3]).max() > LIMITS["coordinate_mm"]:
        raise ValueError(
            f"its translation {a[:3, 3].tolist()} mm is beyond {LIMITS['coordinate_mm']:g} mm (1 km)"
        )
    if np.abs(a[:3, :3]).max() > 1.0 + 1e-4:
        raise ValueError(
            f"its rotation part {a[:3, :3].tolist()} has an entry beyond 1 in size: not a rotation matrix"
        )
    try:
        as_transform(a, name, atol=1e-4)
    except ValueError as e:
        raise ValueError(str(e).split(": ", 1)[-1]) from None
    return v


#: Joint-stiffness parameters of a serial robot: k1, k2, ... (N*mm/rad or N/mm).
_JOINT_PARAM = re.compile(r"k[1-9][0-9]?")
_LINK_PARAM = re.compile(r"[EGf]_[A-Za-z0-9_]{1,100}")
Angle = Annotated[Finite, _between(-3600.0, 3600.0, "degrees")]


class RobotSpec(_Spec):
    """The robot: a model to fit and draw beside the measurements, or ``none``.

    ``model`` is a robot kind of the registry (:mod:`stiffmap.kinds`: ``delta``, ``3prr``,
    ``urdf``, ``legs``...). Besides ``params`` (its parameters, in their units) and ``fit``
    (those fitted; default: the kind's), the section holds the kind's own keys: the file
    that describes it (``urdf``, ``legs``: relative to the campaign folder) and what its
    entry's ``keys`` name (a URDF robot's ``tip_frame``, ``tip_offset_mm``,
    ``tool_rpy_deg``, ``q_seed_deg``; docs/campaigns.md). The model itself is built beside
    the spec (:mod:`stiffmap.campaign.robot`).
    """

    model_config = ConfigDict(extra="allow", frozen=True, strict=True)

    model: Text = NO_ROBOT
    params: dict[str, Finite] = Field(default_factory=dict)
    #: Parameters fitted to the measurements (default: the kind's, e.g. k_theta for the Delta,
    #: kj for the 3PRR, every joint of a URDF robot).
    fit: list[Text] | None = None

    @property
    def keys(self) -> dict:
        """The kind's own keys (the file's key included), as campaign.toml gives them."""
        return dict(self.model_extra or {})

    @property
    def kind(self) -> RobotKind | None:
        """The registry's entry of ``model`` (None for ``none``)."""
        return None if self.model == NO_ROBOT else robot_kind(self.model)

    @field_validator("model")
    @classmethod
    def _registered(cls, v: str) -> str:
        if v != NO_ROBOT and v not in ROBOT_KINDS:
            raise ValueError(f"Input should be {', '.join(map(repr, ROBOT_KINDS))} or {NO_ROBOT!r}")
        return v

    @model_validator(mode="after")
    def _known(self):
        lo, hi = LIMITS["model_param"]
        for k, v in self.params.items():
            if v != 0 and not lo <= abs(v) <= hi:
                raise ValueError(
                    f"robot.params.{k} = {v:g} is not between {lo:g} and {hi:g} in size (in the "
                    "parameter's unit, docs/models.md): a typing mistake?"
                )
        if self.fit is not None and len(set(self.fit)) != len(self.fit):
            raise ValueError("robot.fit = a parameter is listed twice")
        kind = self.kind
        self._check_own_keys(kind)
        if kind is None:
            return self
        if kind.file_key is not None:
            if self.keys.get(kind.file_key) is None:
                raise ValueError(f'model = "{kind.name}" needs robot.{kind.file_key} (its {kind.file} file)')
            value = self.keys[kind.file_key]
            if not isinstance(value, str):
                raise ValueError(f"robot.{kind.file_key} = expected a file name (text), got {value!r}")
            _check_path_text(value, f"robot.{kind.file_key}")
        for key in kind.path_keys:  # files and folders named by the kind's own keys (a URDF's links)
            value = self.keys.get(key)
            for text in value if isinstance(value, list) else [value]:
                if isinstance(text, str):
                    _check_path_text(text, f"robot.{key}")
        try:
            check_keys(kind, {k: v for k, v in self.keys.items() if k != kind.file_key})
        except FieldError as e:
            if e.reason == "Field required":
                raise ValueError(f'model = "{kind.name}" needs robot.{e.field}') from None
            raise ValueError(f"robot.{e.field} = {e.reason}") from None
        if kind.joint_params:
            self._check_joint_params(kind)
        elif kind.file_key is None:
            self._check_by_building(kind)
        return self

    def _check_own_keys(self, kind: RobotKind | None) -> None:
        """Keys of another kind, or of none, are named: 'robot.tip_frame is for model = "urdf"'."""
        own = set() if kind is None else {kind.file_key, *(kind.keys.model_fields if kind.keys else ())}
        for key in self.keys:
            if key in own:
                continue
            owners = [
                k.name
                for k in ROBOT_KINDS.values()
                if key == k.file_key or (k.keys is not None and key in k.keys.model_fields)
            ]
            if owners:
                raise ValueError(f'robot.{key} is for model = "{owners[0]}", not "{self.model}"')
            known = sorted({"model", "params", "fit", *(k for k in own if k)})
            close = difflib.get_close_matches(key, known, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else f" (expected one of {', '.join(known)})"
            raise ValueError(f"robot.{key} = unknown key{hint}")

    def _check_joint_params(self, kind: RobotKind) -> None:
        """A serial robot's parameters are its joints' stiffnesses k1, k2, ..., positive."""
        links = self.keys.get("links") is not None  # flexible links' E_<name>, G_<name>, f_<name> too
        bad = [
            k
            for k in list(self.params) + list(self.fit or ())
            if not (_JOINT_PARAM.fullmatch(k) or (links and _LINK_PARAM.fullmatch(k)))
        ]
        if bad:
            raise ValueError(
                f"robot.params / robot.fit: {bad[0]!r} is not a joint stiffness of a {kind.name} robot; "
                "its parameters are k1, k2, ... (N*mm/rad; N/mm for a prismatic joint)"
                + (", and its links' E_<name>, G_<name> (MPa), f_<name>" if links else "")
            )
        if any(v <= 0 for v in self.params.values()):
            raise ValueError("robot.params: joint stiffnesses must be positive (N*mm/rad)")

    def _check_by_building(self, kind: RobotKind) -> None:
        """A kind built without a file: its model is built now, so a bad parameter is named here."""
        try:
            model = build_robot(RobotDescription(kind.name, dict(self.params)))
            kind.fitted_names(model, self.fit)
        except FieldError as e:
            raise ValueError(f"robot.{e.field} = {e.reason}") from None


class CameraSpec(_Spec):
    """The calibrated camera (``camera.json``, relative to the campaign directory)."""

    file: FileName = "camera.json"


class CamerasSpec(_Spec):
    """Several calibrated cameras (``rig.json`` from ``stiffmap calibrate-rig``).

    Every image of the campaign is then a set of one image per camera: the ``[images]``
    patterns hold ``{camera}``, replaced by each camera's name.
    """

    rig: FileName = "rig.json"
    #: The cameras' names, as in the rig file (optional: a check that the file is the one meant).
    names: list[Annotated[str, Strict(), Field(min_length=1, max_length=LIMITS["name_component"])]] | None = (
        None
    )

    @field_validator("names")
    @classmethod
    def _names(cls, v):
        if v is None:
            return v
        if not v:
            raise ValueError("must name at least one camera")
        for n in v:
            if n != n.strip() or not re.fullmatch(r"[^/\\{}\x00-\x1f]+", n):
                raise ValueError(
                    f"{n!r} is not a camera name usable in a file name (no slash, brace, control character "
                    "or outer space)"
                )
        dup = sorted({n for n in v if v.count(n) > 1})
        if dup:
            raise ValueError(f"{dup[0]!r} is listed twice")
        return v


class BoardSpec(_Spec):
    board: Annotated[str, Strict(), Field(max_length=40)]
    square_mm: Annotated[Finite, _between(*LIMITS["square_mm"], "mm")]

    @field_validator("board")
    @classmethod
    def _board(cls, v: str) -> str:
        cols, rows = parse_board_size(v)
        lo, hi = LIMITS["board_side"]
        if not (lo <= cols <= hi and lo <= rows <= hi):
            raise ValueError(
                f"a board of {cols}x{rows} inner corners: each side must have {lo} to {hi} "
                "(the corner detector needs 3 or more)"
            )
        return v.strip().lower()


class FixedTargetSpec(BoardSpec):
    """The target fixed to the robot base, with its known pose in the base frame."""

    fixed2base: list[list[Finite]]

    @field_validator("fixed2base")
    @classmethod
    def _rigid(cls, v):
        return _check_transform(v, "fixed2base")


class MobileTargetSpec(BoardSpec):
    """The target on the platform; ``point_mm`` is the point whose displacement is measured."""

    point_mm: Annotated[tuple[Coord, Coord, Coord], Field(strict=False)] = (0.0, 0.0, 0.0)
    mobile2tcp: list[list[Finite]] | None = None

    @field_validator("mobile2tcp")
    @classmethod
    def _rigid(cls, v):
        return None if v is None else _check_transform(v, "mobile2tcp")


class TargetsSpec(_Spec):
    fixed: FixedTargetSpec | None = None
    mobile: MobileTargetSpec

    @model_validator(mode="after")
    def _distinct(self):
        if self.fixed is not None and self.fixed.board == self.mobile.board:
            raise ValueError(
                f"the fixed and mobile boards are both {self.mobile.board}: they are told apart by "
                "their size, so they must differ"
            )
        return self


class GridSpec(_Spec):
    x: list[Coord]
    y: list[Coord]
    z: list[Coord] = Field(default_factory=lambda: [0.0])


class PositionsSpec(_Spec):
    """Exactly one of ``preset``, ``list``, ``grid`` (mm, base frame), ``q_deg`` (a serial robot's
    joint configurations) or ``poses`` (a platform that turns: ``[x, y, z, roll, pitch, yaw]``,
    mm and degrees, R = Rz(yaw) Ry(pitch) Rx(roll))."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, populate_by_name=True)

    preset: Text | None = None
    points: list[list[Coord]] | None = Field(default=None, alias="list")
    grid: GridSpec | None = None
    #: A URDF robot's joint configurations (degrees; mm for a prismatic joint), one per position:
    #: the positions are where they put the measured point.
    q_deg: list[list[Angle]] | None = None
    #: Poses of a platform that turns (a robot kind with ``turning_platform``: a ``dim = 6``
    #: legs TOML), one per position: x, y, z (mm), roll, pitch, yaw (degrees).
    poses: list[list[Finite]] | None = None

    @model_validator(mode="after")
    def _one(self):
        keys = (
            ("preset", "preset"),
            ("list", "points"),
            ("grid", "grid"),
            ("q_deg", "q_deg"),
            ("poses", "poses"),
        )
        given = [k for k, a in keys if getattr(self, a) is not None]
        if len(given) != 1:
            raise ValueError(
                "give exactly one of 'preset', 'list', 'grid', 'q_deg' or 'poses'"
                + (f" (got {', '.join(given)})" if given else "")
            )
        if self.poses is not None:
            _check_poses(self.poses)
        if self.q_deg is not None:
            if not self.q_deg:
                raise ValueError("'q_deg' is empty")
            if len({len(q) for q in self.q_deg}) > 1:
                i = next(i for i, q in enumerate(self.q_deg) if len(q) != len(self.q_deg[0]))
                raise ValueError(
                    f"q_deg[{i}] has {len(self.q_deg[i])} joint values, q_deg[0] has {len(self.q_deg[0])}"
                )
        if self.points is not None:
            if not self.points:
                raise ValueError("'list' is empty")
            for i, p in enumerate(self.points):
                if len(p) not in (2, 3):
                    raise ValueError(f"list[{i}] must be [x, y, z] (or [x, y] for a planar robot), got {p}")
        if self.grid is not None and not (self.grid.x and self.grid.y and self.grid.z):
            raise ValueError("grid: x, y and z must each hold at least one value")
        if self.preset is not None:
            try:
                preset_points(self.preset)
            except ValueError as e:
                raise ValueError(f"positions.preset = {e}") from None
        n = self.count()
        if n > LIMITS["positions"]:
            raise ValueError(f"{n} positions; a campaign may have at most {LIMITS['positions']}")
        return self

    def count(self) -> int:
        """The number of positions (without building them)."""
        if self.q_deg is not None:
            return len(self.q_deg)
        if self.poses is not None:
            return len(self.poses)
        if self.points is not None:
            return len(self.points)
        if self.grid is not None:
            return len(self.grid.x) * len(self.grid.y) * len(self.grid.z)
        return len(preset_points(self.preset))

    def resolve(self) -> np.ndarray:
        """Positions, shape (n, 3) mm (z = 0 for planar points); not for ``q_deg``
        (:meth:`CampaignSpec.position_points` puts those through the robot's kinematics)."""
        if self.q_deg is not None:
            raise ValueError("positions.q_deg: the positions come from the robot's kinematics")
        if self.preset is not None:
            pts = np.asarray(preset_points(self.preset), dtype=float)
        elif self.poses is not None:
            pts = np.array([p[:3] for p in self.poses], dtype=float)
        elif self.points is not None:
            pts = np.array([list(p) + [0.0] * (3 - len(p)) for p in self.points], dtype=float)
        else:
            g = self.grid
            X, Y, Z = np.meshgrid(g.x, g.y, g.z, indexing="ij")
            pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
        if pts.shape[1] == 2:
            pts = np.c_[pts, np.zeros(len(pts))]
        return pts

    def orientations_deg(self) -> np.ndarray | None:
        """The platform's roll, pitch, yaw (n, 3) degrees at each position of ``poses`` (None:
        positions without orientations, the platform level)."""
        return None if self.poses is None else np.array([p[3:] for p in self.poses], dtype=float)


#: Largest roll, pitch or yaw of a pose in ``positions.poses``, degrees.
MAX_POSE_ANGLE_DEG = 180.0


def _check_poses(poses: list[list[float]]) -> None:
    """``positions.poses``: a non-empty list of [x, y, z, roll, pitch, yaw] (ValueError naming the row)."""
    if not poses:
        raise ValueError("'poses' is empty")
    for i, p in enumerate(poses):
        if len(p) == 3:
            raise ValueError(
                f"poses[{i}] = {p} is a position without its orientation: give [x, y, z, roll, pitch, yaw] "
                "(mm, degrees), or the positions as 'list' (the platform level)"
            )
        if len(p) != 6:
            raise ValueError(
                f"poses[{i}] = {p} has {len(p)} numbers; a pose is [x, y, z, roll, pitch, yaw] (mm, degrees)"
            )
        big = [v for v in p[:3] if abs(v) > LIMITS["coordinate_mm"]]
        if big:
            raise ValueError(f"poses[{i}] = {p}: {big[0]} mm is beyond +-{LIMITS['coordinate_mm']:g} mm")
        turned = [v for v in p[3:] if abs(v) > MAX_POSE_ANGLE_DEG]
        if turned:
            raise ValueError(f"poses[{i}] = {p}: {turned[0]} deg is beyond +-{MAX_POSE_ANGLE_DEG:g} deg")


_AXIS_NAMES = ("x", "y", "z", "+x", "+y", "+z", "-x", "-y", "-z")


class LoadCaseSpec(_Spec):
    """A load: a mass along a direction, or a force vector in N (base frame)."""

    mass_kg: MassKg | None = None
    direction: Text | list[Coord] | None = None
    force_n: Annotated[tuple[ForceN, ForceN, ForceN], Field(strict=False)] | None = None
    label: Text = ""

    @model_validator(mode="after")
    def _one(self):
        if self.force_n is not None and (self.mass_kg is not None or self.direction is not None):
            raise ValueError("give either force_n, or mass_kg with direction, not both")
        if self.force_n is None and (self.mass_kg is None or self.direction is None):
            raise ValueError("give force_n = [fx, fy, fz] (N), or mass_kg with direction")
        if self.force_n is not None and not any(self.force_n):
            raise ValueError("force_n is zero")
        d = self.direction
        if isinstance(d, str) and d.strip().lower() not in _AXIS_NAMES:
            raise ValueError(f"direction {d!r}: expected one of x, y, z, -x, -y, -z or a vector [x, y, z]")
        if isinstance(d, list) and (len(d) != 3 or not any(d)):
            raise ValueError(f"direction {d}: expected a non-zero vector [x, y, z]")
        return self


class FrictionSpec(_Spec):
    """Friction subtracted from the loads applied through a pulley (the reference: X and Y)."""

    mass_kg: NonNegMassKg
    std_kg: NonNegMassKg = 0.0
    directions: list[Literal["x", "y", "z"]] = Field(default_factory=lambda: ["x", "y"])


class LoadsSpec(_Spec):
    """Exactly one of ``preset`` (``paper9``) or ``cases``; optional friction."""

    preset: Text | None = None
    cases: list[LoadCaseSpec] | None = None
    friction: FrictionSpec | None = None
    #: Where the loads act, relative to the measured point, in the base frame's axes (mm): a
    #: load off the measured point also applies a moment (the tool keeps its orientation at
    #: every position). Used by a URDF robot's joint-stiffness fit.
    point_mm: Annotated[tuple[Coord, Coord, Coord], Field(strict=False)] | None = None

    @model_validator(mode="after")
    def _one(self):
        if (self.preset is None) == (self.cases is None):
            raise ValueError("give exactly one of 'preset' or 'cases'")
        if self.cases is not None and not self.cases:
            raise ValueError("'cases' is empty")
        if self.cases is not None and len(self.cases) > LIMITS["loads"]:
            raise ValueError(f"{len(self.cases)} load cases; a campaign may have at most {LIMITS['loads']}")
        if self.preset is not None:
            try:
                load_preset(self.preset)
            except ValueError as e:
                raise ValueError(f"loads.preset = {e}") from None
        return self

    def count(self) -> int:
        """The number of load cases."""
        return len(self.cases) if self.cases is not None else len(load_preset(self.preset))

    def resolve(self, g: float):
        """The load cases (:class:`stiffmap.loads.LoadCase`), friction applied."""
        if self.preset is not None:
            loads = load_preset(self.preset, g=g)
        else:
            loads = []
            for c in self.cases:
                if c.force_n is not None:
                    f = np.asarray(c.force_n, dtype=float)
                    loads.append(LoadCase(f, np.zeros((3, 3)), c.label or f"F = {tuple(c.force_n)} N"))
                else:
                    loads.append(load_from_mass(c.mass_kg, c.direction, g=g, label=c.label or None))
        if self.friction is not None:
            axes = {"x": 0, "y": 1, "z": 2}
            out = []
            for ld in loads:
                u = np.abs(ld.force) / ld.magnitude
                if any(u[axes[a]] > 0.999 for a in self.friction.directions):
                    ld = with_friction(ld, self.friction.mass_kg, self.friction.std_kg, g=g)
                out.append(ld)
            loads = out
        return loads


_FIELDS = {"position", "load", "repeat", "camera"}


def _check_pattern(v: str, required: set[str]) -> str:
    try:
        parsed = list(string.Formatter().parse(v))
    except ValueError as e:
        raise ValueError(f"bad pattern {v!r}: {e}") from None
    names = {f for _, f, _, _ in parsed if f is not None}
    unknown = {n.split("!")[0].split(":")[0] for n in names} - _FIELDS
    if unknown:
        raise ValueError(
            f"unknown placeholder(s) {sorted(unknown)} in {v!r}; use {{position}}, {{load}}, {{repeat}} "
            "(and {camera} with several cameras)"
        )
    missing = required - names
    if missing:
        raise ValueError(f"pattern {v!r} must contain {', '.join('{' + m + '}' for m in sorted(missing))}")
    for _, field, spec, _ in parsed:
        if field is None:
            continue
        if field.split("!")[0].split(":")[0] == "camera" and (spec or "!" in field):
            raise ValueError(f"bad pattern {v!r}: write {{camera}} as it is, without a format")
        if "{" in spec or "}" in spec:
            raise ValueError(f"bad pattern {v!r}: a placeholder inside {{{field}:{spec}}}")
        widths = [int(d) for d in re.findall(r"\d+", spec)]
        if any(w > LIMITS["format_width"] for w in widths):
            raise ValueError(
                f"bad pattern {v!r}: {{{field}:{spec}}} asks for {max(widths)} characters; "
                f"at most {LIMITS['format_width']}"
            )
    try:
        sample = v.format(position=1, load=1, repeat=1, camera="left")
    except (ValueError, KeyError, IndexError, TypeError) as e:
        raise ValueError(f"bad pattern {v!r}: {e}") from None
    _check_path_text(sample, "file name")
    return v


class ImagesSpec(_Spec):
    """File-name patterns of the images, relative to the campaign directory.

    Placeholders ``{position}``, ``{load}``, ``{repeat}`` are 1-based indices and
    accept format specs (``{position:02d}``). The unloaded pattern may omit
    ``{load}`` when one unloaded image serves every load case of a repeat.
    """

    unloaded: Annotated[str, Strict(), Field(max_length=LIMITS["path"])] = DEFAULT_UNLOADED
    loaded: Annotated[str, Strict(), Field(max_length=LIMITS["path"])] = DEFAULT_LOADED
    #: "pairs": each loaded image against its own unloaded image (the robot may move
    #: between measurements); "mean-reference": against the mean of all unloaded images
    #: of the position (the robot stays at the position during all its loads and
    #: repeats), which halves the reference's share of the noise.
    pairing: Literal["pairs", "mean-reference"] = "pairs"

    @field_validator("unloaded")
    @classmethod
    def _unloaded(cls, v: str) -> str:
        return _check_pattern(v, {"position"})

    @field_validator("loaded")
    @classmethod
    def _loaded(cls, v: str) -> str:
        return _check_pattern(v, {"position", "load"})

    def path(self, state: Literal["unloaded", "loaded"], position: int, load: int, repeat: int) -> str:
        """Relative path of one image (1-based indices).

        With several cameras, the path of the image set: ``{camera}`` is kept as it is
        (:func:`stiffmap.rig.camera_path` gives each camera's file).
        """
        pat = self.unloaded if state == "unloaded" else self.loaded
        return pat.format(position=position, load=load, repeat=repeat, camera=CAMERA_FIELD)

    @property
    def per_camera(self) -> bool:
        """True when the patterns name one image per camera (``{camera}``)."""
        return CAMERA_FIELD in self.unloaded or CAMERA_FIELD in self.loaded


_MOVE_FIELDS = {"x", "y", "z"}


def _check_move_command(v: str) -> str:
    """A command template with {x}, {y}, {z} (mm; format specs allowed, e.g. {x:.3f})."""
    if not v.strip():
        raise ValueError("empty move_command")
    if len(v) > LIMITS["path"]:
        raise ValueError(f"move_command of {len(v)} characters; at most {LIMITS['path']}")
    try:
        parsed = list(string.Formatter().parse(v))
    except ValueError as e:
        raise ValueError(f"bad move_command {v!r}: {e}") from None
    names = {f.split("!")[0].split(":")[0] for _, f, _, _ in parsed if f is not None}
    unknown = names - _MOVE_FIELDS
    if unknown:
        raise ValueError(
            f"unknown placeholder(s) {sorted(unknown)} in move_command {v!r}; use {{x}}, {{y}}, {{z}} (mm)"
        )
    if not names:
        raise ValueError(f"move_command {v!r} holds none of {{x}}, {{y}}, {{z}}: where would it move to?")
    try:
        v.format(x=-100.0, y=-34.0, z=-400.0)
    except (ValueError, KeyError, IndexError, TypeError) as e:
        raise ValueError(f"bad move_command {v!r}: {e}") from None
    return v


class CaptureSpec(_Spec):
    """How ``stiffmap capture`` takes the images from a live camera (``docs/capture.md``)."""

    #: Settled frames per image: averaged into one (``average = true``), or each its own repeat.
    frames: Annotated[Count, Field(ge=1, le=1000)] = 1
    average: bool = True
    #: How long the platform must stay still, within the measurement noise, before an image (s).
    settle_seconds: Annotated[Finite, _between(0.0, 3600.0, "s")] = 1.0
    #: Motion of the platform at rest (1 sigma per axis, mm), added to the noise of the test.
    vibration_mm: Annotated[Finite, _between(0.0, 10.0, "mm")] = 0.001
    #: Give up an image (with --yes) when no good settled frame came for this long (s).
    timeout_s: Annotated[Finite, _between(0.01, LIMITS["time_s"], "s")] = 120.0
    #: A command run to move the robot: {x}, {y}, {z} are the position in mm.
    move_command: Annotated[str, Strict(), AfterValidator(_check_move_command)] | None = None


class MeasurementSpec(_Spec):
    """How board poses are measured in the images."""

    #: "auto": photometric refinement of each chessboard pose (the blurred board fitted to
    #: every edge pixel; 3-6x more precise along the line of sight, about 50-120 ms per
    #: board), falling back to the corner pose when its consistency check fails;
    #: "corners": corner-based poses only (faster); "photometric": as auto.
    refine: Literal["auto", "photometric", "corners"] = "auto"


def _sign(v):
    if isinstance(v, bool) or v not in (1, -1):
        raise ValueError(f"sign must be 1 or -1 (-1 behind a mirror), got {v!r}")
    return v


class SensorRecordingSpec(_Spec):
    """One displacement-sensor recording: where, along which axis, which file."""

    point: list[Coord]
    direction: Literal["x", "y", "z", "-x", "-y", "-z"]
    file: FileName
    sign: Annotated[int, BeforeValidator(_sign)] = 1
    label: Text | None = None  # e.g. the point's number on the workspace drawing
    #: Plateaus by hand, [[start, end], ...] in s, when the automatic detection fails.
    step_times: list[Annotated[tuple[TimeS, TimeS], Field(strict=False)]] | None = None

    @field_validator("point")
    @classmethod
    def _point(cls, v):
        if len(v) not in (2, 3):
            raise ValueError(f"a point is [x, y] (planar) or [x, y, z] (mm), got {len(v)} coordinate(s)")
        return v

    @field_validator("step_times")
    @classmethod
    def _spans(cls, v):
        if v is not None:
            if len(v) < 2:
                raise ValueError("give at least 2 plateaus [start, end] (s)")
            if len(v) > 10_000:
                raise ValueError(f"{len(v)} plateaus; at most 10000")
            for a, b in v:
                if not b > a:
                    raise ValueError(f"a plateau [start, end] needs end > start, got [{a}, {b}]")
            for (_, b0), (a1, b1) in zip(v, v[1:], strict=False):
                if a1 < b0:
                    raise ValueError(
                        f"the plateaus must be in time order and not overlap; [{a1}, {b1}] starts before "
                        f"the previous one ends ({b0} s)"
                    )
        return v

    @model_validator(mode="after")
    def _direction_in_plane(self):
        if self.direction.endswith("z") and len(self.point) < 3:
            raise ValueError(
                f"direction {self.direction!r} needs a point [x, y, z]; this point is planar [x, y]"
            )
        return self


def _steps(v):
    if v is not None:
        if len(v) < 2:
            raise ValueError(f"a table of steps holds at least 2 loads, got {len(v)}")
        if len(v) > 10_000:
            raise ValueError(f"{len(v)} steps; at most 10000")
        if max(v) == min(v):
            raise ValueError("every step has the same load: no slope can be fitted")
    return v


class SensorSpec(_Spec):
    """Sensor campaigns: the conversion, the step detector and the recordings."""

    scale_um_per_v: Annotated[Finite, _between(*LIMITS["scale_um_per_v"], "um/V")] = 640.0
    range_v: Annotated[Finite, _between(*LIMITS["range_v"], "V")] = 8.0
    channel_map: dict[Text, Text] = Field(default_factory=dict)
    load_unit: Literal["kgf", "N", "V"] = "kgf"
    load_n_per_v: Annotated[Finite, _between(*LIMITS["load_n_per_v"], "N/V")] | None = None
    steps_kgf: Annotated[list[NonNegMassKg], AfterValidator(_steps)] | None = None
    steps_n: (
        Annotated[list[Annotated[Finite, _between(0.0, LIMITS["force_n"], "N")]], AfterValidator(_steps)]
        | None
    ) = None
    reference_load_n: Annotated[Finite, _between(1e-3, LIMITS["force_n"], "N")] = 490.5
    window_s: Annotated[Finite, _between(*LIMITS["window_s"], "s")] = 0.25
    min_plateau_s: Annotated[Finite, _between(*LIMITS["window_s"], "s")] = 0.5
    threshold_sigma: Annotated[Finite, _between(*LIMITS["threshold_sigma"], "")] = 5.0
    remove_drift: bool = True
    exclude_bad_samples: bool = False
    recordings: list[SensorRecordingSpec]

    @field_validator("channel_map")
    @classmethod
    def _channels(cls, v):
        try:
            parse_channel_map(",".join(f"{k}={c}" for k, c in v.items()) or None)
        except FieldError as e:  # this key's own problem: its reason (the key is named by the spec)
            raise ValueError(e.reason) from None
        if any("," in k or "=" in k or "," in c or "=" in c for k, c in v.items()):
            raise ValueError("a channel name holds ',' or '='")
        return v

    @model_validator(mode="after")
    def _consistent(self):
        if self.steps_kgf is not None and self.steps_n is not None:
            raise ValueError("give steps_kgf or steps_n, not both")
        if self.load_unit == "V" and self.load_n_per_v is None:
            raise ValueError("load_unit = 'V' needs load_n_per_v (the load cell's scale, N/V)")
        if self.load_n_per_v is not None and self.load_unit != "V":
            raise ValueError("load_n_per_v is the scale of a load channel in volts: set load_unit = 'V'")
        if not self.recordings:
            raise ValueError("sensor.recordings = the list is empty: name at least one recording")
        if len(self.recordings) > LIMITS["recordings"]:
            raise ValueError(f"{len(self.recordings)} recordings; at most {LIMITS['recordings']}")
        seen: dict[str, int] = {}
        for i, r in enumerate(self.recordings):
            if r.file in seen:
                raise ValueError(
                    f"sensor.recordings[{i}] = file {r.file!r} is already recordings[{seen[r.file]}]: "
                    "each recording is one file"
                )
            seen[r.file] = i
        dims = {len(r.point) for r in self.recordings}
        if len(dims) > 1:
            raise ValueError("the recordings' points mix [x, y] and [x, y, z]: give every point the same way")
        return self


class CampaignSpec(_Spec):
    """A whole campaign (every key, with comments: :data:`stiffmap.campaign.spec_writer.EXAMPLE_TOML`)."""

    name: Text = "campaign"
    kind: Literal["vision", "sensor"] = "vision"
    g: Annotated[Finite, _between(*LIMITS["g"], "m/s^2")] = 9.80665
    repeats: Annotated[Count, Field(ge=1, le=LIMITS["repeats"])] = 1
    robot: RobotSpec = Field(default_factory=RobotSpec)
    camera: CameraSpec | None = None
    cameras: CamerasSpec | None = None
    targets: TargetsSpec | None = None
    positions: PositionsSpec | None = None
    loads: LoadsSpec | None = None
    images: ImagesSpec = Field(default_factory=ImagesSpec)
    measurement: MeasurementSpec = Field(default_factory=MeasurementSpec)
    sensor: SensorSpec | None = None
    capture: CaptureSpec | None = None

    @property
    def capture_settings(self) -> CaptureSpec:
        """The ``[capture]`` section, or its defaults when there is none."""
        return self.capture if self.capture is not None else CaptureSpec()

    @model_validator(mode="after")
    def _complete(self):
        if self.positions is not None and self.positions.poses is not None:
            kind = self.robot.kind
            if kind is None or not kind.turning_platform:
                turning = " or ".join(f'"{k.name}"' for k in ROBOT_KINDS.values() if k.turning_platform)
                raise ValueError(
                    f"positions.poses = orientations need a robot whose platform turns: robot.model = "
                    f"{turning} (a dim = 6 legs TOML), not {self.robot.model!r}; give the positions as 'list'"
                )
        if self.positions is not None and self.positions.q_deg is not None:
            kind = self.robot.kind
            if kind is None or not kind.configurations:
                serial = " or ".join(f'"{k.name}"' for k in ROBOT_KINDS.values() if k.configurations)
                raise ValueError(
                    f"positions.q_deg gives joint configurations: it needs robot.model = {serial}"
                )
        if self.kind == "vision":
            if self.camera is not None and self.cameras is not None:
                raise ValueError("give [camera] (one camera) or [cameras] (a rig of several), not both")
            if self.cameras is not None:
                for key in ("unloaded", "loaded"):
                    if CAMERA_FIELD not in getattr(self.images, key):
                        raise ValueError(
                            f"images.{key} = {getattr(self.images, key)!r}: with [cameras] each image is "
                            "a set of one image per camera, so the pattern must hold {camera}"
                        )
            elif self.images.per_camera:
                raise ValueError(
                    "the [images] patterns hold {camera}: that needs a [cameras] section (a rig file from "
                    "stiffmap calibrate-rig)"
                )
            missing = [k for k in ("camera", "targets", "positions", "loads") if getattr(self, k) is None]
            if self.cameras is not None:
                missing.remove("camera")
            if missing:
                raise ValueError(
                    f"a vision campaign needs the section(s) {', '.join('[' + m + ']' for m in missing)}"
                )
            pts = self.positions.points or []
            flat = [i for i, pt in enumerate(pts) if len(pt) != 3]
            if flat:
                raise ValueError(
                    f"positions.list[{flat[0]}] = {pts[flat[0]]} has {len(pts[flat[0]])} coordinates; a "
                    "vision campaign measures 3-D displacements, so its positions are [x, y, z] (mm)"
                )
            try:
                self.loads.resolve(self.g)
            except ValueError as e:
                key = "loads.friction" if "friction" in str(e) else "loads"
                raise ValueError(f"{key} = {e}") from None
            if self.repeats > 1 and "{repeat" not in self.images.loaded:
                raise ValueError("with repeats > 1 the images.loaded pattern must contain {repeat}")
            n = self.positions.count() * self.loads.count() * self.repeats * 2
            if n > LIMITS["images"]:
                raise ValueError(
                    f"repeats = {self.repeats} with {self.positions.count()} positions and "
                    f"{self.loads.count()} load cases name {n} images; a campaign may name at most "
                    f"{LIMITS['images']}"
                )
            cap = self.capture
            if cap is not None and not cap.average and cap.frames > 1 and cap.frames != self.repeats:
                raise ValueError(
                    f"capture.frames = {cap.frames} with average = false keeps the frames as the "
                    f"repeats: it must equal repeats = {self.repeats} (or set average = true)"
                )
        elif self.sensor is None:
            raise ValueError("a sensor campaign needs a [sensor] section")
        return self


# ---------------------------------------------------------------------- loading


def parse_spec(text: str, source: str = SPEC_NAME) -> CampaignSpec:
    """Validate the text of a ``campaign.toml``.

    A leading byte-order mark (which some Windows editors write) is ignored.

    Raises
    ------
    InputError
        ``source: line N, key 'a.b': what is wrong`` for each problem (joined by "; ").
    """
    text = text.removeprefix("\ufeff")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"not valid TOML: {e}", source=source) from None
    except RecursionError:
        raise InputError("not valid TOML here: arrays or tables nested too deeply", source=source) from None
    except ValueError:  # an integer of thousands of digits
        raise InputError("not a usable TOML file: a number has thousands of digits", source=source) from None
    try:
        return CampaignSpec.model_validate(data)
    except ValidationError as e:
        raise InputError(validation_message(e, text, CampaignSpec), source=source) from None
    except RecursionError:
        raise InputError("arrays or tables nested too deeply", source=source) from None


def decode_spec(data: bytes, source: str = SPEC_NAME) -> str:
    """The text of ``campaign.toml``'s bytes: UTF-8 (with or without a byte-order mark).

    Raises
    ------
    InputError
        UTF-16 or UTF-32 text, or bytes that are not UTF-8 (naming the line and column).
    """
    for bom, name in (
        (b"\xff\xfe\x00\x00", "UTF-32"),
        (b"\x00\x00\xfe\xff", "UTF-32"),
        (b"\xff\xfe", "UTF-16"),
        (b"\xfe\xff", "UTF-16"),
    ):
        if data.startswith(bom):
            raise InputError(f"is {name} text; save it as UTF-8", source=source)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        col = e.start - (data.rfind(b"\n", 0, e.start) + 1) + 1
        raise InputError(
            f"line {line}, column {col}: not UTF-8 text (byte 0x{data[e.start]:02x}); save it as UTF-8",
            source=source,
        ) from None


def load_spec(path: str | Path) -> CampaignSpec:
    """Read ``campaign.toml`` (a file, or a campaign directory holding one)."""
    p = Path(path)
    if p.is_dir():
        p = p / SPEC_NAME
    if not p.is_file():
        if p.is_dir():
            raise InputError(f"is a folder; {SPEC_NAME} must be a file", source=str(p))
        raise InputError(f"no {SPEC_NAME} found (run 'stiffmap init' to write an example)", source=str(p))
    try:
        size = p.stat().st_size
        if size > MAX_SPEC_BYTES:
            raise InputError(
                f"{size} bytes; a campaign.toml of more than {MAX_SPEC_BYTES} bytes is not a spec",
                source=str(p),
            )
        data = p.read_bytes()
    except OSError as e:
        raise InputError(f"cannot read: {e.strerror or e}", source=str(p)) from None
    return parse_spec(decode_spec(data, str(p)), source=str(p))
