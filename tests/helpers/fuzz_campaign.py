"""Fuzz classes of campaign directories: ``campaign.toml``, its file lists, truth files, the database.

Every class starts from a VALID campaign written by the library's own simulators
and mutates one thing:

- :func:`vision_seed`: a small simulated vision campaign, two positions of the Delta
  robot, four load cases, one repeat (10 rendered images of 300 x 700 px;
  ``stiffmap run`` measures it in well under a second), written once per process by
  :func:`stiffmap.campaign.simulated.write_campaign`, with its ``truth.json``;
  :func:`vision_seed_with_results` adds the ``stiffmap.db`` and ``exports/`` of a
  run on it (a run then resumes: positions are reused or re-derived);
- :func:`sensor_seed`: a simulated sensor campaign (3PRR, two points, LDV recordings
  as CSV) from :func:`stiffmap.campaign.simulated_sensor.write_sensor_campaign`.

Mutations are of the spec as data (:func:`mutated_spec`: a wrong type, an extreme or
non-finite number, a missing, unknown or emptied key, a huge string, a long list, at
any key of the seed's spec, then written as TOML), of the spec as text (TOML
duplicates, BOM, encodings, line ends, nesting, and the harness's generic
:func:`helpers.fuzz.mutated_text`), of the file names the spec gives
(:func:`image_index_cases`, :func:`recording_index_cases`), of the truth files
(:func:`truth_cases`) and of the directory itself (:func:`directory_cases`: a results
database that is not one, folders where files belong, a missing directory).

``blamed`` is None for most cases: a mutated spec may rightly end in a partial run
(exit 1) whose warnings name images or positions rather than ``campaign.toml``. The
test module checks the stricter property itself (:func:`names_a_campaign_file`).
"""

from __future__ import annotations

import copy
import dataclasses
import datetime
import functools
import json
import math
import re
import shutil
import sqlite3
import tempfile
import tomllib
from pathlib import Path

import numpy as np
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from helpers.fuzz import FuzzCase, FuzzClass, mutated_bytes, mutated_text, run_argv
from stiffmap.camera import CameraModel, reference_camera
from stiffmap.campaign.simulated import write_campaign
from stiffmap.campaign.simulated_sensor import write_sensor_campaign
from stiffmap.geometry import concat, transform_from
from stiffmap.loads import paper9
from stiffmap.models.prr3 import PRR3
from stiffmap.sim.robot import delta_robot
from stiffmap.sim.scene import default_scene
from stiffmap.sim.testbed import SimConfig

__all__ = [
    "FUZZ_CLASSES",
    "RUN",
    "vision_seed",
    "bare_vision_seed",
    "vision_seed_with_results",
    "sensor_seed",
    "toml_dumps",
    "mutated_spec",
    "names_a_campaign_file",
]


class CampaignCase(FuzzCase):
    """A :class:`~helpers.fuzz.FuzzCase` whose repr lists its files by size (a campaign holds MBs)."""

    def __repr__(self) -> str:
        small = {k: v for k, v in self.files.items() if len(v) <= 2000 and not k.startswith("images/")}
        big = {k: len(v) for k, v in self.files.items() if k not in small}
        shown = {k: (v if len(repr(v)) < 400 else v[:200] + b"...") for k, v in small.items()}
        return f"CampaignCase(argv={self.argv!r}, note={self.note!r}, files={shown!r}, sizes={big!r})"

    def _repr_pretty_(self, p, cycle) -> None:  # hypothesis's printer of falsifying examples
        p.text(repr(self))


#: ``stiffmap run`` as the fuzz cases call it: one process, no progress bar, no report.
RUN = ("run", "{dir}", "--quiet", "--workers", "1", "--no-report")

# ------------------------------------------------------------------------- seeds


