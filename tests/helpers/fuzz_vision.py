"""Fuzz classes of the vision path: camera.json, the fixed2base transform, images, stage manifests, options.

Every class starts from valid inputs a lab would have: a small camera (320x240 px, the
quick tests' camera at half the resolution) written by :func:`stiffmap.camera.save_camera`
with the fields a calibration writes, images of a 7x6 mobile and a 9x4 fixed chessboard
rendered through it (:func:`helpers.board_images.quick_board_image`), calibration views of
a board, a ``fixed2base`` transform and a stage manifest; then one input is made malformed
(:func:`helpers.fuzz.mutated_text`, :func:`helpers.fuzz.mutated_bytes`, and the targeted
strategies below: a wrong type or an extreme value at one key of camera.json, a transform
that is not rigid, an image re-encoded, cut, shrunk to 1x1 or replaced by a text file or a
directory, a board size or a dictionary that does not exist).

:data:`FUZZ_CLASSES` lists them for ``tests/test_fuzz_vision.py`` and
``benchmarks/bench_fuzz.py``. The valid inputs are rendered once per process
(:func:`seeds`, about a second).
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass

import cv2
import numpy as np
from hypothesis import strategies as st

from helpers.board_images import quick_board_image
from helpers.board_scenes import close_two_target_poses, look_at_pose, moved_pose, scaled_camera, small_camera
from helpers.fuzz import FuzzCase, FuzzClass, mutated_bytes, mutated_text
from stiffmap.camera import CameraModel
from stiffmap.geometry import matrix_from_rotvec
from stiffmap.io import dumps_json
from stiffmap.targets import Chessboard

__all__ = ["FUZZ_CLASSES", "Seeds", "seeds", "CAMERA", "MOBILE", "FIXED", "CALIB_BOARD"]

#: The camera of every class: 320x240 px, moderate barrel distortion.
CAMERA = scaled_camera(small_camera(), 0.5)
MOBILE = Chessboard(7, 6, 10.0)
FIXED = Chessboard(9, 4, 10.0)
#: The board of the calibration views (bigger squares: it fills more of the small image).
CALIB_BOARD = Chessboard(7, 6, 20.0)

#: Stage steps of the manifest, mm.
_STAGE_AXIS = np.array([0.8, 0.1, 0.59]) / np.linalg.norm([0.8, 0.1, 0.59])


@dataclass(frozen=True)
class Seeds:
    """The valid inputs every class mutates (file name -> bytes)."""

    camera_json: bytes
    fixed2base_json: bytes
    images: dict[str, bytes]  # ref.png, ref2.png, moved.png, stage2.png, stage5.png (PNG, 8-bit grey)
    arrays: dict[str, np.ndarray]  # the same as arrays, to re-encode
    calib_views: dict[str, bytes]  # view1.png ... view5.png of CALIB_BOARD
    manifest: str  # stage.csv
    mobile2cam: dict[str, np.ndarray]  # the true pose of the mobile board in each image
    fixed2cam: np.ndarray
    fixed2base: np.ndarray


def _png(img: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", img)
    assert ok
    return buf.tobytes()


def _calibrated_camera() -> CameraModel:
    """CAMERA with the fields `stiffmap calibrate` writes (std, RMS, views)."""
    c = CAMERA
    return CameraModel(
        c.image_size,
        c.fx,
        c.fy,
        c.cx,
        c.cy,
        c.dist,
        std={"fx": 0.8, "fy": 0.8, "cx": 0.6, "cy": 0.5, "dist": [0.004, 0.02, 0.0002, 0.0002, 0.05]},
        rms_px=0.05,
        residual_std_px=(0.04, 0.035),
        views=tuple(
            {"image": f"view{k}.png", "used": True, "rms_px": 0.05, "reason": ""} for k in range(1, 6)
        ),
    )


@functools.cache
def seeds() -> Seeds:
    """Render and write the valid inputs (once per process)."""
    rng = np.random.default_rng(16)
    M0, F = close_two_target_poses(MOBILE, FIXED)
    delta = np.array([0.5, -0.2, 0.3, 1e-3, -2e-3, 5e-4])
    shots = {
        "ref.png": M0,
        "ref2.png": M0,
        "moved.png": moved_pose(M0, delta),
        "stage2.png": moved_pose(M0, np.r_[2.0 * _STAGE_AXIS, 0, 0, 0]),
        "stage5.png": moved_pose(M0, np.r_[5.0 * _STAGE_AXIS, 0, 0, 0]),
    }
    arrays = {
        name: quick_board_image(CAMERA, [(FIXED, F), (MOBILE, T)], rng=rng) for name, T in shots.items()
    }
    tilts = [(0, 0, 0), (25, 0, 5), (-25, 5, -5), (0, 25, 10), (5, -25, -10)]
    offsets = [(0, 0), (15, 10), (-15, -10), (10, -15), (-10, 15)]
    calib = {
        f"view{k + 1}.png": _png(
            quick_board_image(
                CAMERA,
                [(CALIB_BOARD, look_at_pose(330, CALIB_BOARD, tilt_deg=t, offset_mm=o))],
                rng=rng,
            )
        )
        for k, (t, o) in enumerate(zip(tilts, offsets, strict=True))
    }
    B = np.eye(4)
    B[:3, :3] = matrix_from_rotvec([0.1, -0.2, 0.3])
    B[:3, 3] = [150.0, -20.0, 35.0]
    manifest = "image,nominal_mm\nref.png,0\nref2.png,0\nstage2.png,2\nstage5.png,5\n"
    return Seeds(
        camera_json=(dumps_json(_calibrated_camera().to_dict()) + "\n").encode(),
        fixed2base_json=(dumps_json({"fixed2base": B}) + "\n").encode(),
        images={k: _png(v) for k, v in arrays.items()},
        arrays=arrays,
        calib_views=calib,
        manifest=manifest,
        mobile2cam=shots,
        fixed2cam=F,
        fixed2base=B,
    )


# ------------------------------------------------------------------------------ JSON values
#: JSON texts put where a value belongs: extreme numbers, wrong types, deep nesting.
RAW_JSON_VALUES = (
    "0",
    "-0.0",
    "-1",
    "1e308",
    "-1e308",
    "1e-308",
    "5e-324",
    "1e10",
    "-1e10",
    "1e-10",
    "NaN",
    "Infinity",
    "-Infinity",
    "9" * 400,
    "1" * 5000,
    '"abc"',
    '""',
    '"1.5"',
    "null",
    "true",
    "false",
    "[]",
    "{}",
    "[1, 2]",
    "[320, 240, 1]",
    "[[320, 240]]",
    '{"a": 1}',
    "[" * 3000 + "]" * 3000,
)
#: Factors a plausible number is multiplied by (some keep it plausible, some do not).
FACTORS = (0.0, -1.0, 1e-3, 0.05, 0.5, 0.999, 1.001, 2.0, 50.0, 200.0, 1e3, 1e6)

_SENTINEL = "@@FUZZ@@"


def _paths(obj, prefix=()):
    """Every path (tuple of keys/indices) to a value inside a JSON object."""
    out = [prefix] if prefix else []
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            out += _paths(v, (*prefix, i))
    return out


def _get(obj, path):
    for p in path:
        obj = obj[p]
    return obj


def _set(obj, path, value):
    parent = _get(obj, path[:-1])
    parent[path[-1]] = value


@st.composite
def mutated_json_value(draw, valid: str) -> bytes:
    """A JSON file with one value replaced: an extreme number, a wrong type, a scaled number,
    or a key removed or added, or the whole file replaced by another JSON value."""
    data = json.loads(valid)
    paths = _paths(data)
    kind = draw(st.sampled_from(("raw", "raw", "scale", "drop", "extra", "whole", "length")))
    if kind == "whole":
        return draw(st.sampled_from(RAW_JSON_VALUES)).encode()
    path = draw(st.sampled_from(paths))
    target = _get(data, path)
    if kind == "scale" and isinstance(target, (int, float)) and not isinstance(target, bool):
        v = target * draw(st.sampled_from(FACTORS))
        _set(data, path, int(v) if isinstance(target, int) and abs(v) < 1e15 else v)
        return json.dumps(data).encode()
    if kind == "drop":
        parent = _get(data, path[:-1])
        del parent[path[-1]]
        return json.dumps(data).encode()
    if kind == "extra":
        parent = _get(data, path[:-1])
        if isinstance(parent, dict):
            parent["unknown_key"] = 1
        else:
            parent.append(draw(st.sampled_from((0.0, 1e300, "x", None))))
        return json.dumps(data).encode()
    if kind == "length" and isinstance(target, list):
        n = draw(st.integers(0, 14))
        _set(data, path, (target * 14)[:n] if target else [0.0] * n)
        return json.dumps(data).encode()
    _set(data, path, _SENTINEL)
    return json.dumps(data).replace(f'"{_SENTINEL}"', draw(st.sampled_from(RAW_JSON_VALUES))).encode()


def malformed_json(valid: str) -> st.SearchStrategy[bytes]:
    """Targeted value mutations and the harness's text mutations of a JSON file."""
    return st.one_of(mutated_json_value(valid), mutated_text(valid))


