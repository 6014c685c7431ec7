"""The campaign spec, ``campaign.toml``: what was measured, how, and where the files are.

A campaign is a directory (DESIGN.md section 4)::

    CAMPAIGN/
      campaign.toml        # this spec
      camera.json          # calibrated camera (vision campaigns)
      images/...           # raw images, never modified
      stiffmap.db          # results (written by ``stiffmap run``)
      report/              # derived report

The spec is validated with pydantic; every problem is reported with the key
(``targets.fixed.square_mm``) and the line of ``campaign.toml`` it is on.
``stiffmap init DIR`` writes a commented example (:data:`EXAMPLE_TOML`).
"""

from __future__ import annotations

import difflib
import math
import re
import string
import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from ..errors import InputError
from ..targets import parse_board_size

__all__ = [
    "CampaignSpec",
    "load_spec",
    "parse_spec",
    "dump_spec",
    "SPEC_NAME",
    "EXAMPLE_TOML",
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
    from ..geometry import as_transform

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
        from ..models import MECHANISMS

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
            from ..models.presets import preset_points

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
        from ..loads import LoadCase, load_from_mass, preset, with_friction

        if self.preset is not None:
            loads = preset(self.preset, g=g)
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
    """A whole campaign (see :data:`EXAMPLE_TOML` for every key with comments)."""

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


def _table_paths(text: str) -> list[tuple[int, tuple]]:
    """(line number, key path) of every ``key =`` line and table header in a TOML text."""
    out: list[tuple[int, tuple]] = []
    table: tuple = ()
    counters: dict[tuple, int] = {}
    header = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?")
    keyline = re.compile(r"^\s*([A-Za-z0-9_\-\"'.]+)\s*=")
    for i, line in enumerate(text.splitlines(), start=1):
        m = header.match(line)
        if m:
            parts = tuple(p.strip().strip("\"'") for p in m.group(2).split("."))
            if m.group(1) == "[[":
                counters[parts] = counters.get(parts, -1) + 1
                table = (*parts, counters[parts])
            else:
                table = parts
            out.append((i, table))
            continue
        m = keyline.match(line)
        if m:
            key = tuple(p.strip().strip("\"'") for p in m.group(1).split("."))
            out.append((i, table + key))
    return out


def _line_of(paths: list[tuple[int, tuple]], loc: tuple) -> int | None:
    best, best_len = None, -1
    for line, path in paths:
        n = 0
        for a, b in zip(path, loc, strict=False):
            if str(a) != str(b):
                break
            n += 1
        if n == len(path) and n > best_len:
            best, best_len = line, n
    return best


_KNOWN_KEYS: dict[tuple, list[str]] = {}


def _known_keys(loc: tuple) -> list[str]:
    """Names of the keys valid at the table ``loc`` (for 'did you mean')."""
    model: Any = CampaignSpec
    for part in loc:
        if isinstance(part, int):
            continue
        field = getattr(model, "model_fields", {}).get(part)
        if field is None:
            return []
        ann = field.annotation
        candidates = [ann, *getattr(ann, "__args__", ())]
        nxt = None
        for c in candidates:
            for cc in (c, *getattr(c, "__args__", ())):
                if isinstance(cc, type) and issubclass(cc, BaseModel):
                    nxt = cc
        if nxt is None:
            return []
        model = nxt
    return list(getattr(model, "model_fields", {}))


def _describe(err: dict) -> str:
    kind = err["type"]
    loc = tuple(err["loc"])
    if kind == "extra_forbidden":
        known = _known_keys(loc[:-1])
        close = difflib.get_close_matches(str(loc[-1]), known, n=1)
        hint = (
            f" (did you mean {close[0]!r}?)"
            if close
            else (f" (expected one of {', '.join(known)})" if known else "")
        )
        return f"unknown key{hint}"
    if kind == "missing":
        return "missing key"
    msg = err["msg"]
    msg = msg.removeprefix("Value error, ")
    if "input" in err and kind not in ("model_type",) and not isinstance(err["input"], dict):
        shown = repr(err["input"])
        if len(shown) > 60:
            shown = shown[:57] + "..."
        msg = f"{msg} (got {shown})"
    return msg


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
        paths = _table_paths(text)
        msgs = []
        for err in e.errors():
            loc = tuple(x for x in err["loc"] if not (isinstance(x, str) and x.startswith("function-")))
            # pydantic adds union member names such as 'list[float]'; drop them.
            loc = tuple(
                x for x in loc if not (isinstance(x, str) and ("[" in x or x in ("str", "float", "int")))
            )
            text_msg = _describe(err)
            if not loc:
                # A check across sections names its key at the start of its message.
                m = re.match(r"([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+)(?:\[(\d+)\])? = ", text_msg)
                if m:
                    loc = tuple(m.group(1).split(".")) + ((int(m.group(2)),) if m.group(2) else ())
                    text_msg = text_msg[m.end() :]
            line = _line_of(paths, loc) if loc else None
            key = ".".join(str(x) for x in loc) if loc else "(top level)"
            where = f"line {line}, " if line else ""
            msgs.append(f"{where}key {key!r}: {text_msg}")
        # One line per campaign: the problems joined.
        uniq = list(dict.fromkeys(msgs))
        raise InputError("; ".join(uniq), source=source) from None


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


# ---------------------------------------------------------------------- writing


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"cannot write a non-finite number {v} to TOML")
        return repr(float(v))
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    if isinstance(v, np.generic):
        return _toml_value(v.item())
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