def _read_tree(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def small_vision_config(seed: int = 7) -> SimConfig:
    """Two positions, four load cases (0.5 kg along +y, -x, -z, 0.2 kg along +y), one repeat.

    Four load cases are the fewest that identify K with an offset (three would lie on one
    plane that misses the origin).

    The reference camera's optics at half resolution, turned to look at the region
    where both boards are at these positions, on a 300 x 700 px sensor: the boards are
    as large in the image as in the reference set-up at half resolution (enough for
    every image to measure), in a twentieth of the pixels.
    """
    sc = default_scene()
    x, y = sc.camera.rays_from_pixels(np.array([[1150.0, 700.0]]))[0]
    d = np.array([x, y, 1.0]) / math.hypot(x, y, 1.0)
    axis = np.cross([0.0, 0.0, 1.0], d)
    R = Rotation.from_rotvec(axis / np.linalg.norm(axis) * math.asin(np.linalg.norm(axis))).as_matrix()
    ref = reference_camera()
    w, h = 300, 700
    cam = CameraModel((w, h), ref.fx / 2, ref.fy / 2, (w - 1) / 2, (h - 1) / 2, ref.dist)
    scene = dataclasses.replace(sc, camera=cam, cam2base=concat(transform_from(R, np.zeros(3)), sc.cam2base))
    return SimConfig(
        scene=scene,
        robot=delta_robot(),
        positions=np.array([[0.0, 0.0, -300.0], [50.0, 0.0, -300.0]]),
        loads=tuple(paper9()[:4]),
        repeats=1,
        seed=seed,
        border_px=4.0,
        robot_stays=True,  # one unloaded image per position: 5 images per position
        name="fuzz seed: two positions of the virtual test-bed",
    )


@functools.cache
def vision_seed() -> dict[str, bytes]:
    """The files of the small simulated vision campaign (relative path -> bytes)."""
    d = Path(tempfile.mkdtemp(prefix="stiffmap-seed-"))
    try:
        write_campaign(d / "c", small_vision_config(), workers=1)
        return _read_tree(d / "c")
    finally:
        shutil.rmtree(d, ignore_errors=True)


@functools.cache
def bare_vision_seed() -> dict[str, bytes]:
    """:func:`vision_seed` without its calibration views (its camera.json has no uncertainty):
    the same positions and images, written in a fifth of the time."""
    d = Path(tempfile.mkdtemp(prefix="stiffmap-seed-"))
    try:
        write_campaign(d / "c", dataclasses.replace(small_vision_config(), calibration_views=0), workers=1)
        return _read_tree(d / "c")
    finally:
        shutil.rmtree(d, ignore_errors=True)


@functools.cache
def vision_seed_with_results() -> dict[str, bytes]:
    """:func:`vision_seed` with the ``stiffmap.db`` and ``exports/`` of a run on it."""
    d = Path(tempfile.mkdtemp(prefix="stiffmap-seed-"))
    try:
        for name, data in vision_seed().items():
            (d / name).parent.mkdir(parents=True, exist_ok=True)
            (d / name).write_bytes(data)
        o = run_argv([a.replace("{dir}", str(d)) for a in RUN])
        if o.code != 0:
            raise RuntimeError(f"the seed campaign does not run: exit {o.code}: {o.stderr[-500:]}")
        return _read_tree(d)
    finally:
        shutil.rmtree(d, ignore_errors=True)


@functools.cache
def sensor_seed() -> dict[str, bytes]:
    """The files of a small simulated sensor campaign: 3PRR, two points loaded along y."""
    d = Path(tempfile.mkdtemp(prefix="stiffmap-seed-"))
    try:
        write_sensor_campaign(
            d / "c", PRR3(kj=600.0), [[400.0, 270.0], [300.0, 320.0]], directions=("y",), repeats=1, seed=9
        )
        return _read_tree(d / "c")
    finally:
        shutil.rmtree(d, ignore_errors=True)


# ------------------------------------------------------------------- TOML writing


def _toml_str(s: str) -> str:
    out = ['"']
    for c in s:
        o = ord(c)
        if c == '"':
            out.append('\\"')
        elif c == "\\":
            out.append("\\\\")
        elif o < 32 or o == 127:
            out.append(f"\\u{o:04x}")
        elif 0xD800 <= o <= 0xDFFF:
            out.append("?")  # TOML cannot hold a lone surrogate
        else:
            out.append(c)
    out.append('"')
    return "".join(out)


def _toml_key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else _toml_str(k)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _toml_str(v)
    if isinstance(v, (datetime.date, datetime.datetime, datetime.time)):
        return v.isoformat()
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def toml_dumps(d: dict, *, newline: str = "\n") -> str:
    """A TOML text of ``d``: top-level values, then one ``[table]`` per dict (nested ones dotted)."""
    lines: list[str] = []

    def table(prefix: tuple[str, ...], t: dict) -> None:
        subs = []
        if prefix:
            lines.append("")
            lines.append("[" + ".".join(_toml_key(p) for p in prefix) + "]")
        for k, v in t.items():
            if isinstance(v, dict) and v and all(isinstance(x, dict) for x in v.values()):
                subs.append((k, v))
            else:
                lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
        for k, v in subs:
            table((*prefix, k), v)

    table((), d)
    return newline.join(lines) + newline


# --------------------------------------------------------------- spec mutations


def _leaf_paths(obj, prefix: tuple = ()) -> list[tuple]:
    """Every key path of a parsed TOML document (tables, arrays and their elements, values)."""
    out = [prefix] if prefix else []
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _leaf_paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj[:4]):  # a few elements of each array are enough
            out += _leaf_paths(v, (*prefix, i))
    return out


