"""Malformed inputs of the vision commands: one clear message naming the file, or a right answer.

The fuzz tests (marker ``fuzz``) throw every class of ``helpers.fuzz_vision`` at the
commands in-process: camera.json, the fixed2base transform, images, stage manifests and
the options that name boards and dictionaries. Where a command succeeds, its ``--json``
output is checked: finite numbers (or null where unknown), rigid poses, and, where the
input is the same picture as a valid image (re-encoded as TIFF, JPEG, 16 bit, colour...),
the true pose or displacement.

The regression tests below run the real command (in this process,
``helpers.cli_process.run_here``) on each defect the fuzzing found, and check its one line.
"""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest
from helpers.board_images import quick_board_image
from helpers.board_scenes import look_at_pose
from helpers.cli_process import assert_one_line_error, run_here
from helpers.fuzz import FuzzCase, assert_handled, run_case
from helpers.fuzz_vision import CALIB_BOARD, CAMERA, FUZZ_CLASSES, MOBILE, SAME_PICTURE, seeds
from hypothesis import given

from stiffmap.camera import CameraModel, save_camera
from stiffmap.geometry import displacement_from_poses

_BY_NAME = {fc.name: fc for fc in FUZZ_CLASSES}


# ------------------------------------------------------------------------------ fuzz tests
def _finite_or_null(x) -> bool:
    if x is None:
        return True
    if isinstance(x, list):
        return all(_finite_or_null(v) for v in x)
    return isinstance(x, (int, float)) and math.isfinite(x)


def _rigid(T) -> bool:
    T = np.asarray(T, dtype=float)
    R = T[:3, :3]
    return (
        T.shape == (4, 4)
        and np.all(np.isfinite(T))
        and np.allclose(R.T @ R, np.eye(3), atol=1e-9)
        and np.allclose(T[3], [0, 0, 0, 1])
    )


def _label(case: FuzzCase) -> str:
    return case.note.removeprefix("image: ")


def _check_pose(case: FuzzCase, rows) -> None:
    s = seeds()
    assert isinstance(rows, list) and len(rows) == 2
    for row in rows:
        if "error" in row:
            continue
        assert _rigid(row["board2cam"]) and _finite_or_null(row["cov"]), row
        assert _finite_or_null(row["rms_px"]) and row["n_corners"] >= 4
        if case.note.startswith("image: ") and _label(case) in SAME_PICTURE and "ref" not in row["image"]:
            # The same picture re-encoded: the moved board's true pose (depth error ~0.02 mm).
            t = np.asarray(row["board2cam"])[:3, 3] - s.mobile2cam["moved.png"][:3, 3]
            assert np.all(np.abs(t) < [0.05, 0.05, 0.15]), (case.note, t)


def _check_displacement(case: FuzzCase, rows) -> None:
    s = seeds()
    assert isinstance(rows, list) and rows
    for row in rows:
        if "error" in row:
            continue
        for k in ("d", "r", "d_std", "r_std"):
            assert _finite_or_null(row[k]) and len(row[k]) == 3, row
    moved = displacement_from_poses(s.mobile2cam["ref.png"], s.mobile2cam["moved.png"])
    for row in rows:
        ok = "error" not in row and row.get("image") is not None
        if ok and row["image"].endswith("moved.png") and case.note.startswith("image: "):
            # The valid moved image against the valid reference (the bad image only added).
            if "--reference" not in case.argv[-2:]:
                assert abs(np.linalg.norm(row["d"]) - np.linalg.norm(moved[:3])) < 0.1, (case.note, row)


def _check_validate(case: FuzzCase, obj) -> None:
    assert isinstance(obj, dict) and obj["steps"]
    for step in obj["steps"]:
        assert step["n"] >= 1 and step["nominal_mm"] > 0
        for k in ("mean_mm", "std_mm", "error_mm", "along_mean_mm", "along_std_mm"):
            assert _finite_or_null(step[k]), step
    assert _finite_or_null(obj["axis"]) and _finite_or_null(obj["rms_error_mm"])


def _check_calibrate(case: FuzzCase, obj) -> None:
    # What calibrate writes, the other commands read: it passes camera.json's checks.
    cam = CameraModel.from_dict(obj)
    assert cam.image_size == CAMERA.image_size
    assert abs(cam.fx / CAMERA.fx - 1) < 0.1 and abs(cam.cx - CAMERA.cx) < 20, obj


_CHECKS = {
    "pose": _check_pose,
    "displacement": _check_displacement,
    "validate": _check_validate,
    "calibrate": _check_calibrate,
}


def check_output(case: FuzzCase, outcome) -> None:
    """A command that succeeded (or partly) printed sane ``--json`` output."""
    if outcome.code not in (0, 1) or "--json" not in case.argv or not outcome.stdout.strip():
        return
    _CHECKS[case.argv[0]](case, json.loads(outcome.stdout))