#: What each key means, written beside it by :func:`dump_spec` (the same words as EXAMPLE_TOML).
KEY_COMMENTS = {
    "kind": '"vision" (camera + boards) or "sensor" (LDV/DAQ recordings)',
    "g": "m/s^2, turns masses into forces once",
    "repeats": "repeated measurements of each load case (ISO 5725)",
    "robot.model": '"delta", "3prr", or "none" for measurements only',
    "robot.params": "model parameters to start from (the model's defaults for the others)",
    "robot.fit": "parameters fitted to the measurements",
    "camera.file": "from: stiffmap calibrate IMAGES... --board COLSxROWS --square-mm S --out camera.json",
    "targets.fixed.board": "the board fixed to the robot base: inner corners COLSxROWS",
    "targets.fixed.fixed2base": "its pose in the robot base frame (4x4, mm)",
    "targets.mobile.board": "the board on the moving platform (a different size from the fixed one)",
    "targets.mobile.point_mm": "the point whose displacement is reported, in the mobile board frame (mm)",
    "targets.mobile.mobile2tcp": "the mobile board's pose in the tool frame (4x4, mm)",
    "positions.preset": "paper48: 16 positions on each of z = -200, -310, -400 mm",
    "positions.list": "[x, y, z] in mm, base frame",
    "loads.preset": "paper9: 0.5, 0.2, 0.1 kg along +y, -x, -z",
    "loads.cases": "{mass_kg, direction} or {force_n = [fx, fy, fz]} (N, base frame)",
    "loads.friction": "pulley friction, subtracted from the loads along these directions",
    "images.unloaded": "file pattern, 1-based {position}, {load}, {repeat}",
    "images.loaded": "file pattern, 1-based {position}, {load}, {repeat}",
    "images.pairing": '"pairs", or "mean-reference" when the robot stays at each position for all its loads',
    "measurement.refine": '"auto" (photometric poses, corner poses as fallback) or "corners" (faster)',
    "sensor.scale_um_per_v": "displacement sensor scale, um/V",
    "sensor.range_v": "analog output range, +-V (saturation)",
    "sensor.load_unit": '"kgf", "N" or "V" (with load_n_per_v)',
    "sensor.reference_load_n": "load of the static error, N (50 kgf = 490.5 N)",
    "sensor.recordings": "sign = -1 behind a mirror; step_times = [[start, end], ...] s: plateaus by hand",
}


def _commented(line: str, comment: str | None) -> list[str]:
    """The line with its comment beside it, or above it when the line is long."""
    if not comment:
        return [line]
    if len(line) > 50:
        return [f"# {line.split(' =', 1)[0]}: {comment}", line]
    return [f"{line:<26} # {comment}" if len(line) < 26 else f"{line}  # {comment}"]


