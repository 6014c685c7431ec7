"""Fuzz tests of campaign directories (helpers.fuzz_campaign): never a traceback, a hang or silence.

Each class of :data:`helpers.fuzz_campaign.FUZZ_CLASSES` is one hypothesis test: the
command either succeeds (and then its JSON summary holds only finite numbers or
nulls) or ends with one clear message (exit 1 or 2) that names what it is about.
``pytest -m fuzz tests/test_fuzz_campaign.py`` runs the long profile.

A case runs a whole campaign (tens of images, a database, sometimes a report): the default
run takes 4 examples of each class instead of the profile's 12, to stay within 20 s; the
long profile takes its own number.
"""

from __future__ import annotations

import json

import pytest
from helpers.fuzz import assert_handled, run_case
from helpers.fuzz_campaign import FUZZ_CLASSES, names_a_campaign_file
from hypothesis import given, settings

pytestmark = pytest.mark.fuzz

_BY_NAME = {c.name: c for c in FUZZ_CLASSES}

#: The current profile's number of examples, at most 4 in the default run (conftest: 12).
_EXAMPLES = settings(max_examples=settings().max_examples if settings().max_examples > 12 else 4)


def _finite_json(text: str) -> None:
    """``text`` is one JSON object whose numbers are all finite (NaN and Infinity refused)."""

    def refuse(name):
        raise AssertionError(f"non-finite number {name} in the JSON output")

    json.loads(text, parse_constant=refuse)


def _check(case) -> None:
    o = run_case(case)
    assert_handled(case, o)
    assert names_a_campaign_file(case, o.stderr, o.code), (
        f"a message does not say what it is about (exit {o.code}; {case.note}):\n{o.stderr[-1500:]}"
    )
    if "--json" in case.argv and o.code in (0, 1) and o.stdout.strip():
        _finite_json(o.stdout)
    assert "Traceback" not in o.stdout


@_EXAMPLES
@given(case=_BY_NAME["campaign.toml (vision) x run"].cases)
def test_vision_campaign_toml(case):
    _check(case)


@_EXAMPLES
@given(case=_BY_NAME["campaign.toml (sensor) x run"].cases)
def test_sensor_campaign_toml(case):
    _check(case)


@_EXAMPLES
@given(case=_BY_NAME["[images] patterns, camera.file, image files x run"].cases)
def test_image_file_names(case):
    _check(case)


@_EXAMPLES
@given(case=_BY_NAME["[sensor] recordings list x run"].cases)
def test_recording_file_names(case):
    _check(case)


@_EXAMPLES
@given(case=_BY_NAME["truth.json, truth_corners.json.gz x report, run"].cases)
def test_truth_files(case):
    _check(case)


@_EXAMPLES
@given(case=_BY_NAME["campaign directory, stiffmap.db x run, report, init"].cases)
def test_campaign_directory(case):
    _check(case)


def test_every_class_is_tested():
    tested = {
        "campaign.toml (vision) x run",
        "campaign.toml (sensor) x run",
        "[images] patterns, camera.file, image files x run",
        "[sensor] recordings list x run",
        "truth.json, truth_corners.json.gz x report, run",
        "campaign directory, stiffmap.db x run, report, init",
    }
    assert set(_BY_NAME) == tested