def _fuzz(name: str):
    fc = _BY_NAME[name]

    @given(fc.cases)
    def run(case: FuzzCase) -> None:
        o = run_case(case)
        assert_handled(case, o)
        check_output(case, o)

    run()


@pytest.mark.fuzz
@pytest.mark.parametrize("name", list(_BY_NAME))
def test_vision_inputs_end_in_a_clear_message_or_a_sane_result(name):
    _fuzz(name)


def test_the_valid_seeds_are_measured():
    """The seeds of every class are valid: each command succeeds on them with the true values."""
    s = seeds()
    files = {"camera.json": s.camera_json, "fixed2base.json": s.fixed2base_json, **s.images}
    from helpers.fuzz_vision import displacement_argv, validate_argv

    o = run_case(FuzzCase(files, displacement_argv()))
    assert o.kind == "ok", o.stderr
    rows = json.loads(o.stdout)
    G = s.fixed2base @ np.linalg.inv(s.fixed2cam)
    truth = displacement_from_poses(G @ s.mobile2cam["ref.png"], G @ s.mobile2cam["moved.png"])
    assert rows[0]["frame"] == "base"
    assert np.linalg.norm(np.array(rows[0]["d"]) - truth[:3]) < 0.05  # mm
    o = run_case(FuzzCase(files | {"stage.csv": s.manifest.encode()}, validate_argv()))
    assert o.kind == "ok", o.stderr
    steps = json.loads(o.stdout)["steps"]
    assert [st["nominal_mm"] for st in steps] == [2.0, 5.0]
    assert all(abs(st["error_mm"]) < 0.05 for st in steps), steps  # mm
    argv = ("calibrate", *(f"{{dir}}/{n}" for n in s.calib_views), "--board", CALIB_BOARD.size)
    o = run_case(
        FuzzCase(dict(s.calib_views), (*argv, "--square-mm", "20", "--out", "{dir}/c.json", "--json"))
    )
    assert o.kind == "ok", o.stderr
    _check_calibrate(FuzzCase({}, ("calibrate",)), json.loads(o.stdout))


# ------------------------------------------------------------------------ regression tests
@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """The seeds written to a directory, as a user would have them."""
    d = tmp_path_factory.mktemp("fuzz_vision")
    s = seeds()
    for name, data in {**s.images, **s.calib_views}.items():
        (d / name).write_bytes(data)
    (d / "camera.json").write_bytes(s.camera_json)
    (d / "fixed2base.json").write_bytes(s.fixed2base_json)
    (d / "stage.csv").write_text(s.manifest)
    return d


def _camera_with(d, **changes):
    obj = json.loads(seeds().camera_json)
    obj.update(changes)
    (d / "cam.json").write_text(json.dumps(obj))
    return d / "cam.json"


def _pose(d, camera, *images, extra=()):
    images = images or ("ref.png", "moved.png")
    return run_here(
        "pose", *(d / i for i in images), "--camera", camera, "--board", "7x6", "--square-mm", "10", *extra
    )


@pytest.mark.parametrize(
    ("change", "key", "what"),
    [
        ({"fx": 1e-308}, "'fx'", "not a plausible focal length"),
        ({"fy": 5e6}, "'fy'", "0.1 to 100 times the image diagonal"),
        ({"cx": 1e6}, "'cx'", "is outside the 320x240 px image"),
        # The camera.json of issue 26 (Bouguet's 13x12 board calibrated as 9x6): fx 4410, fy 1433,
        # cx 760 on a 640-px-wide image, RMS 10.9 px; each rule alone refuses it.
        ({"fx": 4410.0, "fy": 1433.0}, "'fy'", "is not a camera's pixel aspect"),
        ({"cx": 330.0}, "'cx'", "principal point 330 px is outside the 320x240 px image"),
        ({"rms_px": 10.9}, "'rms_px'", "reprojection RMS 10.9 px is far above"),
        ({"dist": [1e10, 0.0, 0.0, 0.0, 0.0]}, "'dist[0]'", "k1 = 1e+10 is not a plausible"),
        ({"dist": [0.0, 0.0, 5.0, 0.0, 0.0]}, "'dist[2]'", "p1 = 5"),
        ({"dist": [0.0] * 5 + [-1000.0, 0.0, 0.0], "std": None}, "'dist'", "folds over (or has a pole)"),
        ({"image_size": [10**9, 240]}, "'image_size'", "not a camera image"),
        ({"std": {"fx": -1.0}}, "'std.fx'", "standard deviation"),
        ({"rms_px": float("nan")}, "'rms_px'", "finite number"),
        ({"views": [1]}, "'views[0]'", "must be an object"),
    ],
)
def test_an_implausible_camera_json_names_its_key(lab, change, key, what):
    """camera.json: the physical checks at the boundary, one line naming the file and the key."""
    r = _pose(lab, _camera_with(lab, **change))
    assert r.returncode == 2
    assert_one_line_error(r, "cam.json", f"key {key}:", what)


