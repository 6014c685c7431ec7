"""Fuzz tests of rigs, one camera's images, capture options, results databases and Dask
addresses (helpers.fuzz_safety).

Each class of :data:`helpers.fuzz_safety.FUZZ_CLASSES` is one hypothesis test: the command
succeeds (its JSON then holds only finite numbers or nulls: NaN is never printed as a value) or
ends with one clear message (exit 1 or 2); a case wrong in a way that gives plausible results
(a rig file of another rig, a camera that measured nothing) is warned or refused by name.
``pytest -m fuzz tests/test_fuzz_safety.py`` runs the long profile; the default run takes 3
examples of each class (2 of the classes of [robot] and capture, 1 of one camera's images).
"""

from __future__ import annotations

import json

import pytest
from helpers.fuzz import assert_handled, run_case
from helpers.fuzz_campaign import names_a_campaign_file
from helpers.fuzz_safety import FUZZ_CLASSES, names_the_dask_option
from hypothesis import given, settings

from stiffmap.capture import session

pytestmark = pytest.mark.fuzz

_BY_NAME = {c.name: c for c in FUZZ_CLASSES}

#: The current profile's number of examples, at most 3 in the default run (conftest: 12).
_EXAMPLES = settings(max_examples=settings().max_examples if settings().max_examples > 12 else 3)
#: The classes added in phase B of issue 27 (a run or a capture of 2-3 s each): 2 in the default run.
_FEW = settings(max_examples=settings().max_examples if settings().max_examples > 12 else 2)
#: One run of the rig campaign (2-3 s) in the default run.
_ONE = settings(max_examples=settings().max_examples if settings().max_examples > 12 else 1)


def _finite_json(text: str) -> None:
    def refuse(name):
        raise AssertionError(f"non-finite number {name} in the JSON output")

    json.loads(text, parse_constant=refuse)


def _check(case):
    o = run_case(case)
    assert_handled(case, o)
    if "--json" in case.argv and o.code in (0, 1) and o.stdout.strip():
        _finite_json(o.stdout)
    assert "nan" not in o.stdout.lower().replace("nanny", ""), o.stdout[-500:]
    return o


@_EXAMPLES
@given(case=_BY_NAME["rig.json x pose --rig, run"].cases)
def test_rig_files(case):
    o = _check(case)
    assert names_a_campaign_file(case, o.stderr, o.code) or case.argv[0] == "pose", o.stderr[-1500:]


@_ONE
@given(case=_BY_NAME["one camera's images x run (rig)"].cases)
def test_one_cameras_images(case):
    o = _check(case)
    assert names_a_campaign_file(case, o.stderr, o.code), o.stderr[-1500:]


@_FEW
@given(case=_BY_NAME["[robot] and its file x run"].cases)
def test_robot_sections(case):
    o = _check(case)
    assert names_a_campaign_file(case, o.stderr, o.code), o.stderr[-1500:]


@_FEW
@given(case=_BY_NAME["capture options x capture"].cases)
def test_capture_options(case):
    floor = session.MIN_WALL_S
    session.MIN_WALL_S = 1.0  # a camera whose clock barely moves waits timeout_s = 1 s, not 10 s
    try:
        o = _check(case)
    finally:
        session.MIN_WALL_S = floor
    assert o.code in (0, 1, 2), o.stderr[-1500:]


@_EXAMPLES
@given(case=_BY_NAME["stiffmap.db values x report, run"].cases)
def test_results_databases(case):
    o = _check(case)
    assert names_a_campaign_file(case, o.stderr, o.code), o.stderr[-1500:]


@_FEW
@given(case=_BY_NAME["[robot] changed after the run x report, compensate"].cases)
def test_robots_changed_after_the_run(case):
    o = _check(case)
    if case.expect is not None:  # the fit is another robot's: said, and left out or refused
        assert o.code in (1, 2), o.stderr[-1500:]


@_EXAMPLES
@given(case=_BY_NAME["--dask addresses x run"].cases)
def test_dask_addresses(case):
    o = _check(case)
    assert names_the_dask_option(case, o.stderr, o.code), f"exit {o.code}: {o.stderr[-1500:]}"


def test_every_class_is_tested():
    assert set(_BY_NAME) == {
        "rig.json x pose --rig, run",
        "one camera's images x run (rig)",
        "[robot] and its file x run",
        "capture options x capture",
        "stiffmap.db values x report, run",
        "[robot] changed after the run x report, compensate",
        "--dask addresses x run",
    }