def _toml_table(prefix: str, d: dict, out: list[str], comments: dict[str, str] | None = None) -> None:
    scalars = {k: v for k, v in d.items() if not isinstance(v, dict) or k in ("params", "channel_map")}
    tables = {k: v for k, v in d.items() if k not in scalars}
    if prefix and scalars:
        out.append(f"\n[{prefix}]")
    for k, v in scalars.items():
        note = (comments or {}).get(f"{prefix}.{k}" if prefix else k)
        long_list = isinstance(v, list) and v and all(isinstance(x, (list, tuple)) for x in v) and len(v) > 4
        if isinstance(v, list) and v and (all(isinstance(x, dict) for x in v) or long_list):
            if note:
                out.append(f"# {k}: {note}")
            out.append(f"{k} = [")
            out.extend(f"  {_toml_value(x)}," for x in v)
            out.append("]")
        else:
            out.extend(_commented(f"{k} = {_toml_value(v)}", note))
    for k, v in tables.items():
        _toml_table(f"{prefix}.{k}" if prefix else k, v, out, comments)


def dump_spec(spec: CampaignSpec, header: str = "", *, comments: bool = True) -> str:
    """TOML text of a spec (round-trips through :func:`parse_spec`), keys explained in comments."""
    data = spec.model_dump(exclude_none=True, mode="python", by_alias=True)
    out: list[str] = []
    if header:
        out.extend("# " + ln if ln else "#" for ln in header.strip().splitlines())
    _toml_table("", data, out, KEY_COMMENTS if comments else None)
    text = "\n".join(out) + "\n"
    parse_spec(text)  # never write a spec we could not read back
    return text


EXAMPLE_TOML = """\
# stiffmap campaign: what was measured, how, and where the files are.
# Units: mm, N, kg (converted once with g), rad. Paths are relative to this directory.

name = "my robot, 2026-11"
kind = "vision"            # "vision" (camera + boards) or "sensor" (LDV/DAQ recordings)
g = 9.80665                # m/s^2, turns masses into forces (the reference study used 9.81)
repeats = 10               # repeated measurements of each load case (ISO 5725)

[robot]
model = "delta"            # "delta", "3prr", or "none" for measurements only
params = {}                # model parameters to start from, e.g. {k_theta = 450000.0}

[camera]
file = "camera.json"       # from: stiffmap calibrate IMAGES... --board 13x12 --square-mm 30 --out camera.json

[targets.fixed]            # the board fixed to the robot base
board = "9x6"              # inner corners COLSxROWS
square_mm = 10.0
# its pose in the robot base frame (4x4, mm): the reference study's motor-support board
fixed2base = [[1.0, 0.0, 0.0, -75.63], [0.0, 0.0, 1.0, 188.10], [0.0, -1.0, 0.0, 31.00], [0.0, 0.0, 0.0, 1.0]]

[targets.mobile]           # the board on the moving platform (a different size from the fixed one)
board = "5x4"
square_mm = 10.0
point_mm = [0.0, 0.0, 0.0] # the point whose displacement is reported, in the mobile board frame

# positions, mm in the base frame: one of
#   preset = "paper48" | list = [[x, y, z], ...] | grid = {x = [...], y = [...], z = [...]}
[positions]
preset = "paper48"         # 16 positions on each of z = -200, -310, -400 mm

# loads: one of
#   preset = "paper9" | cases = [{mass_kg = 0.5, direction = "+y"}, {force_n = [0.0, 0.0, -4.9]}]
[loads]
preset = "paper9"          # 0.5, 0.2, 0.1 kg along +y, -x, -z
friction = {mass_kg = 0.028, std_kg = 0.008, directions = ["x", "y"]}   # pulley friction, subtracted

[images]                   # 1-based {position}, {load}, {repeat}
unloaded = "images/p{position:02d}/l{load:02d}_r{repeat:02d}_unloaded.png"
loaded = "images/p{position:02d}/l{load:02d}_r{repeat:02d}_loaded.png"
pairing = "pairs"          # or "mean-reference" when the robot stays at each position for all its loads
"""
