"""The campaign spec, ``campaign.toml``: what was measured, how, and where the files are.

A campaign is a directory (DESIGN.md section 4)::

    CAMPAIGN/
      campaign.toml        # this spec
      camera.json          # calibrated camera (vision campaigns)
      images/...           # raw images, never modified
      stiffmap.db          # results (written by ``stiffmap run``)
      report/              # derived report

This module holds the schema (pydantic models, one per table) and reading it:
:func:`load_spec`, :func:`parse_spec`. Every problem is reported with the key
(``targets.fixed.square_mm``) and the line of ``campaign.toml`` it is on
(:mod:`stiffmap.campaign.spec_errors`). Writing a spec, with every key
explained, and the commented example ``stiffmap init DIR`` writes are in
:mod:`stiffmap.campaign.spec_writer`.
"""

from __future__ import annotations

import string
import tomllib
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from ..errors import InputError
from ..geometry import as_transform
from ..loads import LoadCase, load_from_mass, with_friction
from ..loads import preset as load_preset
from ..models import MECHANISMS
from ..models.presets import preset_points
from ..targets import parse_board_size
from .spec_errors import validation_message

__all__ = [
    "CampaignSpec",
    "load_spec",
    "parse_spec",
    "SPEC_NAME",
    "DEFAULT_UNLOADED",
    "DEFAULT_LOADED",
]

SPEC_NAME = "campaign.toml"
DEFAULT_UNLOADED = "images/p{position:02d}/l{load:02d}_r{repeat:02d}_unloaded.png"
DEFAULT_LOADED = "images/p{position:02d}/l{load:02d}_r{repeat:02d}_loaded.png"

PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]


class _Spec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _check_transform(v: list[list[float]], name: str) -> list[list[float]]:
    a = np.asarray(v, dtype=float)
    if a.shape != (4, 4):
        raise ValueError(f"must be a 4x4 matrix (4 rows of 4 numbers), got shape {a.shape}")
    try:
        as_transform(a, name, atol=1e-4)
    except ValueError as e:
        raise ValueError(str(e).split(": ", 1)[-1]) from None
    return v


class RobotSpec(_Spec):
    """The robot: a model to fit and draw beside the measurements, or ``none``."""

    model: Literal["delta", "3prr", "none"] = "none"
    params: dict[str, Finite] = Field(default_factory=dict)
    #: Parameters fitted to the measurements (default: k_theta for the Delta, kj for the 3PRR).
    fit: list[str] | None = None

    def mechanism(self, **overrides: float):
        """The model with ``params`` (then ``overrides``) applied; ValueError on a bad parameter."""
        if self.model == "none":
            raise ValueError("robot.model is 'none': the campaign has no model")
        model = MECHANISMS[self.model]()
        params = {**self.params, **overrides}
        try:
            return model.with_params(**params) if params else model
        except TypeError as e:
            raise ValueError(str(e)) from None

    def fitted_names(self) -> tuple[str, ...]:
        """The parameters to fit: ``fit``, or the model's default."""
        if self.fit:
            return tuple(self.fit)
        return ("kj",) if self.model == "3prr" else ("k_theta",)


class CameraSpec(_Spec):
    """The calibrated camera (``camera.json``, relative to the campaign directory)."""

    file: str = "camera.json"


class BoardSpec(_Spec):
    board: str
    square_mm: PositiveFloat

    @field_validator("board")
    @classmethod
    def _board(cls, v: str) -> str:
        parse_board_size(v)
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

    point_mm: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.0)
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
    x: list[Finite]
    y: list[Finite]
    z: list[Finite] = Field(default_factory=lambda: [0.0])


