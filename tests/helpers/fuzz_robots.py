"""Fuzz classes of the robot descriptions: legs TOML, URDF, xacro, poses and configurations CSVs.

Each class starts from a robot description stiffmap ships or its tests hold (the legs TOMLs of
``src/stiffmap/models/robots``: the hexapod and the 3-RPS (dim 6), the Delta (dim 3), the 3PRR
(dim 2); ``tests/robots/acme_rs6.urdf``, the vendor-style ``cluttered_mm.urdf`` and the split
xacro description of ``tests/robots/xacro_ws``) and makes one thing wrong, as a user bringing
their own robot file would: a key missing or added, a value of the wrong type, a stiffness or a
length of 0, -1, nan or 1e300, a leg duplicated or made to coincide with another (a singular
platform), an unknown joint kind; in a URDF a joint or link missing or twice, an axis 0 0 0, an
origin of 1e300, a mimic joint naming a missing joint, itself or a loop, limits lower > upper, a
cycle, two roots, not XML at all; in a xacro description a missing argument, an unresolved
``$(find)``, an include of a missing file or of itself, a macro error.

Exit 0 is not enough where the answer can be checked independently (:class:`RobotCase`'s
``oracle``; a disagreement is ``wrong``):

- a dim-6 legs TOML whose legs are still UPS legs (a universal joint, the actuated prismatic
  leg, a ball joint on the platform): K6 = sum k_i a_i a_i^T, a_i = (n_i, r_i x n_i) at the pose
  read from the input (Gosselin's closed form, the form ``tests/test_models_legs6.py`` checks);
- the shipped 3-RPS (lower mobility: it holds only poses whose x, y, yaw follow z, roll, pitch):
  a pose printed with a K6 lies in every leg's plane (1e-6 mm) and within its stroke, its K6 is
  the closed form of the legs' axial and bending springs (:func:`rps3_k6`), and a pose printed
  without one says why; the same for the K_tcp of ``simulate --robot 3rps.toml``'s truth.json;
- legs given as URDFs (one URDF's Cartesian chain listed as three legs, each with another joint
  actuated): K = diag(k1, k2, k3) whatever [params] says;
- a URDF: the measured point and K of :mod:`helpers.urdf_reference` (forward kinematics in
  NumPy from the file's numbers, no stiffmap code) on the same mutated file, when it can read
  it (finite numbers, no cycle of joints or mimics);
- every ``--json`` output: only finite numbers or null.
"""

from __future__ import annotations

import functools
import json
import math
import re
import tomllib
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

from helpers import urdf_reference as ref
from helpers.fuzz import FuzzCase, FuzzClass, Outcome, mutated_text
from helpers.poses import rps_pose
from stiffmap.models.legs_file import parse_legs_text

__all__ = ["FUZZ_CLASSES", "RobotCase", "toml_text", "ups_k6", "urdf_check", "legs_check"]

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "src" / "stiffmap" / "models" / "robots"
TEST_ROBOTS = ROOT / "tests" / "robots"
XACRO_WS = TEST_ROBOTS / "xacro_ws"

#: Relative agreement the oracles ask for (both sides compute in float64 from the same numbers;
#: the reference's Jacobian is by central differences: 1e-6 is far above its error).
REL_TOL = 1e-5


@dataclass(frozen=True, repr=False)  # FuzzCase's short repr: the files' sizes, not their bytes
class RobotCase(FuzzCase):
    """A :class:`~helpers.fuzz.FuzzCase` with an independent check of a successful run:
    ``oracle(outcome)`` returns what is wrong with its output (``run_case`` then says ``wrong``),
    or None."""

    oracle: Callable[[Outcome], str | None] | None = None


# --------------------------------------------------------------------------- TOML writing
_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE.match(k) else json.dumps(k)


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    return "[" + ", ".join(_value(x) for x in v) + "]"


def _is_tables(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def _table(d: dict, prefix: str, out: list[str]) -> None:
    for k, v in d.items():
        if not isinstance(v, dict) and not _is_tables(v):
            out.append(f"{_key(k)} = {_value(v)}")
    for k, v in d.items():
        name = f"{prefix}.{_key(k)}" if prefix else _key(k)
        if isinstance(v, dict):
            out += ["", f"[{name}]"]
            _table(v, name, out)
        elif _is_tables(v):
            for item in v:
                out += ["", f"[[{name}]]"]
                _table(item, name, out)


def toml_text(data: dict) -> str:
    """A TOML text of nested dicts and lists (tables and arrays of tables; nan and inf as TOML's)."""
    out: list[str] = []
    _table(data, "", out)
    return "\n".join(out) + "\n"


# --------------------------------------------------------------------------- oracles
def _finite_json(text: str) -> str | None:
    def refuse(name):
        raise ValueError(name)

    try:
        json.loads(text, parse_constant=refuse)
    except ValueError as e:
        return f"non-finite number {e} in the JSON output"
    return None


def _rel(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300))


def _rpy(roll, pitch, yaw) -> np.ndarray:
    return ref.rpy_matrix((roll, pitch, yaw))


def _ups_legs(data: dict) -> list[tuple[np.ndarray, np.ndarray, float]] | None:
    """(base joint mm, platform joint mm in the platform frame, k N/mm) per leg when every leg of a
    parsed legs TOML is a UPS leg as hexapod.toml writes it (else None: no closed form)."""
    params = data.get("params")
    if data.get("dim") != 6 or not isinstance(params, dict) or not isinstance(data.get("legs"), list):
        return None
    out = []
    try:
        for leg in data["legs"]:
            if set(leg) - {"name", "attach_mm", "tip_offset_mm", "joints"} or any(
                leg.get("tip_offset_mm", [0])
            ):
                return None
            u1, u2, s = leg["joints"]
            ok = (
                (u1["type"], u2["type"], s["type"]) == ("revolute", "revolute", "prismatic")
                and (list(u1["axis"]), list(u2["axis"]), list(s["axis"])) == ([1, 0, 0], [0, 1, 0], [0, 0, 1])
                and u1["role"] == u2["role"] == "passive"
                and s["role"] == "actuated"
                and not ({"xyz_mm", "rpy"} & (set(u2) | set(s)))
            )
            k = float(params[s["stiffness"]])
            b, a = np.array(u1["xyz_mm"], dtype=float), np.array(leg["attach_mm"], dtype=float)
            if (
                not ok
                or b.shape != (3,)
                or a.shape != (3,)
                or not (np.isfinite(b).all() and np.isfinite(a).all())
            ):
                return None
            if not (0 < k < math.inf):
                return None
            out.append((b, a, k))
    except (KeyError, TypeError, ValueError):
        return None
    return out


def ups_k6(legs, pose) -> np.ndarray:
    """Gosselin's K6 = sum k_i a_i a_i^T, a_i = (n_i, r_i x n_i) at ``pose`` (x, y, z mm, roll,
    pitch, yaw rad): legs that are springs along their lines (the platform joints balls)."""
    R = _rpy(*pose[3:])
    K6 = np.zeros((6, 6))
    for b, a, k in legs:
        r = R @ a
        n = np.asarray(pose[:3]) + r - b
        n = n / np.linalg.norm(n)
        w = np.r_[n, np.cross(r, n)]
        K6 += k * np.outer(w, w)
    return K6


