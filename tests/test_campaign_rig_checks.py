"""A rig campaign says what ``pose --rig`` says of one image set, for them all (issue 27).

The seed is the fuzz layer's small rig campaign (:func:`helpers.fuzz_safety.rig_seed`: two
cameras 30 degrees apart, one position of the Delta, four load cases). Before issue 27 each of
these ran with exit 0 and ``failures: []``: a ``rig.json`` with its cameras' names swapped gave
k_theta 1.33e-06 N mm/rad, a camera moved by 50 mm changed it by up to 68 %, and a camera whose
images were all missing, truncated, of another size or folders was buried in
``measurements.per_camera``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from helpers.fuzz import run_argv
from helpers.fuzz_safety import rig_seed

from stiffmap.campaign.rig_checks import rig_failures


def _campaign(tmp_path: Path) -> Path:
    for name, data in rig_seed().items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(data)
    return tmp_path


def _edit_rig(root: Path, edit) -> None:
    d = json.loads((root / "rig.json").read_text())
    edit(d)
    (root / "rig.json").write_text(json.dumps(d))


def _run(root: Path):
    o = run_argv(["run", str(root), "--quiet", "--no-report"])
    summary = root / "exports" / "summary.json"
    return o, json.loads(summary.read_text()) if summary.is_file() else {}


def _swap(d):
    c = d["cameras"]
    c[0]["name"], c[1]["name"] = c[1]["name"], c[0]["name"]


def _move_50mm(d):
    d["cameras"][1]["cam2rig"][0][3] += 50.0


@pytest.mark.parametrize(
    "edit",
    [_swap, pytest.param(_move_50mm, marks=pytest.mark.slow)],
    ids=["names swapped", "cam2 moved 50 mm"],
)
def test_a_wrong_rig_file_is_a_failure_naming_the_cameras_disagreement(tmp_path, edit):
    root = _campaign(tmp_path)
    _edit_rig(root, edit)
    o, summary = _run(root)
    assert o.code == 1, o.stderr[-1500:]
    (line,) = [f for f in summary["failures"] if "disagree" in f]
    assert line.startswith("rig.json: the cameras disagree") and "5 of the 5 image sets" in line
    # Each camera's distance from the fused pose, in mm and degrees: a 50 mm move or a swap
    # is tens of mm away (the consistency test's 1-sigma is microns).
    mm = [float(v) for v in re.findall(r"cam\d ([\d.e+]+) mm / [\d.e+]+ deg", line)]
    assert len(mm) == 2 and max(mm) > 10.0, line
    assert any(ln.startswith("warning: rig.json: the cameras disagree") for ln in o.stderr.splitlines())


def _missing(p: Path) -> None:
    p.unlink()


def _truncated(p: Path) -> None:
    p.write_bytes(p.read_bytes()[:300])


def _wrong_size(p: Path) -> None:
    # The other camera's image halved in each direction: a valid PNG of another size.
    import cv2

    img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
    cv2.imwrite(str(p), img[::2, ::2])


def _folder(p: Path) -> None:
    p.unlink()
    p.mkdir()


@pytest.mark.parametrize(
    ("damage", "reason"),
    [
        (_missing, "no such file"),
        pytest.param(_truncated, "truncated", marks=pytest.mark.slow),
        pytest.param(_wrong_size, "rig.json (camera 'cam2') was calibrated at", marks=pytest.mark.slow),
        pytest.param(_folder, "is a directory", marks=pytest.mark.slow),
    ],
    ids=["missing", "truncated", "wrong size", "folders"],
)
def test_a_camera_that_measured_nothing_is_a_failure_with_its_reason(tmp_path, damage, reason):
    root = _campaign(tmp_path)
    for p in sorted((root / "images").rglob("*_cam2.png")):
        damage(p)
    # With a covariance in rig.json and four load cases for four unknowns, K has no uncertainty:
    # the calibration line says so (before: "camera.json gives no covariance or std").
    _edit_rig(root, _add_cov)
    o, summary = _run(root)
    assert o.code == 1, o.stderr[-1500:]
    (line,) = summary["failures"]
    assert line.startswith("camera cam2 measured nothing in the 5 image set(s)") and reason in line, line
    assert f"warning: {line[:60]}" in o.stderr
    # The other camera measured every set: the stiffness is there, from cam1 alone.
    assert summary["positions"][0]["status"] == "ok"
    text = " ".join(o.stdout.split())
    assert "camera.json" not in text
    assert "rig.json gives it, but no position has an uncertainty of K" in text


def _add_cov(d):
    names = [f"{c['name']}.{p}" for c in d["cameras"] for p in ("fx", "fy", "cx", "cy")]
    d["cov"] = {"params": names, "matrix": (0.01 * np.eye(len(names))).tolist()}


def _row(*cams, status="ok"):
    return status, json.dumps(list(cams))


def _cam(name, ok=True, error=None, offset=(0.001, 0.01), disagree=False):
    return {
        "name": name,
        "ok": ok,
        "error": error,
        "offset_mm": offset[0],
        "offset_deg": offset[1],
        "disagree": disagree,
    }


def test_a_camera_missing_from_some_sets_is_a_note_and_agreement_is_silent():
    rows = [
        _row(_cam("a"), _cam("b")),
        _row(_cam("a"), _cam("b", ok=False, error="b.png: image file not found")),
        _row(_cam("a", ok=False, error="x"), _cam("b", ok=False, error="y"), status="failed"),
    ]
    failures, notes = rig_failures(rows, ("a", "b"), "rig.json")
    assert failures == []
    (note,) = notes
    assert note.startswith("camera b did not measure 1 of the 2 image sets (first: b.png: image file not")
    # Rows of an older revision (no offsets), a single camera, no rows: nothing to say.
    old = ("ok", [{"name": "a", "ok": True}, {"name": "b", "ok": True}])
    assert rig_failures([old], ("a", "b"), "r") == ([], [])
    assert rig_failures([("ok", "not json"), ("ok", None)], ("a", "b"), "r") == ([], [])
    assert rig_failures(rows, ("a",), "rig.json") == ([], [])
    assert rig_failures([], ("a", "b"), "rig.json") == ([], [])
