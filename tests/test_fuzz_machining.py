"""Fuzz tests of ``stiffmap compensate`` (issue 31; helpers.fuzz_machining).

Each class of :data:`helpers.fuzz_machining.FUZZ_CLASSES` is one hypothesis test: the command
writes a corrected program that the independent solvers of ``helpers.machining_checks`` find on
the programmed path within the tolerance (deflected under the force) and covering all of it, or
it ends with one clear message naming the file (exit 1 or 2) and leaves no output and no
temporary file; the inputs are never changed. ``pytest -m fuzz tests/test_fuzz_machining.py``
runs the long profile; the default run takes 3 examples of each class (2 of the arm's: a run
and its independent re-check take about 3 s).

The check itself is tested first: a valid run passes it, and an output made wrong (not
compensated, or one point moved by 5 um) fails it.
"""

from __future__ import annotations

import re
import shutil
import tempfile
from pathlib import Path

import pytest
from helpers.fuzz import assert_handled, run_argv, run_case, write_case
from helpers.fuzz_machining import DATA, FORCES, FUZZ_CLASSES, PLACES, check_compensation, compensate_case
from hypothesis import given, settings

pytestmark = pytest.mark.fuzz

_BY_NAME = {c.name: c for c in FUZZ_CLASSES}

#: The current profile's number of examples, at most 3 in the default run (conftest: 12).
_EXAMPLES = settings(max_examples=settings().max_examples if settings().max_examples > 12 else 3)


def _check(case):
    o = run_case(case)
    assert_handled(case, o)
    return o


@_EXAMPLES
@given(case=_BY_NAME["G-code program x compensate"].cases)
def test_gcode_programs(case):
    _check(case)


@_EXAMPLES
@given(case=_BY_NAME["points CSV x compensate"].cases)
def test_points_files(case):
    _check(case)


@_EXAMPLES
@given(case=_BY_NAME["force CSV x compensate"].cases)
def test_force_files(case):
    _check(case)


@_EXAMPLES
@given(case=_BY_NAME["compensate options"].cases)
def test_options(case):
    _check(case)


@settings(max_examples=settings().max_examples if settings().max_examples > 12 else 2)
@given(case=_BY_NAME["compensate urdf arm6 options"].cases)
def test_arm_options(case):
    _check(case)


@_EXAMPLES
@given(case=_BY_NAME["compensate --from-campaign folder"].cases)
def test_from_campaign_folders(case):
    _check(case)


def _own_cam(robot: str = "3prr"):
    return compensate_case(
        {"p.nc": (DATA / "own_cam_mm.nc").read_bytes()},
        robot,
        "p.nc",
        "--place",
        PLACES[robot],
        "--force-n",
        FORCES[robot],
        blamed="p.nc",
    )


def _shift_one_coordinate(text: str, um: float) -> str:
    """The output with the Y word of line N65 (a cut along X) moved by ``um``."""
    lines = text.splitlines(keepends=True)
    i = next(k for k, ln in enumerate(lines) if ln.startswith("N65"))
    m = re.search(r"Y(-?\d+\.\d*)", lines[i])
    lines[i] = lines[i][: m.start(1)] + f"{float(m.group(1)) + um * 1e-3:.4f}" + lines[i][m.end(1) :]
    return "".join(lines)


@pytest.mark.parametrize("robot", ["3prr", "delta", "urdf arm6"])
def test_the_check_passes_a_good_output_and_fails_a_wrong_one(robot):
    """The oracle is not blind: the run's own output passes; the program as programmed (not
    compensated: the 3PRR deflects by 0.5 mm, the Delta by 0.3 mm, the arm by 0.6 mm) and the output
    with one point
    moved by 5 um (five times the 1 um tolerance) fail it; an input changed is found."""
    case = _own_cam(robot)
    d = Path(tempfile.mkdtemp(prefix="stiffmap-fuzz-"))
    try:
        o = run_argv(write_case(case, d))
        assert o.code == 0, o.stderr
        assert check_compensation(case, d, o) == ""
        good = (d / "o.nc").read_text()
        (d / "o.nc").write_bytes(case.files["p.nc"])
        assert "um off the path" in check_compensation(case, d, o)
        (d / "o.nc").write_text(_shift_one_coordinate(good, 5.0))
        assert "um off the path" in check_compensation(case, d, o)
        (d / "o.nc").write_text(good)
        (d / "p.nc").write_text(good)
        assert check_compensation(case, d, o) == "the input p.nc changed"
    finally:
        shutil.rmtree(d, ignore_errors=True)


def test_every_class_is_tested():
    assert set(_BY_NAME) == {
        "G-code program x compensate",
        "points CSV x compensate",
        "force CSV x compensate",
        "compensate options",
        "compensate urdf arm6 options",
        "compensate --from-campaign folder",
    }


# ------------------------------------------------------------------------ findings
@pytest.mark.parametrize("command", ["compensate", "model"])
def test_an_empty_tip_offset_is_refused_naming_the_option(tmp_path, command):
    """Found by the fuzzing (``--tip-offset-mm ''`` among the arm's wrong values): an empty offset
    was taken for none given, the tool point moved to the flange (0, 0, 0) instead of arm6's
    (0, 0, 100) mm: exit 0, a program compensated for another tool (worst deflection 454 um
    instead of 618 um), or a model at another point. Now one line naming the option."""
    arm6 = "urdf arm6"
    if command == "compensate":
        shutil.copy(DATA / "own_cam_mm.nc", tmp_path / "p.nc")
        argv = ["compensate", *arm6.split(), "--path", str(tmp_path / "p.nc")]
        argv += ["--out", str(tmp_path / "o.nc"), "--place", PLACES[arm6], "--force-n", FORCES[arm6]]
        argv += ["--json", "-q", "--no-figures"]
    else:
        (tmp_path / "q.csv").write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,40,-10,0,60,0\n")
        argv = ["model", *arm6.split(), "--tip", "tool0", "--configs", str(tmp_path / "q.csv"), "--json"]
    o = run_argv([*argv, "--tip-offset-mm", ""])
    lines = [ln for ln in o.stderr.splitlines() if ln.strip()]
    assert o.code == 2 and len(lines) == 1, (o.code, o.stderr)
    assert "--tip-offset-mm" in lines[0] and "got ''" in lines[0], lines[0]
    assert not (tmp_path / "o.nc").exists()