# --------------------------------------------------------------------------------- commands
def _measure_argv(command: str, *images: str, json_out: bool = True) -> tuple[str, ...]:
    argv = (command, *(f"{{dir}}/{i}" for i in images), "--camera", "{dir}/camera.json")
    argv += ("--board", MOBILE.size, "--square-mm", f"{MOBILE.square_mm:g}")
    return argv + (("--json",) if json_out else ())


def _fixed_argv() -> tuple[str, ...]:
    return ("--fixed-board", FIXED.size, "--fixed-square-mm", f"{FIXED.square_mm:g}", "--fixed2base")


def displacement_argv(*, fixed: bool = True, reference: str = "ref.png", moved: str = "moved.png"):
    """``stiffmap displacement moved --reference ref ...`` (with the fixed target when ``fixed``)."""
    argv = _measure_argv("displacement", moved) + ("--reference", f"{{dir}}/{reference}")
    if fixed:
        argv += (*_fixed_argv(), "{dir}/fixed2base.json")
    return argv


def validate_argv() -> tuple[str, ...]:
    return ("validate", "{dir}/stage.csv", *_measure_argv("validate")[1:])


# ---------------------------------------------------------------------------- camera.json
@st.composite
def _camera_cases(draw, command: str) -> FuzzCase:
    s = seeds()
    cam = draw(malformed_json(s.camera_json.decode()))
    files = {"camera.json": cam}
    if command == "pose":
        files |= {"ref.png": s.images["ref.png"], "moved.png": s.images["moved.png"]}
        argv = _measure_argv("pose", "ref.png", "moved.png")
    elif command == "displacement":
        files |= {k: s.images[k] for k in ("ref.png", "moved.png")} | {"fixed2base.json": s.fixed2base_json}
        argv = displacement_argv()
    else:
        files |= {k: s.images[k] for k in ("ref.png", "ref2.png", "stage2.png", "stage5.png")}
        files["stage.csv"] = s.manifest.encode()
        argv = validate_argv()
    return FuzzCase(files=files, argv=argv, blamed="camera.json", note=f"camera.json for {command}")