def _get(obj, path: tuple):
    for p in path:
        obj = obj[p]
    return obj


def _set(obj, path: tuple, value) -> None:
    _get(obj, path[:-1])[path[-1]] = value


def _delete(obj, path: tuple) -> None:
    parent = _get(obj, path[:-1])
    del parent[path[-1]]


#: Values of another type than the key's, or of the same type but absurd.
WRONG_VALUES = (
    "",
    "abc",
    "9.81",
    "true",
    "é" * 3,
    "../../etc/passwd",
    "/etc/passwd",
    "a\x00b",
    "{position}",
    True,
    False,
    0,
    -1,
    1,
    2,
    3,
    2**63 - 1,
    -(2**63),
    0.0,
    -0.0,
    1.5,
    1e308,
    -1e308,
    5e-324,
    1e-300,
    1e300,
    1e20,
    math.inf,
    -math.inf,
    math.nan,
    [],
    [1],
    [1.0, 2.0],
    [[1.0, 2.0, 3.0]],
    ["a", "b"],
    [math.nan, 1.0, 2.0],
    {},
    {"a": 1},
    datetime.date(1979, 5, 27),
    datetime.datetime(1979, 5, 27, 7, 32),
)


@st.composite
def mutated_spec(draw, text: str) -> bytes:
    """A mutated ``campaign.toml``: one key of ``text``'s spec changed, then written as TOML."""
    doc = tomllib.loads(text)
    paths = _leaf_paths(doc)
    path = draw(st.sampled_from(paths))
    kind = draw(
        st.sampled_from(
            (
                "value",
                "value",
                "value",
                "delete",
                "unknown key",
                "huge string",
                "long list",
                "empty",
                "number",
            )
        )
    )
    doc = copy.deepcopy(doc)
    if kind == "value":
        _set(doc, path, draw(st.sampled_from(WRONG_VALUES)))
    elif kind == "number":
        old = _get(doc, path)
        scale = draw(st.sampled_from((-1.0, 0.0, 1e-9, 1e-6, 0.5, 2.0, 10.0, 1e3, 1e6, 1e12, 1e300)))
        if isinstance(old, (int, float)) and not isinstance(old, bool):
            _set(doc, path, type(old)(old * scale) if isinstance(old, float) else int(old * min(scale, 1e6)))
        else:
            _set(doc, path, scale)
    elif kind == "delete":
        _delete(doc, path)
    elif kind == "unknown key":
        target = _get(doc, path)
        if isinstance(target, dict):
            target[draw(st.sampled_from(("extra", "Name", "preset ", "list", "file", "κ")))] = 1
        else:
            _get(doc, path[:-1]).__setitem__(path[-1], {"value": target})
    elif kind == "huge string":
        _set(
            doc,
            path,
            draw(st.sampled_from(("x", "é", "/", "{position}"))) * draw(st.sampled_from((300, 5000, 10**6))),
        )
    elif kind == "long list":
        n = draw(st.sampled_from((100, 10**4, 10**5)))
        _set(doc, path, [[0.0, 0.0, -300.0]] * n if draw(st.booleans()) else [1.0] * n)
    elif kind == "empty":
        old = _get(doc, path)
        _set(doc, path, {} if isinstance(old, dict) else ([] if isinstance(old, list) else ""))
    try:
        return toml_dumps(doc).encode("utf-8")
    except TypeError:
        return text.encode("utf-8")


