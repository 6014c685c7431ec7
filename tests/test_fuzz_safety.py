"""Fuzz tests of rigs, results databases and Dask addresses (helpers.fuzz_safety).

Each class of :data:`helpers.fuzz_safety.FUZZ_CLASSES` is one hypothesis test: the command
succeeds (its JSON then holds only finite numbers or nulls: NaN is never printed as a value) or
ends with one clear message (exit 1 or 2). ``pytest -m fuzz tests/test_fuzz_safety.py`` runs
the long profile; the default run takes 3 examples of each class.
"""

from __future__ import annotations

import json

import pytest
from helpers.fuzz import assert_handled, run_case
from helpers.fuzz_campaign import names_a_campaign_file
from helpers.fuzz_safety import FUZZ_CLASSES, names_the_dask_option
from hypothesis import given, settings

pytestmark = pytest.mark.fuzz

_BY_NAME = {c.name: c for c in FUZZ_CLASSES}

#: The current profile's number of examples, at most 3 in the default run (conftest: 12).
_EXAMPLES = settings(max_examples=settings().max_examples if settings().max_examples > 12 else 3)


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


@_EXAMPLES
@given(case=_BY_NAME["stiffmap.db values x report, run"].cases)
def test_results_databases(case):
    o = _check(case)
    assert names_a_campaign_file(case, o.stderr, o.code), o.stderr[-1500:]


@_EXAMPLES
@given(case=_BY_NAME["--dask addresses x run"].cases)
def test_dask_addresses(case):
    o = _check(case)
    assert names_the_dask_option(case, o.stderr, o.code), f"exit {o.code}: {o.stderr[-1500:]}"


def test_every_class_is_tested():
    assert set(_BY_NAME) == {
        "rig.json x pose --rig, run",
        "stiffmap.db values x report, run",
        "--dask addresses x run",
    }