# ------------------------------------------------------------------------------ fixed2base
#: Matrices that are not a rigid transform, or not a 4x4 matrix of numbers.
def _bad_transforms() -> list:
    R = matrix_from_rotvec([0.1, -0.2, 0.3])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = [150.0, -20.0, 35.0]
    out = []
    for f in (0.0, 0.5, 1.001, 2.0, -1.0):  # scaled rotations (f = -1: a reflection)
        M = T.copy()
        M[:3, :3] *= f
        out.append(M.tolist())
    M = T.copy()
    M[0, 1] += 0.01  # shear
    out.append(M.tolist())
    M = T.copy()
    M[3] = [0, 0, 1, 1]  # bottom row
    out.append(M.tolist())
    M = T.copy()
    M[3, 3] = 2.0
    out.append(M.tolist())
    M = T.copy()
    M[:3, 3] = [1e300, 0, 0]  # translation of 1e300 mm
    out.append(M.tolist())
    M = T.copy()
    M[:3, 3] = [1e12, -1e12, 0]  # a transform from another unit?
    out.append(M.tolist())
    M = T.copy()
    M[:3, :3] = np.diag([1.0, 1.0, -1.0]) @ R  # det -1
    out.append(M.tolist())
    out.append(np.zeros((4, 4)).tolist())
    out.append(T[:3].tolist())
    out.append(T[:3, :3].tolist())
    out.append(T.ravel().tolist())
    out.append([[1, 0, 0, 0], [0, 1, 0], [0, 0, 1, 0], [0, 0, 0, 1]])  # ragged
    return out