def legs_check(toml_bytes: bytes, params: dict[str, float] | None = None) -> Callable[[Outcome], str | None]:
    """The oracle of ``model legs FILE --json``: finite JSON; for UPS legs, each printed K6 is the
    closed form at the printed pose (and the pose one of the requested ones: checked by the caller)."""

    def check(o: Outcome) -> str | None:
        bad = _finite_json(o.stdout)
        if bad or not o.stdout.strip():
            return bad
        try:
            data = tomllib.loads(toml_bytes.decode("utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError):
            return None
        if params:
            data.setdefault("params", {}).update(params)
        legs = _ups_legs(data)
        if legs is None:
            return None
        for rec in json.loads(o.stdout):
            if rec.get("K6") is None:
                continue
            pose = [
                rec["x"],
                rec["y"],
                rec["z"],
                *np.radians([rec["roll_deg"], rec["pitch_deg"], rec["yaw_deg"]]),
            ]
            if not np.isfinite(pose).all():
                return f"pose {pose} printed with a K6"
            K6 = ups_k6(legs, pose)
            d = np.array([1, 1, 1, 1e-2, 1e-2, 1e-2])  # rad as 100 mm: no block drowns the others
            if _rel(np.array(rec["K6"]) * d[:, None] * d, K6 * d[:, None] * d) > REL_TOL:
                return f"K6 at {np.round(pose, 4).tolist()} differs from the closed form sum k_i a_i a_i^T"
        return None

    return check


def _cyclic(joints: dict[str, ref.RefJoint]) -> bool:
    """Whether the joints' parent links or their mimic leaders go round in a circle."""
    by_child = {j.child: j for j in joints.values()}
    for j in joints.values():
        seen, at = set(), j.child
        while at in by_child:
            if at in seen:
                return True
            seen.add(at)
            at = by_child[at].parent
        seen, m = set(), j
        while m.mimic is not None:
            if m.name in seen or m.mimic[0] not in joints:
                return True
            seen.add(m.name)
            m = joints[m.mimic[0]]
    return False


def _reference(text: str, tip: str, base: str | None, q_deg: np.ndarray, offset_mm, k: float):
    """The reference's (position, K, K6 or None) per configuration; None when it cannot read the file."""
    try:
        links, joints = ref.read_joints(text)
        if len({j.child for j in joints.values()}) != len(joints) or _cyclic(joints):
            return None
        if len(set(links)) != len(links) or any(
            not np.isfinite(v).all() for j in joints.values() for v in (j.xyz, j.rpy, j.axis)
        ):
            return None
        if any(not np.abs(j.axis).max() > 0 for j in joints.values() if j.type in ref.MOVING):
            return None
        for j in joints.values():  # a direction: 1e300 0 0 is 1 0 0 (its norm would overflow)
            j.axis = j.axis / np.abs(j.axis).max() if j.axis.size and np.abs(j.axis).max() > 0 else j.axis
        if any(j.type not in (*ref.MOVING, "fixed") for j in joints.values()):
            return None
        chain = ref.path(joints, tip, base)
        coords = ref.coordinates(joints, chain)
        if q_deg.shape[1] != len(coords):
            return None
        out = []
        for row in q_deg:
            q = np.array(
                [
                    v if joints[c].type == "prismatic" else math.radians(v)
                    for c, v in zip(coords, row, strict=True)
                ]
            )
            p, K, K6, _ = ref.stiffness(joints, chain, coords, q, [k] * len(coords), offset_mm)
            out.append((p, K, K6))
        return out
    except (
        ET.ParseError,
        KeyError,
        ValueError,
        TypeError,
        AttributeError,
        ZeroDivisionError,
        np.linalg.LinAlgError,
    ):
        return None


def urdf_check(
    urdf_bytes: bytes, tip: str, base: str | None, q_deg, offset_mm=(0.0, 0.0, 0.0), k: float = 1e7
) -> Callable[[Outcome], str | None]:
    """The oracle of ``model urdf FILE --json``: finite JSON, and where the reference reads the
    file, the printed measured point and K (K6) equal its."""

    def check(o: Outcome) -> str | None:
        bad = _finite_json(o.stdout)
        if bad or not o.stdout.strip() or q_deg is None:
            return bad
        with np.errstate(all="ignore"):
            refs = _reference(
                urdf_bytes.decode("utf-8", "replace"), tip, base, np.atleast_2d(q_deg), offset_mm, k
            )
        if refs is None or any(not np.isfinite(p).all() for p, _, _ in refs):
            return None
        recs = json.loads(o.stdout)
        if len(recs) != len(refs):
            return f"{len(recs)} configurations printed for {len(refs)} given"
        for i, (rec, (p, K, K6)) in enumerate(zip(recs, refs, strict=True)):
            if np.linalg.norm(np.subtract(rec["position"], p)) > 1e-6 * max(1.0, np.linalg.norm(p)):
                return (
                    f"configuration {i + 1}: position {rec['position']} where the reference has {p.tolist()}"
                )
            if K is not None and rec.get("K") is not None and _rel(rec["K"], K) > REL_TOL:
                return f"configuration {i + 1}: K differs from the reference's by {_rel(rec['K'], K):.2g}"
            if K6 is not None and rec.get("K6") is not None and _rel(rec["K6"], K6) > REL_TOL:
                return f"configuration {i + 1}: K6 differs from the reference's by {_rel(rec['K6'], K6):.2g}"
            if K is not None and rec.get("K") is None and not o.stderr.strip():
                return f"configuration {i + 1}: no K and no word why (the reference has one)"
        return None

    return check


# --------------------------------------------------------------------------- legs TOML
#: The seeds: (file, command-line points that every seed reaches).
LEGS_SEEDS = {
    "hexapod.toml": ("--grid", "-20:20:2,0,280:320:2", "--orientation", "0,5,0"),
    "3rps.toml": ("--grid", "0,0,250"),
    "delta.toml": ("--grid", "-50:50:2,0,-300"),
    "delta_links.toml": ("--grid", "-50:50:2,0,-300"),
    "3prr.toml": ("--grid", "300:400:2,150:200:2"),
}
#: Values that replace a number (a stiffness, a length, a limit).
BAD_NUMBERS = (0.0, -0.0, -1.0, -500.0, math.nan, math.inf, -math.inf, 1e300, -1e300, 1e-300, 1e12, 5e-324)
#: Values of the wrong type.
BAD_TYPES = ("abc", "", [1.0, 2.0], [], True, {"a": 1.0}, [[1.0, 2.0, 3.0]], ["1", "2", "3"])
#: Joint kinds a description may hold that legs TOMLs do not.
BAD_KINDS = ("spherical", "ball", "Revolute", "continuous", "fixed", "floating", "planar", "", "universal")


@functools.cache
def legs_seed(name: str) -> dict:
    return tomllib.loads((SHIPPED / name).read_text())


def _leg_keys(draw, data: dict) -> tuple[dict, str, str]:
    """A leg or joint table of ``data`` and one of its keys (drawn)."""
    legs = data["legs"]
    leg = legs[draw(st.integers(0, len(legs) - 1))]
    if draw(st.booleans()):
        jt = leg["joints"][draw(st.integers(0, len(leg["joints"]) - 1))]
        return jt, draw(st.sampled_from(sorted(jt))), f"{leg['name']}.{jt['name']}"
    return leg, draw(st.sampled_from(sorted(leg))), leg["name"]


def _set_number(draw, data: dict) -> str:
    """One number of the file (a stiffness, a coordinate, a limit) made absurd."""
    v = draw(st.sampled_from(BAD_NUMBERS))
    if draw(st.booleans()):
        k = draw(st.sampled_from(sorted(data["params"])))
        data["params"][k] = v
        return f"params.{k} = {v}"
    t, key, where = _leg_keys(draw, data)
    cur = t[key]
    if isinstance(cur, list) and cur:
        cur[draw(st.integers(0, len(cur) - 1))] = v
    elif isinstance(cur, float):
        t[key] = v
    else:
        t["q0" if "q0" in t else key] = v
    return f"{where}.{key} = {v}"


def _coincide(draw, data: dict) -> str:
    """Two legs made the same leg (another name): the platform is singular."""
    legs = data["legs"]
    i, j = draw(st.permutations(range(len(legs))))[:2]
    copy = json.loads(json.dumps(legs[i], allow_nan=True))
    copy["name"] = legs[j]["name"]
    for a, b in zip(copy["joints"], legs[j]["joints"], strict=False):
        if "stiffness" in b:
            a["stiffness"] = b["stiffness"]
    legs[j] = copy
    return f"legs {i + 1} and {j + 1} coincide"


LEGS_MUTATIONS = (
    "text", "number", "number", "drop key", "extra key", "wrong type", "2-number attach", "duplicate leg",
    "coincide", "joint kind", "dim", "lower > upper", "axis", "no legs", "missing param", "one leg", "link",
    "link",
)  # fmt: skip


@st.composite
def legs_data(draw, seed: str) -> tuple[bytes, str]:
    """A mutated legs TOML (bytes) and what was done to it."""
    data = json.loads(json.dumps(legs_seed(seed), allow_nan=True))
    kind = draw(st.sampled_from(LEGS_MUTATIONS))
    legs = data["legs"]
    if kind == "text":
        return draw(mutated_text((SHIPPED / seed).read_text())), "text mutation"
    if kind == "number":
        what = _set_number(draw, data)
    elif kind == "drop key":
        if draw(st.booleans()):
            key = draw(st.sampled_from(sorted(data)))
            del data[key]
            what = f"top-level {key} dropped"
        else:
            t, key, where = _leg_keys(draw, data)
            del t[key]
            what = f"{where}.{key} dropped"
    elif kind == "extra key":
        t, _, where = _leg_keys(draw, data) if draw(st.booleans()) else (data, "", "top")
        key = draw(st.sampled_from(("stifness", "Axis", "attach", "k", "xyz", "units", "dim2")))
        t[key] = 1.0
        what = f"{where}: unknown key {key}"
    elif kind == "wrong type":
        v = draw(st.sampled_from(BAD_TYPES))
        if draw(st.booleans()):
            key = draw(st.sampled_from(sorted(data)))
            data[key] = v
            what = f"top-level {key} = {v!r}"
        else:
            t, key, where = _leg_keys(draw, data)
            t[key] = v
            what = f"{where}.{key} = {v!r}"
    elif kind == "2-number attach":
        leg = legs[draw(st.integers(0, len(legs) - 1))]
        leg["attach_mm"] = leg["attach_mm"][:2] if len(leg["attach_mm"]) == 3 else [*leg["attach_mm"], 0.0]
        what = f"{leg['name']}.attach_mm of {len(leg['attach_mm'])} numbers (dim {data['dim']})"
    elif kind == "duplicate leg":
        i = draw(st.integers(0, len(legs) - 1))
        legs.insert(i, json.loads(json.dumps(legs[i], allow_nan=True)))
        what = f"leg {i + 1} twice"
    elif kind == "coincide":
        what = _coincide(draw, data)
    elif kind == "joint kind":
        leg = legs[draw(st.integers(0, len(legs) - 1))]
        jt = leg["joints"][draw(st.integers(0, len(leg["joints"]) - 1))]
        jt["type"] = draw(st.sampled_from(BAD_KINDS))
        what = f"{leg['name']}.{jt['name']}.type = {jt['type']!r}"
    elif kind == "dim":
        data["dim"] = draw(st.sampled_from((0, 1, 4, 5, 7, -6, 2, 3, 6)))
        what = f"dim = {data['dim']}"
    elif kind == "lower > upper":
        jts = [(lg["name"], jt) for lg in legs for jt in lg["joints"] if "lower" in jt and "upper" in jt]
        name, jt = jts[draw(st.integers(0, len(jts) - 1))]
        jt["lower"], jt["upper"] = jt["upper"], jt["lower"]
        what = f"{name}.{jt['name']}: lower > upper"
    elif kind == "axis":
        leg = legs[draw(st.integers(0, len(legs) - 1))]
        jt = leg["joints"][draw(st.integers(0, len(leg["joints"]) - 1))]
        jt["axis"] = draw(
            st.sampled_from(([0.0, 0.0, 0.0], [math.nan, 0.0, 1.0], [1e300, 0.0, 0.0], [1.0, 1.0, 0.0]))
        )
        what = f"{leg['name']}.{jt['name']}.axis = {jt['axis']}"
    elif kind == "no legs":
        data["legs"] = []
        what = "no legs"
    elif kind == "missing param":
        key = draw(st.sampled_from(sorted(data["params"])))
        del data["params"][key]
        what = f"params.{key} missing"
    elif kind == "link" and any("links" in lg for lg in legs):
        what = _mutate_link(draw, [lg for lg in legs if "links" in lg])
    else:
        data["legs"] = legs[:1]
        what = "one leg"
    return toml_text(data).encode(), what


def _mutate_link(draw, legs: list[dict]) -> str:
    """One flexible link's data ([[legs.links]]) made wrong: a beam value, a key, its joint."""
    leg = legs[draw(st.integers(0, len(legs) - 1))]
    link = leg["links"][0]
    beam = link.get("beam", {})
    key = draw(st.sampled_from(sorted(beam) + ["after", "name", "beam"]))
    if key == "after":
        link["after"] = draw(st.sampled_from(("no_such_joint", "", "elbow_x")))
    elif key == "name":
        link["name"] = draw(st.sampled_from(("", "k_theta", "E_arm", "a b")))
    elif key == "beam":
        del link["beam"]
    else:
        beam[key] = draw(st.sampled_from(BAD_NUMBERS + BAD_TYPES[:2]))
    return f"{leg['name']}.links[1].{key} = {link.get(key, beam.get(key))!r}"


def _reads(text: bytes) -> bool:
    """Whether the legs reader takes the file (a line dropped may leave another valid robot, which
    may reach none of the points: its error is then about the points, not the file)."""
    try:
        parse_legs_text(text.decode("utf-8"), source="legs.toml")
    except Exception:  # noqa: BLE001 - any refusal: the file must then be named
        return False
    return True


# ------------------------------------------------------------------ legs given as URDFs
#: One URDF's chain (three prismatic joints x, y, z to link l3) listed as three legs, each with
#: another joint actuated: a Cartesian stage, K = diag(k1, k2, k3) (N/mm) at every position.
STAGE_URDF = """<robot name="leg"><link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/>
<joint name="x" type="prismatic"><parent link="base"/><child link="l1"/><axis xyz="1 0 0"/>
<limit lower="-500" upper="500" effort="1" velocity="1"/></joint>
<joint name="y" type="prismatic"><parent link="l1"/><child link="l2"/><axis xyz="0 1 0"/>
<limit lower="-500" upper="500" effort="1" velocity="1"/></joint>
<joint name="z" type="prismatic"><parent link="l2"/><child link="l3"/><axis xyz="0 0 1"/>
<limit lower="-500" upper="500" effort="1" velocity="1"/></joint></robot>
"""
STAGE_K = (100.0, 200.0, 300.0)


def stage_data() -> dict:
    legs = [
        {"name": f"leg{i}", "attach_mm": [0.0, 0.0, 0.0], "urdf": "leg.urdf", "tip_frame": "l3",
         "joints": [{"name": j, "role": "actuated", "stiffness": f"k{i}"}]}
        for i, j in enumerate("xyz", start=1)
    ]  # fmt: skip
    return {
        "name": "cartesian",
        "dim": 3,
        "params": {f"k{i}": k for i, k in enumerate(STAGE_K, 1)},
        "legs": legs,
    }


#: What a leg's urdf and tip_frame keys may wrongly say.
STAGE_KEYS = (
    ("urdf", "no_such.urdf"), ("urdf", "../leg.urdf"), ("urdf", "/etc/passwd"), ("urdf", "."), ("urdf", ""),
    ("urdf", "stage.toml"), ("tip_frame", "l9"), ("tip_frame", "base"), ("tip_frame", "l1"),
    ("tip_frame", ""),
)  # fmt: skip


@st.composite
def stage_cases(draw) -> RobotCase:
    """The Cartesian stage of URDF legs with its TOML or its URDF made wrong."""
    data, urdf = stage_data(), STAGE_URDF.encode()
    kind = draw(st.sampled_from(("key", "param", "urdf", "urdf text")))
    blamed: str | None = None
    if kind == "key":
        key, value = draw(st.sampled_from(STAGE_KEYS))
        leg = data["legs"][draw(st.integers(0, 2))]
        leg[key] = value
        what = f"{leg['name']}.{key} = {value!r}"
    elif kind == "param":
        key = draw(st.sampled_from(sorted(data["params"])))
        data["params"][key] = draw(st.sampled_from(BAD_NUMBERS + (50.0, 1e6)))
        what, blamed = f"params.{key} = {data['params'][key]}", "stage.toml"
    elif kind == "urdf":
        root = ET.fromstring(STAGE_URDF)
        what = "leg.urdf: " + _mutate_urdf(draw, root)
        urdf = ET.tostring(root)
    else:
        urdf, what = draw(mutated_text(STAGE_URDF)), "leg.urdf: text mutation"
    toml = toml_text(data).encode()
    files = {"stage.toml": toml, "leg.urdf": urdf}
    check = _stage_check(data["params"]) if kind in ("param",) else _json_only
    blamed = None if blamed and _reads(toml) else blamed
    argv = ("model", "legs", "{dir}/stage.toml", "--grid", "-20:20:2,0,30", "--json")
    return RobotCase(files, argv, blamed, f"urdf legs: {what}", oracle=check)


def _json_only(o: Outcome) -> str | None:
    return _finite_json(o.stdout) if o.stdout.strip() else None


def _stage_check(params: dict[str, float]) -> Callable[[Outcome], str | None]:
    """K = diag(k1, k2, k3): each leg holds the stage along its actuated joint's axis."""

    def check(o: Outcome) -> str | None:
        bad = _json_only(o)
        if bad or not o.stdout.strip():
            return bad
        K = np.diag([params[f"k{i}"] for i in (1, 2, 3)])
        for rec in json.loads(o.stdout):
            if rec.get("K") is not None and _rel(rec["K"], K) > REL_TOL:
                where = f"({rec['x']}, {rec['y']}, {rec['z']})"
                return f"K at {where} is not diag(k1, k2, k3) = {np.diag(K).tolist()}"
        return None

    return check


@st.composite
def legs_cases(draw) -> RobotCase:
    if draw(st.integers(0, 4)) == 0:
        return draw(stage_cases())
    seed = draw(st.sampled_from(sorted(LEGS_SEEDS)))
    text, what = draw(legs_data(seed))
    argv = ("model", "legs", f"{{dir}}/{seed}", *LEGS_SEEDS[seed], "--json")
    # Another robot that reaches none of the points (an axis turned, a single leg): each point's
    # reason is printed ("unreachable: leg 2 ...", "singular: ..."), the file need not be named.
    # A spring made rigid (inf) where no other spring acts: "singular: leg 3 rigid along a direction".
    # Finite geometry changed (a joint moved, an attach point, a tip offset left to its default):
    # a valid file of another robot, which may reach none of the points.
    rigid = what.startswith("params.") and what.endswith("= inf")
    moved = re.search(r"\.(attach_mm|xyz_mm|tip_offset_mm|rpy|axis|q0) = (?!nan|inf|-inf)", what)
    other = what.endswith(("[1e+300, 0.0, 0.0]", "[1.0, 1.0, 0.0]", "one leg", "tip_offset_mm dropped"))
    other = other or what.endswith(("dim = 2", "dim = 3", "dim = 6"))  # what the file says it is
    blamed = None if rigid or moved or other or _reads(text) else seed
    return RobotCase({seed: text}, argv, blamed, f"{seed}: {what}", oracle=legs_check(text))


# --------------------------------------------------------------------------- poses CSV
POSE_COLUMNS = ("x", "y", "z", "roll_deg", "pitch_deg", "yaw_deg")
#: Poses the shipped hexapod reaches (mm, degrees).
POSES = (
    (0.0, 0.0, 300.0, 0.0, 0.0, 0.0),
    (20.0, -15.0, 320.0, 5.0, -3.0, 10.0),
    (-25.0, 10.0, 280.0, -4.0, 6.0, -8.0),
)


def _pose_text(rows, cols=POSE_COLUMNS) -> str:
    return (
        "\n".join(
            [
                ",".join(cols),
                *(",".join(f"{v:.9g}" if isinstance(v, float) else str(v) for v in r) for r in rows),
            ]
        )
        + "\n"
    )


@st.composite
def poses_csv(draw, robot: str = "hexapod.toml") -> tuple[bytes, str]:
    kind = draw(
        st.sampled_from(
            ("text", "orientation alone", "unreachable", "not held", "value", "huge degrees", "columns")
        )
    )
    rows = [list(p) for p in (POSES if robot == "hexapod.toml" else rps3_poses())]
    if kind == "text":
        return draw(mutated_text(_pose_text(rows))), "text mutation"
    if kind == "orientation alone":
        keep = draw(st.sampled_from(POSE_COLUMNS[3:]))
        cols = (*POSE_COLUMNS[:3], keep)
        return _pose_text(
            [r[:3] + [r[POSE_COLUMNS.index(keep)]] for r in rows], cols
        ).encode(), f"only {keep}"
    i = draw(st.integers(0, len(rows) - 1))
    if kind == "unreachable":
        rows[i][2] = draw(st.sampled_from((1000.0, 0.0, -300.0, 600.0)))
        what = f"row {i + 1}: z = {rows[i][2]}"
    elif kind == "not held":  # off a 3-RPS's held poses (x, y, yaw follow z, roll, pitch)
        c = draw(st.sampled_from((0, 1, 5)))
        rows[i][c] += draw(st.sampled_from((10.0, -3.0, 0.5)))
        what = f"row {i + 1}: {POSE_COLUMNS[c]} moved to {rows[i][c]:.6g}"
    elif kind == "value":
        c = draw(st.integers(0, 5))
        rows[i][c] = draw(st.sampled_from(BAD_NUMBERS))
        what = f"row {i + 1}: {POSE_COLUMNS[c]} = {rows[i][c]}"
    elif kind == "huge degrees":
        c = draw(st.integers(3, 5))
        rows[i][c] = draw(st.sampled_from((1e6, -1e6, 720.0, 3600.0, 1e17)))
        what = f"row {i + 1}: {POSE_COLUMNS[c]} = {rows[i][c]}"
    else:
        cols = list(POSE_COLUMNS)
        j = draw(st.integers(0, 5))
        cols[j] = draw(st.sampled_from(("roll", "roll_rad", "X", "", "z", "rx_deg")))
        return _pose_text(rows, cols).encode(), f"column {j + 1} named {cols[j]!r}"
    return _pose_text(rows).encode(), what


# ------------------------------------------------------------------ the 3-RPS (lower mobility)
def _rps3_legs(data: dict) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, float, float]]:
    """(revolute centre mm, ball joint mm in the platform frame, revolute axis, k_leg, k_bend) per
    leg of the shipped 3rps.toml as its header describes it: base revolutes on a circle with axes
    tangent to it (horizontal), the actuated leg along the leg, a bending spring along the axis."""
    out = []
    for i, leg in enumerate(data["legs"], start=1):
        b = np.array(leg["joints"][0]["xyz_mm"], dtype=float)
        w = np.cross([0.0, 0.0, 1.0], b)
        out.append(
            (b, np.array(leg["attach_mm"], dtype=float), w / np.linalg.norm(w),
             float(data["params"][f"k_leg{i}"]), float(data["params"][f"k_bend{i}"]))
        )  # fmt: skip
    return out


