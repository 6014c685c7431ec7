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
#: CPU seconds per module (its tests, fixtures and subprocesses, one core, 2026-11-29): real
#: photographs 50, rig measurement 31 and calibration 26 (CLI 12.5), photometric 24, the
#: simulate CLI 18.5, capture 18, detection 18, vision fuzzing 17, sensor campaigns 17,
#: simulated campaigns 15, the vision CLI 14, report files 11, campaign paths 6, the browser 6
#: (and Chromium's own processes), table fuzzing 3.5, the sensors CLI 0.4 (the last ones since
#: they run the commands in the test's process, ``helpers.cli_process.run_here``).
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