def test_a_camera_json_with_a_huge_integer_or_deep_nesting_is_one_line(lab):
    (lab / "cam.json").write_text(seeds().camera_json.decode().replace("450.0", "9" * 400, 1))
    assert_one_line_error(_pose(lab, lab / "cam.json"), "cam.json", "key 'fx': must be a finite number")
    (lab / "cam.json").write_text("[" * 50_000 + "]" * 50_000)
    assert_one_line_error(_pose(lab, lab / "cam.json"), "cam.json", "nested too deeply")


@pytest.fixture(scope="module")
def strong_lens(tmp_path_factory):
    """A real but strong lens (k1 -0.30, k2 0.15, k3 -0.075) on a 640x480 camera, and its images.

    Its distortion polynomial folds over about 430 px from the principal point, inside the
    margin of the photometric refinement's ray map (64 px beyond the image corners, 464 px).
    """
    d = tmp_path_factory.mktemp("strong_lens")
    cam = CameraModel((640, 480), 530.0, 530.0, 320.0, 240.0, (-0.30, 0.15, 0.0, 0.0, -0.075))
    save_camera(cam, d / "camera.json")
    rng = np.random.default_rng(17)
    for k, off in enumerate([(0, 0), (40, 25)]):
        T = look_at_pose(300, MOBILE, tilt_deg=(5, -8, 2), offset_mm=off)
        cv2.imwrite(str(d / f"view{k}.png"), quick_board_image(cam, [(MOBILE, T)], rng=rng))
    cv2.imwrite(str(d / "blank.png"), np.full((480, 640), 90, np.uint8))
    (d / "cut.png").write_bytes((d / "view1.png").read_bytes()[:5000])
    return d, cam


def test_a_strong_lens_keeps_to_its_invertible_field_and_no_image_costs_the_others(strong_lens):
    """The lens model folds over inside the image's margin: the photometric refinement uses
    only the pixels inside the field where it is invertible (or keeps the corner pose and
    says why); the images that cannot be measured are named, the others measured (exit 1)."""
    d, cam = strong_lens
    with pytest.raises(ValueError, match="cannot be inverted"):
        cam.rays_from_pixels([[-64.0, -64.0]])
    r = _pose(d, d / "camera.json", "view0.png", "blank.png", "cut.png", "view1.png", extra=("--json",))
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    rows = json.loads(r.stdout)
    assert [("error" in row) for row in rows] == [False, True, True, False]
    for row in (rows[0], rows[3]):
        assert row["method"] == "photometric" or "invertible field" in row["fallback"], row
        assert _rigid(row["board2cam"]) and 290 < row["board2cam"][2][3] < 310
    lines = r.stderr.strip().splitlines()
    assert all(ln.startswith("warning: ") for ln in lines), lines
    for name, what in [("blank", "no 7x6"), ("cut", "truncated PNG")]:
        assert sum(f"{name}.png" in ln and what in ln for ln in lines) == 1, (name, lines)


def test_a_bad_fixed2base_names_the_file_and_the_cell(lab):
    s = seeds()
    base = [
        "displacement",
        lab / "moved.png",
        "--reference",
        lab / "ref.png",
        "--camera",
        lab / "camera.json",
        "--board",
        "7x6",
        "--square-mm",
        "10",
        "--fixed-board",
        "9x4",
        "--fixed-square-mm",
        "10",
        "--fixed2base",
        lab / "f2b.json",
    ]
    M = s.fixed2base.tolist()
    M[1][2] = int("9" * 400)
    (lab / "f2b.json").write_text(json.dumps({"fixed2base": M}))
    assert_one_line_error(run_here(*base), "f2b.json", "row 2, column 3: expected a finite number")
    M = s.fixed2base.copy()
    M[:3, 3] = [1e300, 0.0, 0.0]
    (lab / "f2b.json").write_text(json.dumps(M.tolist()))
    assert_one_line_error(run_here(*base), "f2b.json", "translation of 1e+300 mm")
    M = s.fixed2base.copy()
    M[0, 0] = 1e308  # was an internal error (R^T R overflowed)
    (lab / "f2b.json").write_text(json.dumps({"fixed2base": M.tolist()}))
    r = run_here(*base)
    assert_one_line_error(r, "f2b.json", "key 'fixed2base': not a rigid transform", "1e+308")