@st.composite
def toml_text_mutations(draw, text: str) -> bytes:
    """TOML-level mistakes of a valid ``campaign.toml`` text (beyond :func:`mutated_text`)."""
    lines = text.splitlines(keepends=True)
    keyed = [i for i, ln in enumerate(lines) if re.match(r"\s*[A-Za-z_][\w.]*\s*=", ln)]
    headers = [i for i, ln in enumerate(lines) if ln.lstrip().startswith("[")]
    kind = draw(
        st.sampled_from(
            (
                "duplicate key",
                "duplicate table",
                "bom",
                "crlf",
                "cr",
                "latin-1",
                "utf-16",
                "nul",
                "deep array",
                "deep table",
                "empty",
                "comments only",
                "unterminated string",
                "tab indent",
                "huge file",
            )
        )
    )
    if kind == "duplicate key" and keyed:
        i = draw(st.sampled_from(keyed))
        lines.insert(i + 1, lines[i])
    elif kind == "duplicate table" and headers:
        i = draw(st.sampled_from(headers))
        lines.append("\n" + lines[i])
    elif kind == "bom":
        return b"\xef\xbb\xbf" + text.encode("utf-8")
    elif kind == "crlf":
        return text.replace("\n", "\r\n").encode("utf-8")
    elif kind == "cr":
        return text.replace("\n", "\r").encode("utf-8")
    elif kind == "latin-1":
        return text.replace('name = "', 'name = "Müller ', 1).encode("latin-1", errors="replace")
    elif kind == "utf-16":
        return text.encode(draw(st.sampled_from(("utf-16", "utf-16-le", "utf-32"))))
    elif kind == "nul":
        i = draw(st.integers(0, len(text)))
        return (text[:i] + "\x00" + text[i:]).encode("utf-8")
    elif kind == "deep array" and keyed:
        n = draw(st.sampled_from((50, 900, 5000, 50000)))
        i = draw(st.sampled_from(keyed))
        key = lines[i].split("=", 1)[0]
        lines[i] = f"{key}= {'[' * n}1{']' * n}\n"
    elif kind == "deep table" and keyed:
        n = draw(st.sampled_from((50, 900, 5000)))
        i = draw(st.sampled_from(keyed))
        key = lines[i].split("=", 1)[0]
        lines[i] = f"{key}= {'{a = ' * n}1{'}' * n}\n"
    elif kind == "empty":
        return b""
    elif kind == "comments only":
        return "".join("# " + ln for ln in lines).encode("utf-8")
    elif kind == "unterminated string":
        return text.replace('"', "", 1).encode("utf-8")
    elif kind == "tab indent":
        return "".join("\t" + ln for ln in lines).encode("utf-8")
    elif kind == "huge file":
        return (text + "# " + "x" * (17 * 1024 * 1024) + "\n").encode("utf-8")
    return "".join(lines).encode("utf-8")


def _spec_bytes(text: str) -> st.SearchStrategy[bytes]:
    return st.one_of(
        mutated_spec(text),
        mutated_spec(text),
        toml_text_mutations(text),
        mutated_text(text),
    )


def _argv(draw, with_json: bool = True) -> tuple[str, ...]:
    extra: list[str] = []
    if with_json and draw(st.booleans()):
        extra.append("--json")
    if draw(st.integers(0, 3)) == 0:
        extra += ["--method", draw(st.sampled_from(("compliance", "paper", "spd")))]
    return (*RUN, *extra)


@st.composite
def vision_spec_cases(draw) -> FuzzCase:
    """``stiffmap run`` on the vision seed with its campaign.toml mutated (half of them resuming)."""
    files = dict(vision_seed_with_results() if draw(st.booleans()) else vision_seed())
    files["campaign.toml"] = draw(_spec_bytes(files["campaign.toml"].decode("utf-8")))
    return CampaignCase(files=files, argv=_argv(draw), blamed=None, note="campaign.toml (vision) mutated")


@st.composite
def sensor_spec_cases(draw) -> FuzzCase:
    """``stiffmap run`` on the sensor seed with its campaign.toml mutated."""
    files = dict(sensor_seed())
    files["campaign.toml"] = draw(_spec_bytes(files["campaign.toml"].decode("utf-8")))
    return CampaignCase(files=files, argv=_argv(draw), blamed=None, note="campaign.toml (sensor) mutated")


# ------------------------------------------------------------ the files it names