@functools.cache
def rps3_poses() -> tuple[tuple[float, ...], ...]:
    """Poses the shipped 3-RPS holds (mm, deg): z, roll, pitch chosen, x, y, yaw solved by the
    independent solver of helpers.poses (every ball joint in its leg's plane)."""
    legs = _rps3_legs(legs_seed("3rps.toml"))
    attach, axes = np.array([lg[1] for lg in legs]), np.array([lg[2] for lg in legs])
    out = []
    for z, roll, pitch in ((250.0, 0.0, 0.0), (240.0, 4.0, -3.0), (270.0, -6.0, 5.0)):
        p = rps_pose(z, math.radians(roll), math.radians(pitch), attach, axes)
        out.append((*(float(v) for v in p[:3]), *(float(v) for v in np.degrees(p[3:]))))
    return tuple(out)


def rps3_k6(legs, pose) -> np.ndarray:
    """The 3-RPS's K6 at ``pose`` (mm, rad): each leg holds the platform's ball joint along the leg
    (k_leg) and along its revolute's axis (k_bend, the bending across its plane); the wrench of a
    force u at r is (u, r x u), K6 = sum k u_w u_w^T (no load: no geometric term)."""
    R = _rpy(*pose[3:])
    K6 = np.zeros((6, 6))
    for b, a, w, k_leg, k_bend in legs:
        r = R @ a
        n = np.asarray(pose[:3]) + r - b
        for k, u in ((k_leg, n / np.linalg.norm(n)), (k_bend, w)):
            v = np.r_[u, np.cross(r, u)]
            K6 += k * np.outer(v, v)
    return K6


