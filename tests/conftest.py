"""Shared test fixtures. The test helpers live in the ``helpers`` package beside this file."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

# pytest's default import mode puts tests/ on sys.path, which makes ``import helpers`` work;
# this keeps it so under ``--import-mode=importlib`` too.
_TESTS = str(Path(__file__).resolve().parent)
if _TESTS not in sys.path:
    sys.path.insert(0, _TESTS)


# Fuzz tests (marker ``fuzz``): a few deterministic examples in the default run, so that
# ``make test`` stays fast and reproducible; thousands of random ones with ``pytest -m fuzz``.
_FUZZ_COMMON = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
settings.register_profile("default-run", max_examples=12, derandomize=True, database=None, **_FUZZ_COMMON)
settings.register_profile("fuzz", max_examples=400, **_FUZZ_COMMON)


def pytest_configure(config: pytest.Config) -> None:
    long = "fuzz" in (config.getoption("markexpr", "") or "")
    settings.load_profile("fuzz" if long else "default-run")


#: Modules whose tests (with their shared fixtures) take most of the suite's time: all their
#: tests count as ``slow``, out of the fast loop (``make test-fast``), still in ``make test``.
#: Seconds per module (calls and fixtures, 2 workers, 2026-11-29): real photographs 98, the
#: simulate CLI 50, vision fuzzing 44, campaign paths 35, the vision CLI 34, table fuzzing 31,
#: sensor campaigns 30, rig measurement 25 and calibration 24 (CLI 11), the browser 20, capture
#: 18, photometric 18, detection 15, simulated campaigns 13, the sensors CLI 12, report files 11.
SLOW_MODULES = frozenset(
    {
        "test_vision_real",
        "test_sim_cli",
        "test_fuzz_vision",
        "test_campaign_paths",
        "test_vision_cli",
        "test_fuzz_tables",
        "test_campaign_sensor",
        "test_rig_measure",
        "test_rig_calibration",
        "test_rig_calibration_cli",
        "test_report_browser",
        "test_capture",
        "test_vision_photometric",
        "test_vision_detect",
        "test_sim_campaign",
        "test_sensors_cli",
        "test_report_write",
    }
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.path.stem in SLOW_MODULES:
            item.add_marker(pytest.mark.slow)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)