#: File-name patterns for [images]: outside the directory, colliding, odd format specs.
IMAGE_PATTERNS = (
    "../images/p{position:02d}/r{repeat:02d}_unloaded.png",
    "/tmp/p{position:02d}/l{load:02d}_r{repeat:02d}_loaded.png",
    "images/../../p{position}_{load}.png",
    "images/p{position:02d}/r{repeat:02d}_unloaded.png",  # the unloaded pattern, as loaded
    "images/p{position:02d}/l{load:02d}_r{repeat:02d}_loaded.png",
    "images/p{position}{load}.png",  # 1/11 and 11/1 collide
    "images/{position}.png",
    "images/p{position:02d}",  # a folder
    "images",
    "{position}{load}{repeat}",
    "images/p{position:>64}/l{load}.png",
    "images/p{position:065d}/l{load}.png",
    "images/p{position:{load}}/x.png",
    "images/p{position!r}/l{load!s}.png",
    "images/p{position:x}/l{load:o}.png",
    "images/p{position:.2f}/l{load}.png",
    "images/p{position:,}/l{load:_}.png",
    "images/p{position:c}/l{load}.png",
    "images/p{position}/l{load}/" + "d" * 300 + ".png",
    "images/p{0}/l{load}.png",
    "images/p{}/l{load}.png",
    "images/p{position.real}/l{load}.png",
    "images/p{position[0]}/l{load}.png",
    "images/p{{position}}/l{load}.png",
    "images/p{position/l{load}.png",
    "images/p\tposition}/l{load}.png",
    "images/p{position:02d}/l{load:02d}_r{repeat:02d}_loaded.PNG",
    "images/p{position:02d}/l{load:02d}_r{repeat:02d}_loaded.png ",
    "\\\\server\\share\\p{position}_{load}.png",
    "C:/images/p{position}_{load}.png",
    "~/p{position}_{load}.png",
    "images/p{position:02d}/l{load:02d}_r{repeat:02d}_loaded.png\n",
)


@st.composite
def image_index_cases(draw) -> FuzzCase:
    """The ``[images]`` patterns and ``camera.file`` changed, or the image files moved about."""
    files = dict(vision_seed_with_results() if draw(st.booleans()) else vision_seed())
    doc = tomllib.loads(files["campaign.toml"].decode("utf-8"))
    kind = draw(st.sampled_from(("loaded", "unloaded", "both", "camera", "files", "files", "repeats")))
    if kind in ("loaded", "unloaded"):
        doc["images"][kind] = draw(st.sampled_from(IMAGE_PATTERNS))
    elif kind == "both":
        p = draw(st.sampled_from(IMAGE_PATTERNS))
        doc["images"]["loaded"] = doc["images"]["unloaded"] = p
    elif kind == "camera":
        doc["camera"]["file"] = draw(
            st.sampled_from(
                (
                    "../camera.json",
                    "/etc/passwd",
                    "/dev/null",
                    "/dev/zero",
                    "images",
                    "truth.json",
                    "truth_corners.json.gz",
                    "stiffmap.db",
                    "campaign.toml",
                    "images/p01/r01_unloaded.png",
                    "./camera.json",
                    "images/../camera.json",
                    "CAMERA.JSON",
                    "",
                    " ",
                    "camera.json/",
                )
            )
        )
    elif kind == "files":
        images = sorted(k for k in files if k.startswith("images/"))
        for name in draw(st.lists(st.sampled_from(images), min_size=1, max_size=len(images), unique=True)):
            what = draw(st.sampled_from(("delete", "folder", "empty", "swap", "other name")))
            data = files.pop(name)
            if what == "folder":
                files[f"{name}/x.png"] = data
            elif what == "empty":
                files[name] = b""
            elif what == "swap":
                files[name] = vision_seed()[draw(st.sampled_from(images))]
            elif what == "other name":
                files[name.replace(".png", ".PNG")] = data
    elif kind == "repeats":
        doc["repeats"] = draw(st.sampled_from((2, 3, 1000)))
        doc["images"]["loaded"] = draw(st.sampled_from(IMAGE_PATTERNS + (doc["images"]["loaded"],)))
    files["campaign.toml"] = toml_dumps(doc).encode("utf-8")
    extra = ("--allow-outside-paths",) if draw(st.integers(0, 4)) == 0 else ()
    return CampaignCase(files=files, argv=(*RUN, *extra), blamed=None, note=f"[images]/camera.file: {kind}")