#: The shipped 3-RPS's stroke (mm) and the distance from a leg's plane a held pose may have.
RPS3_STROKE = (180.0, 360.0)
PLANE_TOL_MM = 1e-6


def rps3_check(params: dict[str, float] | None = None) -> Callable[[Outcome], str | None]:
    """The oracle of ``model legs 3rps.toml --json``: finite JSON; a pose printed with a K6 is one
    the 3-RPS holds (every ball joint in its leg's plane, every leg within its stroke) and its K6
    is :func:`rps3_k6`'s; a pose printed without one says why (its ``error``)."""

    def check(o: Outcome) -> str | None:
        bad = _finite_json(o.stdout)
        if bad or not o.stdout.strip():
            return bad
        data = json.loads(json.dumps(legs_seed("3rps.toml")))
        data["params"].update(params or {})
        legs = _rps3_legs(data)
        for i, rec in enumerate(json.loads(o.stdout), start=1):
            if rec.get("K6") is None:
                if not rec.get("error"):
                    return f"pose {i}: no K6 and no reason"
                continue
            pose = np.r_[[rec[c] for c in "xyz"], np.radians([rec[c] for c in POSE_COLUMNS[3:]])]
            R = _rpy(*pose[3:])
            for b, a, w, _, _ in legs:
                tip = pose[:3] + R @ a
                off = abs((tip - b) @ w)
                if off > PLANE_TOL_MM:
                    return f"pose {i} printed with a K6: a ball joint {off:.3g} mm off its leg's plane"
                if not RPS3_STROKE[0] - 1e-6 <= np.linalg.norm(tip - b) <= RPS3_STROKE[1] + 1e-6:
                    return f"pose {i} printed with a K6: a leg {np.linalg.norm(tip - b):.6g} mm long"
            d = np.array([1, 1, 1, 1e-2, 1e-2, 1e-2])
            K6 = rps3_k6(legs, pose)
            if _rel(np.array(rec["K6"]) * d[:, None] * d, K6 * d[:, None] * d) > REL_TOL:
                return f"pose {i}: K6 differs from the closed form of the 3-RPS's legs and bending springs"
        return None

    return check