class PositionsSpec(_Spec):
    """Exactly one of ``preset``, ``list`` or ``grid`` (mm, base frame)."""

    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)

    preset: str | None = None
    points: list[list[Finite]] | None = Field(default=None, alias="list")
    grid: GridSpec | None = None

    @model_validator(mode="after")
    def _one(self):
        given = [
            k
            for k, a in (("preset", "preset"), ("list", "points"), ("grid", "grid"))
            if getattr(self, a) is not None
        ]
        if len(given) != 1:
            raise ValueError(
                "give exactly one of 'preset', 'list' or 'grid'"
                + (f" (got {', '.join(given)})" if given else "")
            )
        if self.points is not None:
            if not self.points:
                raise ValueError("'list' is empty")
            for i, p in enumerate(self.points):
                if len(p) not in (2, 3):
                    raise ValueError(f"list[{i}] must be [x, y, z] (or [x, y] for a planar robot), got {p}")
        return self

    def resolve(self) -> np.ndarray:
        """Positions, shape (n, 3) mm (z = 0 for planar points)."""
        if self.preset is not None:
            pts = np.asarray(preset_points(self.preset), dtype=float)
        elif self.points is not None:
            pts = np.array([list(p) + [0.0] * (3 - len(p)) for p in self.points], dtype=float)
        else:
            g = self.grid
            X, Y, Z = np.meshgrid(g.x, g.y, g.z, indexing="ij")
            pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
        if pts.shape[1] == 2:
            pts = np.c_[pts, np.zeros(len(pts))]
        return pts


class LoadCaseSpec(_Spec):
    """A load: a mass along a direction, or a force vector in N (base frame)."""

    mass_kg: PositiveFloat | None = None
    direction: str | list[Finite] | None = None
    force_n: tuple[Finite, Finite, Finite] | None = None
    label: str = ""

    @model_validator(mode="after")
    def _one(self):
        if self.force_n is not None and (self.mass_kg is not None or self.direction is not None):
            raise ValueError("give either force_n, or mass_kg with direction, not both")
        if self.force_n is None and (self.mass_kg is None or self.direction is None):
            raise ValueError("give force_n = [fx, fy, fz] (N), or mass_kg with direction")
        if self.force_n is not None and not any(self.force_n):
            raise ValueError("force_n is zero")
        return self


class FrictionSpec(_Spec):
    """Friction subtracted from the loads applied through a pulley (the reference: X and Y)."""

    mass_kg: NonNegFloat
    std_kg: NonNegFloat = 0.0
    directions: list[Literal["x", "y", "z"]] = Field(default_factory=lambda: ["x", "y"])


class LoadsSpec(_Spec):
    """Exactly one of ``preset`` (``paper9``) or ``cases``; optional friction."""

    preset: str | None = None
    cases: list[LoadCaseSpec] | None = None
    friction: FrictionSpec | None = None

    @model_validator(mode="after")
    def _one(self):
        if (self.preset is None) == (self.cases is None):
            raise ValueError("give exactly one of 'preset' or 'cases'")
        if self.cases is not None and not self.cases:
            raise ValueError("'cases' is empty")
        return self

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


_FIELDS = {"position", "load", "repeat"}


def _check_pattern(v: str, required: set[str]) -> str:
    try:
        names = {f for _, f, _, _ in string.Formatter().parse(v) if f is not None}
    except ValueError as e:
        raise ValueError(f"bad pattern {v!r}: {e}") from None
    unknown = {n.split("!")[0].split(":")[0] for n in names} - _FIELDS
    if unknown:
        raise ValueError(
            f"unknown placeholder(s) {sorted(unknown)} in {v!r}; use {{position}}, {{load}}, {{repeat}}"
        )
    missing = required - names
    if missing:
        raise ValueError(f"pattern {v!r} must contain {', '.join('{' + m + '}' for m in sorted(missing))}")
    try:
        v.format(position=1, load=1, repeat=1)
    except (ValueError, KeyError, IndexError) as e:
        raise ValueError(f"bad pattern {v!r}: {e}") from None
    return v


class ImagesSpec(_Spec):
    """File-name patterns of the images, relative to the campaign directory.

    Placeholders ``{position}``, ``{load}``, ``{repeat}`` are 1-based indices and
    accept format specs (``{position:02d}``). The unloaded pattern may omit
    ``{load}`` when one unloaded image serves every load case of a repeat.
    """

    unloaded: str = DEFAULT_UNLOADED
    loaded: str = DEFAULT_LOADED
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
        """Relative path of one image (1-based indices)."""
        pat = self.unloaded if state == "unloaded" else self.loaded
        return pat.format(position=position, load=load, repeat=repeat)


class MeasurementSpec(_Spec):
    """How board poses are measured in the images."""

    #: "auto": photometric refinement of each chessboard pose (the blurred board fitted to
    #: every edge pixel; 3-6x more precise along the line of sight, about 50-120 ms per
    #: board), falling back to the corner pose when its consistency check fails;
    #: "corners": corner-based poses only (faster); "photometric": as auto.
    refine: Literal["auto", "photometric", "corners"] = "auto"