@st.composite
def _fixed2base_cases(draw) -> FuzzCase:
    s = seeds()
    valid = s.fixed2base_json.decode()
    kind = draw(st.sampled_from(("json", "matrix")))
    if kind == "matrix":
        M = draw(st.sampled_from(_bad_transforms()))
        wrap = draw(st.sampled_from(("fixed2base", "matrix", "plain", "other")))
        obj = M if wrap == "plain" else {wrap: M}
        text = json.dumps(obj).encode()
    else:
        text = draw(malformed_json(valid))
    files = {k: s.images[k] for k in ("ref.png", "moved.png")}
    files |= {"camera.json": s.camera_json, "fixed2base.json": text}
    return FuzzCase(files=files, argv=displacement_argv(), blamed="fixed2base.json", note="fixed2base")


# ---------------------------------------------------------------------------------- images
def _encode(ext: str, img: np.ndarray, params=()) -> bytes:
    ok, buf = cv2.imencode(ext, img, list(params))
    assert ok, ext
    return buf.tobytes()


def _png_header_only(w: int, h: int, bit_depth: int = 8, colour: int = 0) -> bytes:
    """A PNG whose IHDR declares w x h but whose data is one empty IDAT (then IEND)."""
    import struct
    import zlib

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    ihdr = struct.pack(">IIBBBBB", w, h, bit_depth, colour, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b"\x00" * 16))
        + chunk(b"IEND", b"")
    )


def _image_variants() -> dict[str, tuple[str, bytes]]:
    """Variants of the moved image: label -> (file name, bytes). Some are valid, most are not."""
    s = seeds()
    a = s.arrays["moved.png"]
    a16 = a.astype(np.uint16) * 257
    bgr = cv2.cvtColor(a, cv2.COLOR_GRAY2BGR)
    w, h = CAMERA.image_size
    noise = np.random.default_rng(3).integers(0, 256, (h, w), dtype=np.uint8)
    f32 = a.astype(np.float32) / 255
    f32_nan = f32.copy()
    f32_nan[10, 10] = np.nan
    return {
        # Valid encodings of the same picture (the pose must not change).
        "tiff 8 bit": ("moved.tif", _encode(".tiff", a)),
        "tiff 16 bit": ("moved.tif", _encode(".tiff", a16)),
        "png 16 bit": ("moved.png", _encode(".png", a16)),
        "png colour": ("moved.png", _encode(".png", bgr)),
        "jpeg 95": ("moved.jpg", _encode(".jpg", a, (cv2.IMWRITE_JPEG_QUALITY, 95))),
        "jpeg colour 85": ("moved.jpg", _encode(".jpg", bgr, (cv2.IMWRITE_JPEG_QUALITY, 85))),
        "bmp": ("moved.bmp", _encode(".bmp", a)),
        "pgm": ("moved.pgm", _encode(".pgm", a)),
        "png named .jpg": ("moved.jpg", s.images["moved.png"]),
        "tiff float32": ("moved.tif", _encode(".tiff", f32)),
        # Pictures that hold no board, or are of another size.
        "tiff float32 with NaN": ("moved.tif", _encode(".tiff", f32_nan)),
        "1x1": ("moved.png", _encode(".png", np.zeros((1, 1), np.uint8))),
        "2x2": ("moved.png", _encode(".png", np.zeros((2, 2), np.uint8))),
        "7x7": ("moved.png", _encode(".png", np.full((7, 7), 128, np.uint8))),
        "1x240": ("moved.png", _encode(".png", np.full((240, 1), 128, np.uint8))),
        "constant": ("moved.png", _encode(".png", np.full((h, w), 90, np.uint8))),
        "black 16 bit": ("moved.png", _encode(".png", np.zeros((h, w), np.uint16))),
        "white": ("moved.png", _encode(".png", np.full((h, w), 255, np.uint8))),
        "noise": ("moved.png", _encode(".png", noise)),
        "inverted": ("moved.png", _encode(".png", 255 - a)),
        "mirrored": ("moved.png", _encode(".png", a[:, ::-1].copy())),
        "upside down": ("moved.png", _encode(".png", a[::-1, ::-1].copy())),
        "transposed": ("moved.png", _encode(".png", a.T.copy())),
        "double size": ("moved.png", _encode(".png", cv2.resize(a, (2 * w, 2 * h)))),
        "cropped": ("moved.png", _encode(".png", a[:-1, :-1].copy())),
        # Files that are not images.
        "empty": ("moved.png", b""),
        "text named .png": ("moved.png", b"not pixels\n"),
        "json named .png": ("moved.png", s.camera_json),
        "magic only": ("moved.png", b"\x89PNG\r\n\x1a\n"),
        "png magic then text": ("moved.png", b"\x89PNG\r\n\x1a\n" + b"x" * 100 + b"IEND\xaeB`\x82"),
        "jpeg magic then zeros": ("moved.jpg", b"\xff\xd8" + bytes(200) + b"\xff\xd9"),
        "tiff magic only": ("moved.tif", b"II*\x00" + bytes(12)),
        "huge declared png": ("moved.png", _png_header_only(100_000, 100_000)),
        "big declared png": ("moved.png", _png_header_only(30_000, 30_000)),
        "huge declared 16-bit colour png": ("moved.png", _png_header_only(40_000, 40_000, 16, 2)),
        "zero declared png": ("moved.png", _png_header_only(0, 0)),
        "directory named .png": ("moved.png/", b""),
        "missing": ("", b""),
    }