#: Option values of ``model legs`` on a dim-6 robot.
GRID_VALUES = ("0,0,300", "-20:20:3,0,300", "0,0", "0:0:0,0,300", "1:2:1e9,0,300", "nan,0,300", "0,0,1e300",
               "a:b:c", "", "0,0,300,0", "-20:20:-3,0,300", "0:10:1001,0:10:1000,300")  # fmt: skip
ORIENTATION_VALUES = ("0,0,0", "5,0,0", "1e6,0,0", "nan,0,0", "0,0", "-10:10:3,0,0", "0,0,0,0", "inf,0,0",
                      "10:-10:0,0,0", "0:1:1e7,0,0", "x,y,z")  # fmt: skip
MOMENT_VALUES = ("0,0,0", "100,0,-50", "1e300,0,0", "nan,0,0", "1,2", "inf,0,0", "a,b,c")
#: --param values of the hexapod: within the [params] range or not, unknown names, not numbers.
PARAM_VALUES = (
    "k_leg1=500", "k_leg2=700,k_leg5=650", "k_leg1=1e300", "k_leg1=1e-300", "k_leg1=1e12", "k_leg1=2e12",
    "k_leg1=-1", "k_leg1=nan", "k_leg1=inf", "k_leg9=5", "k_leg1", "=5", "k_leg1=1e-6",
)  # fmt: skip
#: A --grid and --orientation each within their limits whose poses are not (1e11 and 1e8 poses:
#: a MemoryError, or a map of days). A grid of a million positions alone is a legitimate long run
#: (its progress printed): not drawn, it would count as a hang.
TOO_MANY_POSES = (
    ("0:10:1000,0:10:1000,300", "0:1:100,0:1:100,0:1:10"),
    ("0:10:100,0:10:100,300", "0:1:100,0:1:100,0"),
    ("0:10:1000,0:10:10,300", "-10:10:101,0,0"),
)


#: --grid, --orientation and --param values of the 3-RPS: poses it holds as given (level on its
#: axis), poses it does not (off the axis, tilted: refused naming the pose it holds), strokes out.
RPS3_GRID_VALUES = ("0,0,240:260:2", "0,0,250", "-5:5:3,0,250", "0,0,100", "0,0,400", "0,0:10:2,250",
                    "nan,0,250", "0,0,1e300", "0,0")  # fmt: skip
RPS3_ORIENTATION_VALUES = ("0,0,0", "0,-5:5:3,0", "5,0,0", "0,0,10", "1e6,0,0", "nan,0,0", "0,0,0,0")
RPS3_PARAM_VALUES = ("k_leg1=800", "k_bend2=1e-300", "k_bend3=0", "k_leg1=nan", "k_leg1=1e300", "k_leg4=5")
#: --param values of the 3-RPS within its range (drawn 3 times in 4: a refused --param hides the rest).
RPS3_PARAM_OK = ("", "k_leg1=800", "k_bend2=260,k_leg3=450")


def _rps3_param(draw) -> str:
    return draw(st.sampled_from(RPS3_PARAM_OK if draw(st.integers(0, 3)) else RPS3_PARAM_VALUES))


@st.composite
def poses_cases(draw) -> RobotCase:
    robot = draw(st.sampled_from(("hexapod.toml", "hexapod.toml", "3rps.toml")))
    text = (SHIPPED / robot).read_bytes()
    hexapod = robot == "hexapod.toml"
    opts: tuple[str, ...]
    override = None
    if draw(st.booleans()):
        csv_text, what = draw(poses_csv(robot))
        files = {robot: text, "poses.csv": csv_text}
        opts, blamed = ("--points", "{dir}/poses.csv"), "poses.csv"
    else:
        values = (GRID_VALUES, ORIENTATION_VALUES) if hexapod else (RPS3_GRID_VALUES, RPS3_ORIENTATION_VALUES)
        g, o = (draw(st.sampled_from(v)) for v in values)
        m = draw(st.sampled_from(MOMENT_VALUES))
        if hexapod and draw(st.integers(0, 4)) == 0:
            g, o = draw(st.sampled_from(TOO_MANY_POSES))
        p = draw(st.sampled_from(PARAM_VALUES)) if hexapod else _rps3_param(draw)
        files, blamed = {robot: text}, None
        what = f"--grid {g!r} --orientation {o!r} --moment-nmm {m!r} --param {p!r}"
        opts = (f"--grid={g}", f"--orientation={o}", f"--moment-nmm={m}", *((f"--param={p}",) if p else ()))
        override = _param_override(p) if p else None
    argv = ("model", "legs", f"{{dir}}/{robot}", *opts, "--json")
    k6 = legs_check(text, override) if hexapod else rps3_check(override)
    note = what if hexapod else f"3rps: {what}"
    return RobotCase(files, argv, blamed, note, oracle=_poses_check(files.get("poses.csv"), k6))


def _param_override(text: str) -> dict[str, float] | None:
    """``--param NAME=VALUE[,NAME=VALUE]`` as the oracle takes it (None when it is not that)."""
    try:
        return {k: float(v) for k, v in (item.split("=") for item in text.split(","))}
    except ValueError:
        return None


def _poses_check(text: bytes | None, k6_check) -> Callable[[Outcome], str | None]:
    """The closed-form K6 at the printed poses; the printed poses are the file's (read here with
    the csv rules of a plain comma-separated file), in its order."""

    def check(o: Outcome) -> str | None:
        bad = k6_check(o)
        if bad or text is None:
            return bad
        try:
            lines = [ln for ln in text.decode("ascii").splitlines() if ln.strip()]
            header = [c.strip() for c in lines[0].split(",")]
            if tuple(header) != POSE_COLUMNS:
                return None
            rows = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
        except (UnicodeDecodeError, ValueError, IndexError):
            return None
        printed = np.array([[r[c] for c in POSE_COLUMNS] for r in json.loads(o.stdout)])
        if rows.shape != printed.shape or not np.isfinite(rows).all():
            return None  # rows left out are named on stderr (exit 1), not exit 0
        if not np.allclose(printed, rows, rtol=1e-9, atol=1e-9):
            return "the poses printed are not the file's"
        return None

    return check


# --------------------------------------------------------------------------- URDF
#: The URDF seeds: file, --tip, --base (None: the root), configurations (deg), options.
URDF_SEEDS = {
    "acme_rs6.urdf": (
        "tool0",
        None,
        ((10.0, 20.0, -30.0, 40.0, 50.0, 60.0), (-80.0, 35.0, 10.0, -20.0, 30.0, -40.0)),
    ),
    "cluttered_mm.urdf": ("r_tool0", "base_link", ((120.0, 10.0, 20.0, -30.0, 40.0, 50.0, 60.0),)),
}
OFFSET_MM = (10.0, -20.0, 30.0)
K_ALL = 1e7