def test_a_bad_image_is_one_named_warning_without_decoder_noise(lab):
    """A PNG whose bytes were changed: one warning naming it (no libpng line on the terminal)."""
    data = bytearray(seeds().images["moved.png"])
    data[20000:20010] = b"0123456789"
    (lab / "corrupt.png").write_bytes(bytes(data))
    r = _pose(lab, lab / "camera.json", "ref.png", "corrupt.png")
    assert r.returncode == 1
    assert_one_line_error(r, "warning:", "corrupt.png", "fails its CRC check")
    # A 2x2 image among calibration views is one view left out, not an internal error.
    cv2.imwrite(str(lab / "tiny.png"), np.zeros((2, 2), np.uint8))
    views = [lab / f"view{k}.png" for k in range(1, 6)]
    r = run_here(
        "calibrate", *views, lab / "tiny.png", "--board", "7x6", "--square-mm", "20", "--out", lab / "c.json"
    )
    # A view left out of a good calibration is a note (status 0), not a warning.
    assert r.returncode == 0 and "Traceback" not in r.stderr and "warning:" not in r.stderr, r.stderr
    assert [ln for ln in r.stderr.splitlines() if ln.startswith("note")] == [
        f"note: not used: {lab / 'tiny.png'}: image is 2x2 px; a board image needs at least 8x8 px"
    ]


@pytest.mark.parametrize(
    ("options", "needles"),
    [
        (("--charuco", "DICT_NOPE", "--marker-mm", "7"), ("--charuco DICT_NOPE", "unknown ArUco dictionary")),
        (("--charuco", "DICT_4X4_50", "--marker-mm", "7", "--board", "19x19"), ("holds 200 markers",)),
        (("--board", "0x0"), ("--board", "at least 3x3 inner corners")),
        (("--board", "2x2"), ("--board", "at least 3x3 inner corners")),
        (("--board", "1000x1000"), ("--board", "not a printed board")),
        (("--square-mm", "-1"), ("--square-mm", "must be a positive number of mm")),
        (("--square-mm", "1e308"), ("--square-mm", "not a printed square's side")),
        (("--square-mm", "abc"), ("Invalid value for '--square-mm'", "stiffmap pose --help")),
    ],
)
def test_option_values_are_one_line_naming_the_option(lab, options, needles):
    args = ["--board", "7x6", "--square-mm", "10"]
    for k in range(0, len(options), 2):
        if options[k] in args:
            args[args.index(options[k]) + 1] = options[k + 1]
        else:
            args += options[k : k + 2]
    r = run_here("pose", lab / "ref.png", "--camera", lab / "camera.json", *args)
    assert r.returncode == 2
    assert_one_line_error(r, *needles)


def test_displacement_point_of_1e308_mm_is_refused(lab):
    r = run_here(
        "displacement", lab / "moved.png", "--reference", lab / "ref.png", "--camera", lab / "camera.json",
        "--board", "7x6", "--square-mm", "10", "--point", "1e308,0,0",
    )  # fmt: skip
    assert_one_line_error(r, "--point", "within 1e+06 mm")


@pytest.mark.parametrize(
    ("row", "needles"),
    [
        (
            "../ref.png,2",
            ("line 4, column 'image'", "outside the manifest's folder", "--allow-outside-paths"),
        ),
        ("/etc/hostname,2", ("line 4, column 'image'", "outside the manifest's folder")),
        ("stage2.png,1e308", ("line 4, column 'nominal_mm'", "not a stage displacement")),
        # The manifest's own folder (a name such as "."): calibrate and pose read folders as
        # their images, a manifest row must be one image (found by the fuzzer: internal error).
        (".,2", ("line 4, column 'image'", "is a folder, expected an image file")),
    ],
)
def test_a_stage_manifest_row_is_named(lab, row, needles):
    lines = seeds().manifest.splitlines()
    lines.insert(3, row)
    (lab / "stage_bad.csv").write_text("\n".join(lines) + "\n")
    r = run_here(
        "validate",
        lab / "stage_bad.csv",
        "--camera",
        lab / "camera.json",
        "--board",
        "7x6",
        "--square-mm",
        "10",
    )
    assert r.returncode == 2
    assert_one_line_error(r, "stage_bad.csv", *needles)


def test_an_image_the_manifest_lists_but_that_is_missing_names_the_manifest_line(lab):
    lines = seeds().manifest.splitlines()
    lines.insert(3, "absent.png,2")
    (lab / "stage_absent.csv").write_text("\n".join(lines) + "\n")
    measure = ["--camera", lab / "camera.json", "--board", "7x6", "--square-mm", "10"]
    r = run_here("validate", lab / "stage_absent.csv", *measure, "--json")
    assert r.returncode == 1  # the others measured
    assert_one_line_error(r, "stage_absent.csv, line 4:", "absent.png: no such file or folder")
    assert [s["n"] for s in json.loads(r.stdout)["steps"]] == [1, 1]
