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


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)