BAD_AXES = ("0 0 0", "nan 0 1", "1 0", "1e300 0 0", "a b c", "0 0 1 0", "inf 0 0", "1e-300 0 0")
BAD_XYZ = ("1e300 0 0", "nan 0 0", "0 0 inf", "1 2", "0.1 0.2 0.3 0.4", "", "1,2,3")
BAD_TYPES_URDF = ("spherical", "Revolute", "", "ball", "floating", "planar", "universal", "screw")
#: Files that are not a robot's URDF.
NOT_URDF = (
    b"",
    b"not xml at all\n",
    b"<?xml version='1.0'?><robot name='r'/>",
    b"<robot name='r'><link name='a'/></robot>",
    b"<?xml version='1.0'?><launch><node pkg='x' type='y'/></launch>",
    b"<sdf version='1.6'><model name='m'><link name='a'/></model></sdf>",
    b"<?xml version='1.0'?><package format='3'><name>acme</name></package>",
    b"<robot name='r'><link name='a'/><joint name='j'",
    b"\xff\xfe<\x00r\x00",
)


def _joints(root, moving_only: bool = False):
    js = root.findall("joint")
    return [j for j in js if j.get("type") in ref.MOVING] if moving_only else js


URDF_MUTATIONS = (
    "drop joint", "drop link", "duplicate joint", "duplicate link", "type", "axis", "origin", "rpy",
    "mimic missing", "mimic self", "mimic loop", "mimic", "limits", "cycle", "two roots", "orphan joint",
    "valid type", "drop element", "unexpanded xacro", "commas",
)  # fmt: skip
#: Changes that leave a valid URDF of another robot (the oracle then checks the answer).
VALID_TYPES = ("prismatic", "continuous", "fixed")


def _other_mutation(draw, root: ET.Element, j: ET.Element, kind: str) -> str:
    """The mutations of a joint that may leave a valid URDF (a joint of another type, an element
    left to its default) or leave a text a URDF reader must not take for numbers."""
    if kind == "valid type":
        j.set("type", draw(st.sampled_from(VALID_TYPES)))
        return f"type {j.get('type')}"
    if kind == "drop element":
        tag = draw(st.sampled_from(("axis", "origin", "limit")))
        if j.find(tag) is not None:
            j.remove(j.find(tag))
        return f"<{tag}> removed"
    el = j.find("origin") if j.find("origin") is not None else ET.SubElement(j, "origin")
    if kind == "unexpanded xacro":
        el.set("xyz", "${d1} 0 0")
        return "origin ${d1} 0 0"
    xyz = el.get("xyz", "0 0 0").split()
    el.set("xyz", ",".join(xyz))
    return f"origin xyz {el.get('xyz')!r}"


def _mutate_urdf(draw, root: ET.Element) -> str:
    """One element-level mutation of a parsed URDF (in place); what it was."""
    moving = _joints(root, True)
    j = moving[draw(st.integers(0, len(moving) - 1))]
    name = j.get("name")
    kind = draw(st.sampled_from(URDF_MUTATIONS))
    if kind == "drop joint":
        root.remove(j)
    elif kind == "drop link":
        links = root.findall("link")
        root.remove(links[draw(st.integers(0, len(links) - 1))])
    elif kind == "duplicate joint":
        root.append(ET.fromstring(ET.tostring(j)))
    elif kind == "duplicate link":
        root.append(ET.Element("link", name=j.find("child").get("link")))
    elif kind == "type":
        j.set("type", draw(st.sampled_from(BAD_TYPES_URDF)))
        kind = f"type {j.get('type')!r}"
    elif kind == "axis":
        el = j.find("axis") if j.find("axis") is not None else ET.SubElement(j, "axis")
        el.set("xyz", draw(st.sampled_from(BAD_AXES)))
        kind = f"axis {el.get('xyz')!r}"
    elif kind in ("origin", "rpy"):
        el = j.find("origin") if j.find("origin") is not None else ET.SubElement(j, "origin")
        el.set("xyz" if kind == "origin" else "rpy", draw(st.sampled_from(BAD_XYZ)))
        kind = f"origin {kind} {el.get('xyz' if kind == 'origin' else 'rpy')!r}"
    elif kind.startswith("mimic"):
        other = [m for m in moving if m is not j]
        lead = {"mimic missing": "no_such_joint", "mimic self": name}.get(kind, other[0].get("name"))
        mult = draw(st.sampled_from(("1", "0", "nan", "-1", "1e300", "2", "abc")))
        ET.SubElement(
            j, "mimic", joint=lead, multiplier=mult, offset=draw(st.sampled_from(("0", "0.1", "nan")))
        )
        if kind == "mimic loop":
            ET.SubElement(other[0], "mimic", joint=name)
        kind = f"{kind}: {name} follows {lead} x {mult}"
    elif kind == "limits":
        lim = j.find("limit") if j.find("limit") is not None else ET.SubElement(j, "limit")
        lo, hi = draw(
            st.sampled_from((("1", "-1"), ("nan", "1"), ("0", "0"), ("-1e300", "1e300"), ("a", "1")))
        )
        lim.set("lower", lo)
        lim.set("upper", hi)
        kind = f"limits {lo} .. {hi}"
    elif kind == "cycle":
        j.find("child").set("link", root.findall("link")[0].get("name"))
    elif kind == "two roots":
        j.find("parent").set("link", "floating_island")
        root.append(ET.Element("link", name="floating_island"))
    elif kind in ("valid type", "drop element", "unexpanded xacro", "commas"):
        kind = _other_mutation(draw, root, j, kind)
    else:
        o = ET.SubElement(root, "joint", name="orphan", type="revolute")
        ET.SubElement(o, "parent", link="nowhere")
        ET.SubElement(o, "child", link=j.find("child").get("link"))
    return f"{name}: {kind}"


@st.composite
def urdf_file(draw, seed: str) -> tuple[bytes, str]:
    text = (TEST_ROBOTS / seed).read_text()
    kind = draw(st.sampled_from(("element", "element", "element", "text", "not urdf")))
    if kind == "text":
        return draw(mutated_text(text)), "text mutation"
    if kind == "not urdf":
        return draw(st.sampled_from(NOT_URDF)), "not a URDF"
    root = ET.fromstring(text)
    what = _mutate_urdf(draw, root)
    return ET.tostring(root), what


def _configs_text(rows, prismatic=()) -> str:
    """Columns q1_deg..qn_deg (qK_mm for the K-th coordinate when it is prismatic, K in ``prismatic``)."""
    n = len(rows[0])
    head = ",".join(f"q{i + 1}_{'mm' if i + 1 in prismatic else 'deg'}" for i in range(n))
    return "\n".join([head, *(",".join(map(str, r)) for r in rows)]) + "\n"


def _urdf_argv(
    name: str, tip: str, base: str | None, extra=(), offset: str | None = None, param: str | None = None
) -> tuple[str, ...]:
    offset = ",".join(map(str, OFFSET_MM)) if offset is None else offset
    param = f"k_theta={K_ALL:g}" if param is None else param
    return (
        "model", "urdf", f"{{dir}}/{name}", "--tip", tip, *(("--base", base) if base else ()),
        f"--tip-offset-mm={offset}", "--configs", "{dir}/q.csv", f"--param={param}", *extra, "--json",
    )  # fmt: skip


#: --tip-offset-mm values: plausible, absurd, malformed.
OFFSET_VALUES = ("0,0,0", "-5,0,250", "1e300,0,0", "1e6,0,0", "nan,0,0", "1,2", "inf,0,0", "a,b,c", "2e6,0,0")
#: --param values of a six-joint arm: one for all, one each, absurd, too few, unknown.
PARAM_URDF_VALUES = (
    "k_theta=1e300", "k_theta=1e-300", "k_theta=0", "k_theta=nan", "k_theta=inf", "k_theta=1,2,3",
    "k_theta=5e7,4e8,2e8,5e7,5e7,3e7", "k1=1e7", "k7=5", "k_theta=1e7,k1=5", "k_theta=", "k_theta=-1e7",
)  # fmt: skip


def _k_of(param: str) -> float | None:
    """The one stiffness ``k_theta=K`` gives every joint (None: not that form)."""
    m = re.fullmatch(r"k_theta=([^,]+)", param)
    try:
        return float(m.group(1)) if m else None
    except ValueError:
        return None