class SensorRecordingSpec(_Spec):
    """One displacement-sensor recording: where, along which axis, which file."""

    point: list[Finite]
    direction: Literal["x", "y", "z", "-x", "-y", "-z"]
    file: str
    sign: Literal[1, -1] = 1
    label: str | None = None  # e.g. the point's number on the workspace drawing
    #: Plateaus by hand, [[start, end], ...] in s, when the automatic detection fails.
    step_times: list[tuple[NonNegFloat, NonNegFloat]] | None = None

    @field_validator("step_times")
    @classmethod
    def _spans(cls, v):
        if v is not None:
            if len(v) < 2:
                raise ValueError("give at least 2 plateaus [start, end] (s)")
            for a, b in v:
                if not b > a:
                    raise ValueError(f"a plateau [start, end] needs end > start, got [{a}, {b}]")
        return v


class SensorSpec(_Spec):
    """Sensor campaigns: the conversion, the step detector and the recordings."""

    scale_um_per_v: PositiveFloat = 640.0
    range_v: PositiveFloat = 8.0
    channel_map: dict[str, str] = Field(default_factory=dict)
    load_unit: Literal["kgf", "N", "V"] = "kgf"
    load_n_per_v: PositiveFloat | None = None
    steps_kgf: list[NonNegFloat] | None = None
    steps_n: list[NonNegFloat] | None = None
    reference_load_n: PositiveFloat = 490.5
    window_s: PositiveFloat = 0.25
    min_plateau_s: PositiveFloat = 0.5
    threshold_sigma: PositiveFloat = 5.0
    remove_drift: bool = True
    exclude_bad_samples: bool = False
    recordings: list[SensorRecordingSpec]

    @model_validator(mode="after")
    def _consistent(self):
        if self.steps_kgf is not None and self.steps_n is not None:
            raise ValueError("give steps_kgf or steps_n, not both")
        if self.load_unit == "V" and self.load_n_per_v is None:
            raise ValueError("load_unit = 'V' needs load_n_per_v (the load cell's scale, N/V)")
        if self.load_n_per_v is not None and self.load_unit != "V":
            raise ValueError("load_n_per_v is the scale of a load channel in volts: set load_unit = 'V'")
        return self


class CampaignSpec(_Spec):
    """A whole campaign (every key, with comments: :data:`stiffmap.campaign.spec_writer.EXAMPLE_TOML`)."""

    name: str = "campaign"
    kind: Literal["vision", "sensor"] = "vision"
    g: PositiveFloat = 9.80665
    repeats: Annotated[int, Field(ge=1)] = 1
    robot: RobotSpec = Field(default_factory=RobotSpec)
    camera: CameraSpec | None = None
    targets: TargetsSpec | None = None
    positions: PositionsSpec | None = None
    loads: LoadsSpec | None = None
    images: ImagesSpec = Field(default_factory=ImagesSpec)
    measurement: MeasurementSpec = Field(default_factory=MeasurementSpec)
    sensor: SensorSpec | None = None

    @model_validator(mode="after")
    def _complete(self):
        if self.kind == "vision":
            missing = [k for k in ("camera", "targets", "positions", "loads") if getattr(self, k) is None]
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
            if self.repeats > 1 and "{repeat" not in self.images.loaded:
                raise ValueError("with repeats > 1 the images.loaded pattern must contain {repeat}")
        elif self.sensor is None:
            raise ValueError("a sensor campaign needs a [sensor] section")
        return self


# ---------------------------------------------------------------------- loading


def parse_spec(text: str, source: str = SPEC_NAME) -> CampaignSpec:
    """Validate the text of a ``campaign.toml``.

    Raises
    ------
    InputError
        ``source: line N, key 'a.b': what is wrong`` for each problem (joined by "; ").
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"not valid TOML: {e}", source=source) from None
    try:
        return CampaignSpec.model_validate(data)
    except ValidationError as e:
        raise InputError(validation_message(e, text, CampaignSpec), source=source) from None


def load_spec(path: str | Path) -> CampaignSpec:
    """Read ``campaign.toml`` (a file, or a campaign directory holding one)."""
    p = Path(path)
    if p.is_dir():
        p = p / SPEC_NAME
    if not p.is_file():
        raise InputError(f"no {SPEC_NAME} found (run 'stiffmap init' to write an example)", source=str(p))
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read: {e}", source=str(p)) from None
    return parse_spec(text, source=str(p))