IMAGE_VARIANTS = (
    "tiff 8 bit",
    "tiff 16 bit",
    "png 16 bit",
    "png colour",
    "jpeg 95",
    "jpeg colour 85",
    "bmp",
    "pgm",
    "png named .jpg",
    "tiff float32",
    "tiff float32 with NaN",
    "1x1",
    "2x2",
    "7x7",
    "1x240",
    "constant",
    "black 16 bit",
    "white",
    "noise",
    "inverted",
    "mirrored",
    "upside down",
    "transposed",
    "double size",
    "cropped",
    "empty",
    "text named .png",
    "json named .png",
    "magic only",
    "png magic then text",
    "jpeg magic then zeros",
    "tiff magic only",
    "huge declared png",
    "big declared png",
    "huge declared 16-bit colour png",
    "zero declared png",
    "directory named .png",
    "missing",
)
#: Variants that are the same picture as the valid image (its pose must come out again).
SAME_PICTURE = frozenset(IMAGE_VARIANTS[:10])


@functools.cache
def image_variants() -> dict[str, tuple[str, bytes]]:
    return _image_variants()


@st.composite
def bad_image(draw, valid: bytes, stem: str = "bad") -> tuple[str, dict[str, bytes], str]:
    """(label, files, the name to pass on the command line) of a malformed or re-encoded image:
    a variant of the moved image (:data:`IMAGE_VARIANTS`), or ``valid`` with bytes mutated."""
    if draw(st.booleans()):
        label = draw(st.sampled_from(IMAGE_VARIANTS))
        name, data = image_variants()[label]
        name = name.replace("moved", stem)
        if label == "missing":
            return label, {}, f"{stem}.png"
        if name.endswith("/"):
            return label, {name + "inside.txt": b"x"}, name.rstrip("/")
        return label, {name: data}, name
    data = draw(mutated_bytes(valid))
    return "mutated bytes", {f"{stem}.png": data}, f"{stem}.png"


@st.composite
def _image_pose_cases(draw) -> FuzzCase:
    s = seeds()
    label, files, name = draw(bad_image(s.images["moved.png"]))
    files = {"ref.png": s.images["ref.png"], "camera.json": s.camera_json} | files
    order = ("ref.png", name) if draw(st.booleans()) else (name, "ref.png")
    return FuzzCase(files=files, argv=_measure_argv("pose", *order), blamed=name, note=f"image: {label}")