def _matching_configs(data: bytes, tip: str, base: str | None, rows) -> tuple[tuple, tuple[int, ...]]:
    """The configurations cut or padded to the reference's coordinates of the mutated file (a
    joint made fixed, a mimic joint), and which are prismatic (1-based): the run then reaches the
    model."""
    try:
        _, joints = ref.read_joints(data.decode("utf-8"))
        if _cyclic(joints):
            return rows, ()
        coords = ref.coordinates(joints, ref.path(joints, tip, base))
    except Exception:  # noqa: BLE001 - the reference cannot read it: the seed's configurations
        return rows, ()
    n = len(coords)
    prismatic = tuple(i + 1 for i, c in enumerate(coords) if joints[c].type == "prismatic")
    return (tuple((tuple(r) + (15.0,) * n)[:n] for r in rows), prismatic) if n else (rows, ())


@st.composite
def urdf_cases(draw) -> RobotCase:
    seed = draw(st.sampled_from(sorted(URDF_SEEDS)))
    tip, base, rows = URDF_SEEDS[seed]
    data, what = draw(urdf_file(seed))
    if draw(st.integers(0, 5)) == 0:  # the tip or the base on another branch, or unknown
        data = (TEST_ROBOTS / seed).read_bytes()
        tip, base = draw(st.sampled_from(
            (("link_1", "link_3"), ("l_tool0", "r_link_1"), ("no_such_link", None), ("base_link", None),
             ("world", "tool0"), ("r_tool0", "l_link_2"))
        ))  # fmt: skip
        what = f"--tip {tip} --base {base}"
    offset, param, k, off = None, None, K_ALL, OFFSET_MM
    if draw(st.integers(0, 4)) == 0:  # the options of the valid file
        data = (TEST_ROBOTS / seed).read_bytes()
        offset, param = draw(st.sampled_from(OFFSET_VALUES)), draw(st.sampled_from(PARAM_URDF_VALUES))
        what = f"--tip-offset-mm {offset} --param {param}"
        k = _k_of(param)
        off = (
            tuple(map(float, offset.split(","))) if re.fullmatch(r"[-\d.e]+(,[-\d.e]+){2}", offset) else None
        )
    rows, prismatic = _matching_configs(data, tip, base, rows)
    files = {seed: data, "q.csv": _configs_text(rows, prismatic).encode()}
    if k is not None and off is not None and 0 < k < math.inf:
        check = urdf_check(data, tip, base, np.array(rows, dtype=float), off, k)
    else:
        check = lambda o: _finite_json(o.stdout) if o.stdout.strip() else None  # noqa: E731
    argv = _urdf_argv(seed, tip, base, offset=offset, param=param)
    return RobotCase(files, argv, None, f"{seed}: {what}", oracle=check)


# --------------------------------------------------------------------------- xacro
XACRO_MAIN = "xacro_ws/acme_description/urdf/acme_rs6.urdf.xacro"
XACRO_MACRO = "xacro_ws/acme_description/urdf/acme_rs6_macro.xacro"
XACRO_TRANS = "xacro_ws/common/urdf/transmission.xacro"


@functools.cache
def xacro_seed() -> dict[str, bytes]:
    return {
        p.relative_to(TEST_ROBOTS).as_posix(): p.read_bytes()
        for p in sorted(XACRO_WS.rglob("*"))
        if p.is_file()
    }


#: (file, text replaced, replacement, what): the mistakes of a split description.
XACRO_EDITS = (
    (XACRO_MACRO, "$(find acme_resources)", "$(find no_such_package)", "unresolved $(find)"),
    (XACRO_MACRO, "transmission.xacro", "no_such_file.xacro", "include of a missing file"),
    (XACRO_TRANS, '<xacro:macro name="acme_transmission"',
     '<xacro:include filename="$(find acme_description)/urdf/acme_rs6_macro.xacro"/>'
     '<xacro:macro name="acme_transmission"', "include loop"),
    (XACRO_MAIN, 'filename="$(find acme_description)/urdf/acme_rs6_macro.xacro"',
     'filename="acme_rs6.urdf.xacro"', "the file includes itself"),
    (XACRO_MACRO, "${radians(lower_deg)}", "${radians(lower_deg) / 0}", "division by zero"),
    (XACRO_MACRO, "${d1}", "${d_one}", "undefined property"),
    (XACRO_MACRO, 'xyz="${xyz}"', 'xyz="${xyz"', "unclosed expression"),
    (XACRO_MAIN, '<xacro:acme_rs6 prefix="$(arg prefix)"/>', "<xacro:acme_rs7/>", "unknown macro"),
    (XACRO_MACRO, '<xacro:acme_transmission joint="${prefix}joint_${n}"/>',
     '<xacro:acme_transmission/>', "macro call without its parameter"),
    (XACRO_MACRO, 'value="${with_flange}"', 'value="maybe"', "xacro:if of a non-boolean"),
    (XACRO_MACRO, 'value="0.270"', 'value="1e300"', "a property of 1e300"),
    (XACRO_MACRO, 'value="0.270"', 'value="nan"', "a property of nan"),
    (XACRO_MAIN, '<xacro:arg name="prefix" default=""/>', "", "an argument not declared"),
    (XACRO_MACRO, "</robot>", "", "a file not closed"),
)  # fmt: skip


#: --xacro-arg values: none (mount_height has no default), no value, not a number, huge.
XACRO_ARGS = (
    (), ("--xacro-arg", "mount_height"), ("--xacro-arg", "mount_height=0.25"),
    ("--xacro-arg", "mount_height=-3"), ("--xacro-arg", "mount_height=abc"),
    ("--xacro-arg", "mount_height=nan"),
    ("--xacro-arg", "=0.4"), ("--xacro-arg", "mount_height=1e300"), ("--xacro-arg", "prefix=a b"),
)  # fmt: skip


@st.composite
def xacro_cases(draw) -> RobotCase:
    files = dict(xacro_seed())
    args: tuple[str, ...] = ("--xacro-arg", "mount_height=0.4")
    kind = draw(st.sampled_from(("edit", "edit", "text", "args")))
    if kind == "edit":
        name, old, new, what = draw(st.sampled_from(XACRO_EDITS))
        files[name] = files[name].replace(old.encode(), new.encode())
    elif kind == "text":
        name = draw(st.sampled_from((XACRO_MAIN, XACRO_MACRO, XACRO_TRANS)))
        files[name] = draw(mutated_text(files[name].decode()))
        what = f"text mutation of {Path(name).name}"
    else:
        args = draw(st.sampled_from(XACRO_ARGS))
        what = f"arguments {' '.join(args) or '(none)'}"
    rows = URDF_SEEDS["acme_rs6.urdf"][2]
    files["q.csv"] = _configs_text(rows).encode()
    argv = (
        *_urdf_argv(XACRO_MAIN, "tool0", None, (*args, "--package-path", "{dir}/xacro_ws"))[:-1],
        "--json",
    )
    return RobotCase(files, argv, None, f"xacro: {what}", oracle=_xacro_check(files, args, rows))


def _xacro_check(files: dict[str, bytes], args, rows) -> Callable[[Outcome], str | None]:
    """Finite JSON; where the description is unchanged but for its arguments' values, the
    reference's answer on the vendor's pre-expanded URDF with that pedestal height."""

    seed = xacro_seed()
    mount = next((a.split("=", 1)[1] for a in args if a.startswith("mount_height=")), None)
    try:
        height = float(mount) if mount is not None else math.nan
    except ValueError:
        height = math.nan
    same = all(files[k] == v for k, v in seed.items())
    if not (same and math.isfinite(height)):
        return lambda o: _finite_json(o.stdout) if o.stdout.strip() else None
    # the vendor's pre-expanded file is the same robot on a pedestal of 0.4 m
    text = (TEST_ROBOTS / "acme_rs6.urdf").read_text().replace('xyz="0 0 0.4"', f'xyz="0 0 {height!r}"')
    return urdf_check(text.encode(), "tool0", None, np.array(rows, dtype=float), OFFSET_MM, K_ALL)


