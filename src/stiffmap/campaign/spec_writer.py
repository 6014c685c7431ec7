"""Writing ``campaign.toml``: a spec as TOML with every key explained, and the example to start from.

:func:`dump_spec` writes a :class:`~stiffmap.campaign.spec.CampaignSpec` (the
virtual test-bed's campaigns are written with it) with :data:`KEY_COMMENTS`
beside the keys; :data:`EXAMPLE_TOML` is the commented example ``stiffmap init
DIR`` writes. Both read back with :func:`stiffmap.campaign.spec.parse_spec`.
"""

from __future__ import annotations

import math
import string
from typing import Any

import numpy as np

from .spec import CampaignSpec, parse_spec

__all__ = ["dump_spec", "EXAMPLE_TOML", "KEY_COMMENTS"]


_TOML_ESCAPES = {"\\": "\\\\", '"': '\\"', "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}


def _toml_char(c: str) -> str:
    """One character of a TOML basic string: escaped when TOML does not allow it as it is
    (quote, backslash, and every control character: a label read from a CSV may hold one)."""
    if c in _TOML_ESCAPES:
        return _TOML_ESCAPES[c]
    if c < " " or c == "\x7f":
        return f"\\u{ord(c):04x}"
    return c


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
        return '"' + "".join(_toml_char(c) for c in v) + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    if isinstance(v, np.generic):
        return _toml_value(v.item())
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


#: What each key means: written beside it by :func:`dump_spec`, and in :data:`EXAMPLE_TOML` where
#: the example says the same (its other comments carry the example's own values).
KEY_COMMENTS = {
    "kind": '"vision" (camera + boards) or "sensor" (LDV/DAQ recordings)',
    "g": "m/s^2, turns masses into forces once",
    "repeats": "repeated measurements of each load case (ISO 5725)",
    "robot.model": '"delta", "3prr", "urdf" (serial, from its URDF), "legs" (parallel, by its legs), "none"',
    "robot.params": "model parameters to start from (the model's defaults for the others)",
    "robot.fit": "parameters fitted to the measurements",
    "robot.urdf": "the serial robot's URDF, relative to this folder (lengths in metres)",
    "robot.tip_frame": "the URDF link that carries the measured point",
    "robot.tip_offset_mm": "the measured point in that link's frame (mm)",
    "robot.tool_rpy_deg": "the tool's orientation at every position (roll, pitch, yaw in degrees)",
    "robot.q_seed_deg": "where inverse kinematics starts (degrees): the branch of every configuration",
    "robot.legs": "the TOML file describing the robot's legs (docs/models.md)",
    "positions.q_deg": "joint configurations (degrees), one per position",
    "positions.poses": "a platform that turns (dim = 6 legs): [x, y, z, roll, pitch, yaw], mm and degrees",
    "loads.point_mm": "where the loads act, from the measured point, base axes (mm)",
    "camera.file": "from: stiffmap calibrate IMAGES... --board COLSxROWS --square-mm S --out camera.json",
    "cameras.rig": "several cameras, from: stiffmap calibrate-rig --camera NAME=GLOB ... --out rig.json",
    "cameras.names": "the rig's cameras (a check); [images] patterns hold {camera}",
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
    "images.unloaded": "file pattern, 1-based {position}, {load}, {repeat} (and {camera} with [cameras])",
    "images.loaded": "file pattern, 1-based {position}, {load}, {repeat} (and {camera} with [cameras])",
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


_EXAMPLE_TEMPLATE = """\
# stiffmap campaign: what was measured, how, and where the files are.
# Units: mm, N, kg (converted once with g), rad. Paths are relative to this directory.

name = "my robot, 2026-11"
kind = "vision"            # ${kind}
g = 9.80665                # m/s^2, turns masses into forces (the reference study used 9.81)
repeats = 10               # ${repeats}

[robot]
model = "delta"            # ${robot.model}
params = {}                # model parameters to start from, e.g. {k_theta = 450000.0}

[camera]
file = "camera.json"       # from: stiffmap calibrate IMAGES... --board 13x12 --square-mm 30 --out camera.json
# Several cameras instead (a rig): replace [camera] by
#   [cameras]
#   rig = "rig.json"  # from: stiffmap calibrate-rig --camera left='cal/l*.png' ... --out rig.json
# and put {camera} in the [images] patterns (e.g. images/p{position:02d}/..._loaded_{camera}.png).

[targets.fixed]            # the board fixed to the robot base
board = "9x6"              # inner corners COLSxROWS
square_mm = 10.0
# ${targets.fixed.fixed2base}: the reference study's motor-support board
fixed2base = [[1.0, 0.0, 0.0, -75.63], [0.0, 0.0, 1.0, 188.10], [0.0, -1.0, 0.0, 31.00], [0.0, 0.0, 0.0, 1.0]]

[targets.mobile]           # ${targets.mobile.board}
board = "5x4"
square_mm = 10.0
point_mm = [0.0, 0.0, 0.0] # the point whose displacement is reported, in the mobile board frame

# positions, mm in the base frame: one of
#   preset = "paper48" | list = [[x, y, z], ...] | grid = {x = [...], y = [...], z = [...]}
#   (a platform that turns, a dim = 6 legs TOML: poses = [[x, y, z, roll, pitch, yaw], ...], degrees)
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


class _KeyTemplate(string.Template):
    """``${robot.model}``: the comment of a key of :data:`KEY_COMMENTS`."""

    idpattern = r"[a-z_][a-z0-9_.]*"


#: The commented example campaign.toml (``stiffmap init DIR``).
EXAMPLE_TOML = _KeyTemplate(_EXAMPLE_TEMPLATE).substitute(KEY_COMMENTS)