#: Recording file names: outside, duplicates, the campaign's other files, folders, odd names.
RECORDING_NAMES = (
    "../recordings/trace_000.csv",
    "/etc/passwd",
    "/dev/zero",
    "recordings",
    "recordings/",
    "recordings/index.csv",
    "recordings/truth.json",
    "truth.json",
    "campaign.toml",
    "stiffmap.db",
    "recordings/trace_000.csv",
    "recordings/./trace_000.csv",
    "recordings/missing.csv",
    "recordings/trace_000.tdms",
    "recordings/trace_000.mat",
    "recordings/trace_000",
    "recordings/trace_000.CSV",
    "recordings/" + "t" * 300 + ".csv",
    "",
    "\t",
)


@st.composite
def recording_index_cases(draw) -> FuzzCase:
    """The ``[sensor] recordings`` list changed: file names, points, directions, signs, plateaus."""
    files = dict(sensor_seed())
    doc = tomllib.loads(files["campaign.toml"].decode("utf-8"))
    recs = doc["sensor"]["recordings"]
    i = draw(st.integers(0, len(recs) - 1))
    kind = draw(
        st.sampled_from(("file", "file", "point", "direction", "sign", "step_times", "list", "files"))
    )
    if kind == "file":
        recs[i]["file"] = draw(st.sampled_from(RECORDING_NAMES))
    elif kind == "point":
        recs[i]["point"] = draw(
            st.sampled_from(
                (
                    [],
                    [400.0],
                    [400.0, 270.0, 0.0],
                    [1e6, 0.0],
                    [1e7, 0.0],
                    [-1.0, -1.0],
                    [0.0, 0.0],
                    [400.0, 270.0, 0.0, 1.0],
                )
            )
        )
    elif kind == "direction":
        recs[i]["direction"] = draw(st.sampled_from(("x", "-y", "z", "-z", "xy", "", "Y", "+y")))
    elif kind == "sign":
        recs[i]["sign"] = draw(st.sampled_from((0, 2, -1, 1.0, True, "-1")))
    elif kind == "step_times":
        recs[i]["step_times"] = draw(
            st.sampled_from(
                (
                    [[0.0, 4.0], [6.0, 9.0]],
                    [
                        [0.0, 4.0],
                        [6.0, 9.0],
                        [10.5, 14.0],
                        [16.0, 19.5],
                        [21.0, 24.5],
                        [26.0, 30.0],
                        [32.0, 36.0],
                    ],
                    [[0.0, 4.0]],
                    [[4.0, 0.0], [6.0, 9.0]],
                    [[0.0, 1e9], [1e9, 2e9]],
                    [[0.0, 1e-9], [1.0, 1.0 + 1e-9]],
                    [[100.0, 101.0], [200.0, 201.0]],
                    [[0.0, 4.0], [0.0, 4.0]],
                    [[0.0, 36.0], [0.0, 36.0]],
                )
            )
        )
    elif kind == "list":
        what = draw(st.sampled_from(("empty", "duplicate", "many", "drop")))
        if what == "empty":
            recs.clear()
        elif what == "duplicate":
            recs.append(dict(recs[i]))
        elif what == "many":
            recs.extend(
                {**recs[i], "file": f"recordings/r{k}.csv"} for k in range(draw(st.sampled_from((10, 20000))))
            )
        else:
            recs.pop(i)
    elif kind == "files":
        name = recs[i]["file"]
        what = draw(st.sampled_from(("delete", "folder", "empty", "other's")))
        data = files.pop(name, b"")
        if what == "folder":
            files[f"{name}/x.csv"] = data
        elif what == "empty":
            files[name] = b""
        elif what == "other's":
            files[name] = files[recs[1 - i]["file"]] if len(recs) > 1 else data
    files["campaign.toml"] = toml_dumps(doc).encode("utf-8")
    extra = ("--allow-outside-paths",) if draw(st.integers(0, 4)) == 0 else ()
    return CampaignCase(files=files, argv=(*RUN, *extra), blamed=None, note=f"[sensor] recordings: {kind}")


# ------------------------------------------------------------------ truth files