# --------------------------------------------------------------------------- configurations CSV
@st.composite
def configs_csv(draw) -> tuple[bytes, str]:
    rows = [list(r) for r in URDF_SEEDS["acme_rs6.urdf"][2]]
    names = [f"joint_{i}" for i in range(1, 7)]
    kind = draw(
        st.sampled_from(("text", "named", "missing", "unknown", "value", "units", "duplicate column"))
    )
    cols = [f"q{i}_deg" for i in range(1, 7)]
    if kind == "text":
        return draw(mutated_text(_configs_text(rows))), "text mutation"
    if kind == "named":
        cols = [f"{n}_deg" for n in names]
        order = draw(st.permutations(range(6)))
        cols, rows = [cols[i] for i in order], [[r[i] for i in order] for r in rows]
        what = "joint-named columns, any order"
    elif kind == "missing":
        i = draw(st.integers(0, 5))
        cols = [f"{n}_deg" for n in names] if draw(st.booleans()) else cols
        del cols[i]
        rows = [r[:i] + r[i + 1 :] for r in rows]
        what = f"column {i + 1} missing"
    elif kind == "unknown":
        cols[draw(st.integers(0, 5))] = draw(
            st.sampled_from(("joint_7_deg", "q7_deg", "joint_1_rad", "q1", "J1_deg"))
        )
        what = f"columns {cols}"
    elif kind == "value":
        r, c = draw(st.integers(0, len(rows) - 1)), draw(st.integers(0, 5))
        rows[r][c] = draw(st.sampled_from(BAD_NUMBERS + (1e6, 720.0)))
        what = f"row {r + 1} column {c + 1} = {rows[r][c]}"
    elif kind == "units":
        c = draw(st.integers(0, 5))
        cols[c] = f"q{c + 1}_mm"
        what = f"{cols[c]} for a revolute joint"
    else:
        c = draw(st.integers(0, 5))
        cols[c] = cols[(c + 1) % 6]
        what = f"column {cols[c]} twice"
    head = ",".join(cols)
    return (head + "\n" + "\n".join(",".join(map(str, r)) for r in rows) + "\n").encode(), what


@st.composite
def configs_cases(draw) -> RobotCase:
    text, what = draw(configs_csv())
    urdf = (TEST_ROBOTS / "acme_rs6.urdf").read_bytes()
    files = {"acme_rs6.urdf": urdf, "q.csv": text}
    return RobotCase(
        files, _urdf_argv("acme_rs6.urdf", "tool0", None), "q.csv", f"q.csv: {what}",
        oracle=_configs_check(text, urdf),
    )  # fmt: skip


def _configs_check(text: bytes, urdf: bytes) -> Callable[[Outcome], str | None]:
    """The reference at the configurations read here: columns q1_deg..q6_deg, or joint_K_deg in
    any order (the documented forms), plain numbers."""

    def check(o: Outcome) -> str | None:
        try:
            lines = [ln for ln in text.decode("ascii").splitlines() if ln.strip()]
            cols = [c.strip() for c in lines[0].split(",")]
            vals = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
        except (UnicodeDecodeError, ValueError, IndexError):
            return _finite_json(o.stdout) if o.stdout.strip() else None
        order = [f"q{i}_deg" for i in range(1, 7)], [f"joint_{i}_deg" for i in range(1, 7)]
        for names in order:
            if sorted(cols) == sorted(names) and vals.ndim == 2 and vals.shape[1] == 6:
                q = vals[:, [cols.index(n) for n in names]]
                return urdf_check(urdf, "tool0", None, q, OFFSET_MM, K_ALL)(o)
        return _finite_json(o.stdout) if o.stdout.strip() else None

    return check


# --------------------------------------------------------------------------- simulate --robot
#: --positions of the 3-RPS: poses it holds, poses it cannot (off its axis level, tilted with x,
#: y, yaw not solved), legs beyond their stroke, not numbers, absurd angles.
RPS3_POSITIONS = ("0,0,250", "0,0,250;0,0,240", "10,0,250", "0,0,nan", "0,0,1e300", "0,0,100", "0,0",
                  "", "0,0,250;;0,0,240", "inf,0,250", "0,0,-250", "0,0,400")  # fmt: skip


@st.composite
def simulate_rps3_case(draw, argv: tuple[str, ...]) -> RobotCase:
    """The shipped 3-RPS (lower mobility) with odd --positions: a list, or a poses CSV mutated
    (huge angles, NaN, poses off the ones it holds); --param within or out of its range. One case
    in four: its TOML mutated (:func:`legs_data`) at its default positions (the truth then only
    finite: the closed form is the shipped geometry's)."""
    files = {"3rps.toml": (SHIPPED / "3rps.toml").read_bytes()}
    if draw(st.integers(0, 3)) == 0:
        files["3rps.toml"], what = draw(legs_data("3rps.toml"))
        return RobotCase(
            files, (*argv, "--robot", "{dir}/3rps.toml"), None, f"3rps.toml: {what}", check=_truth_finite
        )
    if draw(st.booleans()):
        pos = draw(st.sampled_from(RPS3_POSITIONS))
        what = f"--positions {pos!r}"
    else:
        files["positions.csv"], what = draw(poses_csv("3rps.toml"))
        pos, what = "{dir}/positions.csv", f"positions.csv: {what}"
    param = _rps3_param(draw)
    override = _param_override(param) if param else None
    extra = ("--robot", "{dir}/3rps.toml", f"--positions={pos}", *((f"--param={param}",) if param else ()))
    note = f"3rps.toml: {what}" + (f" --param {param}" if param else "")
    return RobotCase(files, (*argv, *extra), None, note, check=_rps3_truth_check(override))


def _truth_finite(directory: Path, o: Outcome) -> str:
    """A run that wrote truth.json: only finite numbers or null in it."""
    truth = directory / "out" / "truth.json"
    return (_finite_json(truth.read_text()) or "") if o.code == 0 and truth.is_file() else ""


def _rps3_truth_check(params: dict[str, float] | None) -> Callable[[Path, Outcome], str]:
    """A run that wrote truth.json: every position a pose the 3-RPS holds, its K_tcp the closed
    form's (:func:`rps3_k6`); the JSON finite."""

    def check(directory: Path, o: Outcome) -> str:
        truth = directory / "out" / "truth.json"
        if o.code != 0 or not truth.is_file():
            return ""
        data = json.loads(json.dumps(legs_seed("3rps.toml")))
        data["params"].update(params or {})
        rows = []
        for p in json.loads(truth.read_text())["positions"]:
            rows.append({**dict(zip("xyz", p["position"], strict=True)),
                         **dict(zip(POSE_COLUMNS[3:], p.get("orientation_deg", [0.0] * 3), strict=True)),
                         "K6": p["K_tcp"]})  # fmt: skip
        return rps3_check(params)(Outcome(0, json.dumps(rows), "")) or ""

    return check


@st.composite
def simulate_cases(draw) -> RobotCase:
    argv = ("simulate", "{dir}/out", "--truth-only", "--select", "1", "--json")
    which = draw(st.sampled_from(("hexapod", "urdf", "3rps")))
    if which == "3rps":
        return draw(simulate_rps3_case(argv))
    if which == "hexapod":
        text, what = draw(legs_data("hexapod.toml"))
        return RobotCase(
            {"hexapod.toml": text}, (*argv, "--robot", "{dir}/hexapod.toml"), None, f"hexapod.toml: {what}"
        )
    data, what = draw(urdf_file("acme_rs6.urdf"))
    rows, prismatic = _matching_configs(data, "tool0", None, URDF_SEEDS["acme_rs6.urdf"][2])
    files = {"acme_rs6.urdf": data, "q.csv": _configs_text(rows, prismatic).encode()}
    extra = (
        "--robot",
        "{dir}/acme_rs6.urdf",
        "--tip",
        "tool0",
        "--configs",
        "{dir}/q.csv",
        "--param",
        "k_theta=1e7",
    )
    return RobotCase(files, (*argv, *extra), None, f"acme_rs6.urdf: {what}")


FUZZ_CLASSES: list[FuzzClass] = [
    FuzzClass("robots: legs TOML x model legs", legs_cases(), "hexapod, 3-RPS (dim 6), Delta (3), 3PRR (2)"),
    FuzzClass(
        "robots: poses CSV x model legs",
        poses_cases(),
        "the hexapod's and the 3-RPS's --points, --grid, --orientation, --moment-nmm",
    ),
    FuzzClass(
        "robots: URDF x model urdf",
        urdf_cases(),
        "element-level mutations, checked against a NumPy reference",
    ),
    FuzzClass(
        "robots: xacro x model urdf",
        xacro_cases(),
        "a split xacro description: args, $(find), includes, macros",
    ),
    FuzzClass("robots: configurations CSV x model urdf", configs_cases(), "q1_deg.. or joint-named columns"),
    FuzzClass(
        "robots: robot file x simulate --robot",
        simulate_cases(),
        "legs TOML and URDF, the 3-RPS's --positions, --truth-only",
        slow=True,
    ),
]