@st.composite
def _image_displacement_cases(draw) -> FuzzCase:
    s = seeds()
    label, files, name = draw(bad_image(s.images["moved.png"]))
    files = {k: s.images[k] for k in ("ref.png", "moved.png")} | {"camera.json": s.camera_json} | files
    files["fixed2base.json"] = s.fixed2base_json
    if draw(st.booleans()):  # a bad moved image beside a good one
        argv = displacement_argv() + (f"{{dir}}/{name}",)
    else:  # a bad second reference beside a good one
        argv = displacement_argv() + ("--reference", f"{{dir}}/{name}")
    return FuzzCase(files=files, argv=argv, blamed=name, note=f"image: {label}")


@st.composite
def _image_calibrate_cases(draw) -> FuzzCase:
    s = seeds()
    label, files, name = draw(bad_image(s.calib_views["view5.png"]))
    views = dict(s.calib_views)
    files = views | files
    names = [*views, name]
    argv = ("calibrate", *(f"{{dir}}/{n}" for n in names), "--board", CALIB_BOARD.size)
    argv += ("--square-mm", f"{CALIB_BOARD.square_mm:g}", "--out", "{dir}/out/camera.json", "--json")
    return FuzzCase(
        files=files | {"out/.keep": b""}, argv=argv, blamed=name, note=f"calibration image: {label}"
    )


# --------------------------------------------------------------------------- stage manifest
_MANIFEST_ROWS = (
    "ref.png,0",
    "ref.png,-0",
    "stage2.png,-2",
    "stage2.png,nan",
    "stage2.png,inf",
    "stage2.png,1e308",
    "stage2.png,1e-308",
    "stage2.png,",
    ",2",
    "absent.png,2",
    "../ref.png,2",
    "/etc/passwd,2",
    "stage.csv,2",
    "camera.json,2",
    ".,2",
    "stage2.png,2,extra",
    '"stage2.png",2',
    "stage2.png;2",
    "ref.png,0\nref.png,0\nref.png,0",
    "stage2.png,2\nstage2.png,2",
)


@st.composite
def _manifest_text(draw) -> bytes:
    s = seeds()
    kind = draw(st.sampled_from(("text", "row", "rows only")))
    if kind == "text":
        return draw(mutated_text(s.manifest))
    rows = list(draw(st.lists(st.sampled_from(_MANIFEST_ROWS), min_size=1, max_size=4)))
    if kind == "row":
        lines = s.manifest.splitlines()
        lines.insert(draw(st.integers(1, len(lines))), rows[0])
        return ("\n".join(lines) + "\n").encode()
    return ("image,nominal_mm\n" + "\n".join(rows) + "\n").encode()


@st.composite
def _manifest_cases(draw) -> FuzzCase:
    s = seeds()
    files = {k: s.images[k] for k in ("ref.png", "ref2.png", "stage2.png", "stage5.png")}
    files |= {"camera.json": s.camera_json, "stage.csv": draw(_manifest_text())}
    return FuzzCase(files=files, argv=validate_argv(), blamed="stage.csv", note="stage manifest")


# ---------------------------------------------------------------------------------- options
BOARD_SIZES = (
    "0x0",
    "1x1",
    "1x6",
    "2x2",
    "3x3",
    "6x7",
    "8x6",
    "1000x1000",
    "99999999x2",
    "7x6x2",
    "abc",
    "-7x6",
    "7.5x6",
    "７x６",
    "",
    " ",
    "7X6",
    "7 x 6",
    "7×6",
    "x",
    "7x",
)
SQUARE_MM = ("-1", "0", "-0", "nan", "inf", "-inf", "1e308", "1e-308", "5e-324", "abc", "", "1e400", "0.001")
DICTIONARIES = (
    "DICT_NOPE",
    "DICT_4X4_50",
    "DICT_5X5_100",
    "DICT_ARUCO_ORIGINAL",
    "",
    "dict_5x5_100",
    "getPredefinedDictionary",
    "__class__",
    "DICT_APRILTAG_36h11",
    "Dictionary",
    "DICT_5X5_100 ",
)
MARKER_MM = ("20", "5", "7.5", "-1", "0", "nan", "inf", "1e308", "abc", "10", "11")
REFINE = ("photometric", "corners", "auto", "bogus", "", "PHOTOMETRIC")
POINTS = ("0,0,0", "1,2", "1,2,3,4", "nan,0,0", "inf,0,0", "1e308,1e308,1e308", "a,b,c", "", ",,")
OUTLIER = ("1", "0.5", "0", "-1", "nan", "inf", "1e308", "abc")