@st.composite
def truth_cases(draw) -> FuzzCase:
    """``stiffmap report DIR`` (and a resumed ``run``) on a campaign whose truth files are mutated.

    ``truth.json`` is an optional extra of simulated campaigns: the report leaves out
    one it cannot use (the command still succeeds), and never fails because of it.
    """
    files = dict(vision_seed_with_results())
    which = draw(st.sampled_from(("truth.json", "truth.json", "truth_corners.json.gz", "both")))
    if which in ("truth.json", "both"):
        text = files["truth.json"].decode("utf-8")
        if draw(st.booleans()):
            files["truth.json"] = draw(mutated_text(text))
        else:
            d = json.loads(text)
            key = draw(st.sampled_from(("positions", "camera", "cam2base", "format", "kind", "corners_file")))
            d[key] = draw(
                st.sampled_from(
                    (
                        None,
                        [],
                        {},
                        "x",
                        1e308,
                        [[float("nan")] * 3] * 3,
                        [{"K": "a", "position": [0]}],
                        "../../etc/passwd",
                    )
                )
            )
            files["truth.json"] = json.dumps(d).encode("utf-8")
    if which in ("truth_corners.json.gz", "both"):
        files["truth_corners.json.gz"] = draw(mutated_bytes(files["truth_corners.json.gz"]))
    argv = draw(st.sampled_from((("report", "{dir}", "--no-png"), RUN)))
    return CampaignCase(files=files, argv=argv, blamed=None, note=f"{which} mutated")


# ---------------------------------------------------------------- the directory


@st.composite
def directory_cases(draw) -> FuzzCase:
    """``stiffmap run``, ``report`` or ``init`` on odd directories and results databases."""
    kind = draw(
        st.sampled_from(
            (
                "db bytes",
                "db bytes",
                "db other",
                "db folder",
                "wal",
                "no spec",
                "spec folder",
                "exports file",
                "report file",
                "camera folder",
                "missing dir",
                "a file",
                "init",
            )
        )
    )
    files = dict(vision_seed_with_results())
    blamed: str | None = None
    argv = RUN
    if kind == "db bytes":
        files["stiffmap.db"] = draw(mutated_bytes(files["stiffmap.db"]))
    elif kind == "db other":
        files["stiffmap.db"] = draw(
            st.sampled_from(
                (
                    b"",
                    b"SQLite format 3\x00",
                    b"SQLite format 3\x00" + bytes(4096),
                    b"not a database\n" * 100,
                    files["campaign.toml"],
                    files["images/p01/r01_unloaded.png"][:8192],
                    _other_sqlite(),
                    _other_schema_version(files["stiffmap.db"]),
                )
            )
        )
        blamed = "stiffmap.db" if files["stiffmap.db"] else None
    elif kind == "db folder":
        del files["stiffmap.db"]
        files["stiffmap.db/x"] = b""
        blamed = "stiffmap.db"
    elif kind == "wal":
        files["stiffmap.db-wal"] = draw(
            st.sampled_from((b"", b"\x37\x7f\x06\x82" + bytes(100), bytes(33000)))
        )
        files["stiffmap.db-shm"] = draw(st.sampled_from((b"", bytes(32768), b"\xff" * 32768)))
    elif kind == "no spec":
        del files["campaign.toml"]
        blamed = "campaign.toml"
    elif kind == "spec folder":
        del files["campaign.toml"]
        files["campaign.toml/x"] = b"name = 'x'\n"
        blamed = "campaign.toml"
    elif kind == "exports file":
        files = {k: v for k, v in files.items() if not k.startswith("exports/")}
        files["exports"] = b"x"
        blamed = "exports"
    elif kind == "report file":
        files["report"] = b"x"
        argv = draw(
            st.sampled_from((("run", "{dir}", "--quiet", "--workers", "1"), ("report", "{dir}", "--no-png")))
        )
        blamed = "report"
    elif kind == "camera folder":
        files["camera.json/x"] = files.pop("camera.json")
        blamed = "camera.json"
    elif kind == "missing dir":
        argv = (*RUN[:1], "{dir}/missing", *RUN[2:])
        blamed = "missing"
    elif kind == "a file":
        argv = draw(
            st.sampled_from(
                (
                    (*RUN[:1], "{dir}/camera.json", *RUN[2:]),
                    (*RUN[:1], "{dir}/campaign.toml", *RUN[2:]),
                    ("report", "{dir}/camera.json", "--no-png"),
                    ("init", "{dir}/camera.json"),
                )
            )
        )
        blamed = None
    elif kind == "init":
        argv = draw(
            st.sampled_from(
                (
                    ("init", "{dir}"),
                    ("init", "{dir}", "--force"),
                    ("init", "{dir}/new"),
                    ("init", "{dir}", "--from-demo"),
                    ("init", "{dir}/camera.json", "--from-demo"),
                    ("init", "{dir}/images", "--from-demo", "--force"),
                )
            )
        )
    if kind.startswith("db") or kind == "wal":
        argv = draw(st.sampled_from((RUN, ("report", "{dir}", "--no-png"))))
    return CampaignCase(files=files, argv=argv, blamed=blamed, note=f"directory: {kind}")


@functools.cache
def _other_sqlite() -> bytes:
    """A SQLite database of another program (its own tables)."""
    d = Path(tempfile.mkdtemp(prefix="stiffmap-seed-"))
    try:
        conn = sqlite3.connect(d / "x.db")
        conn.execute("CREATE TABLE stiffness (a TEXT, b REAL)")
        conn.execute("INSERT INTO stiffness VALUES ('x', 1.0)")
        conn.commit()
        conn.close()
        return (d / "x.db").read_bytes()
    finally:
        shutil.rmtree(d, ignore_errors=True)


def _other_schema_version(db: bytes) -> bytes:
    """The seed's database with another schema version."""
    d = Path(tempfile.mkdtemp(prefix="stiffmap-seed-"))
    try:
        (d / "x.db").write_bytes(db)
        conn = sqlite3.connect(d / "x.db")
        conn.execute("UPDATE meta SET value = '99' WHERE key = 'schema_version'")
        conn.commit()
        conn.close()
        return (d / "x.db").read_bytes()
    finally:
        shutil.rmtree(d, ignore_errors=True)


# ------------------------------------------------------------------ the property


def names_a_campaign_file(case: FuzzCase, stderr: str, code: int | None) -> bool:
    """The stricter property of this module's cases: every message line names what it is about.

    Exit 2 (nothing done): the ``error:`` line names a file of the campaign (or the
    directory). Exit 1 (done with failures): each ``warning:`` line names an image, a
    recording, a position, the model fit or ``campaign.toml``.
    """
    lines = [ln for ln in stderr.splitlines() if ln.startswith(("error:", "warning:"))]
    if code == 2:
        err = [ln for ln in lines if ln.startswith("error:")]
        return bool(err) and any(
            ("/" in ln or "campaign.toml" in ln or "stiffmap.db" in ln or "--" in ln) for ln in err
        )
    if code == 1:
        items = re.compile(
            r"(\.(png|csv|tdms|mat|json|toml|db)\b|position \d|recording |model fit"
            r"|campaign\.toml|robot model)"
        )
        return all(items.search(ln) for ln in lines)
    return True


FUZZ_CLASSES: list[FuzzClass] = [
    FuzzClass(
        "campaign.toml (vision) x run",
        vision_spec_cases(),
        "the vision seed's campaign.toml mutated as data (every key: wrong types, extreme and "
        "non-finite numbers, missing, unknown, huge) and as text (TOML duplicates, BOM, encodings, "
        "line ends, nesting, the generic mutations); half of the runs resume a database",
    ),
    FuzzClass(
        "campaign.toml (sensor) x run",
        sensor_spec_cases(),
        "the sensor seed's campaign.toml mutated as data and as text",
    ),
    FuzzClass(
        "[images] patterns, camera.file, image files x run",
        image_index_cases(),
        "file names of the vision campaign: patterns leading outside, colliding, odd format specs; "
        "the camera file named elsewhere; images deleted, emptied, swapped, turned into folders",
    ),
    FuzzClass(
        "[sensor] recordings list x run",
        recording_index_cases(),
        "the sensor campaign's list of recordings: file names (outside, duplicated, other files of "
        "the campaign, folders), points, directions, signs, plateaus by hand, recordings deleted",
    ),
    FuzzClass(
        "truth.json, truth_corners.json.gz x report, run",
        truth_cases(),
        "a simulated campaign's truth files mutated; the report leaves out what it cannot use",
    ),
    FuzzClass(
        "campaign directory, stiffmap.db x run, report, init",
        directory_cases(),
        "results databases that are not one (mutated bytes, another program's, another schema, "
        "a folder, stray WAL files), folders where files belong, a missing directory, a file",
    ),
]