@st.composite
def _options_cases(draw) -> FuzzCase:
    s = seeds()
    command = draw(st.sampled_from(("pose", "calibrate", "displacement")))
    option = draw(
        st.sampled_from(("--board", "--square-mm", "--charuco", "--refine", "--point", "--outlier-factor"))
    )
    board, square = (
        (CALIB_BOARD if command == "calibrate" else MOBILE).size,
        "10" if command != "calibrate" else "20",
    )
    extra: tuple[str, ...] = ()
    blamed: str | None = option
    if option == "--board":
        board = draw(st.sampled_from(BOARD_SIZES))
        blamed = None  # a malformed size names --board; a wrong one is each image's warning
    elif option == "--square-mm":
        square = draw(st.sampled_from(SQUARE_MM))
    elif option == "--charuco":
        d = draw(st.sampled_from(DICTIONARIES))
        marker = draw(st.sampled_from(MARKER_MM))
        extra = ("--charuco", d, "--marker-mm", marker) if draw(st.booleans()) else ("--charuco", d)
        blamed = None  # the dictionary, or --marker-mm
    elif option == "--refine" and command != "calibrate":
        extra = ("--refine", draw(st.sampled_from(REFINE)))
    elif option == "--point" and command == "displacement":
        extra = ("--point", draw(st.sampled_from(POINTS)))
    elif option == "--outlier-factor" and command == "calibrate":
        extra = ("--outlier-factor", draw(st.sampled_from(OUTLIER)))
    else:
        blamed = None
    files = {"camera.json": s.camera_json}
    if command == "calibrate":
        files |= s.calib_views
        argv = ("calibrate", *(f"{{dir}}/{n}" for n in s.calib_views), "--out", "{dir}/camera_out.json")
    elif command == "pose":
        files |= {"ref.png": s.images["ref.png"], "moved.png": s.images["moved.png"]}
        argv = ("pose", "{dir}/ref.png", "{dir}/moved.png", "--camera", "{dir}/camera.json")
    else:
        files |= {"ref.png": s.images["ref.png"], "moved.png": s.images["moved.png"]}
        argv = (
            "displacement",
            "{dir}/moved.png",
            "--reference",
            "{dir}/ref.png",
            "--camera",
            "{dir}/camera.json",
        )
    argv += ("--board", board, "--square-mm", square, *extra, "--json")
    return FuzzCase(files=files, argv=argv, blamed=blamed, note=f"option {option} of {command}")


# ---------------------------------------------------------------------------------- classes
FUZZ_CLASSES: list[FuzzClass] = [
    FuzzClass("camera.json -> pose", _camera_cases("pose"), "camera.json: mutated text, one key's value"),
    FuzzClass("camera.json -> displacement", _camera_cases("displacement"), "camera.json with two targets"),
    FuzzClass("camera.json -> validate", _camera_cases("validate"), "camera.json of a stage validation"),
    FuzzClass("fixed2base -> displacement", _fixed2base_cases(), "the fixed target's pose on the base"),
    FuzzClass("image -> pose", _image_pose_cases(), "one image re-encoded, cut, or not an image"),
    FuzzClass("image -> displacement", _image_displacement_cases(), "a bad moved or reference image"),
    FuzzClass("image -> calibrate", _image_calibrate_cases(), "a bad view among good calibration views"),
    FuzzClass("stage manifest -> validate", _manifest_cases(), "stage.csv: mutated text, odd rows"),
    FuzzClass("options -> calibrate/pose/displacement", _options_cases(), "board sizes, dictionaries, mm"),
]
