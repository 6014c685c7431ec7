"""Shared test fixtures. The test helpers live in the ``helpers`` package beside this file."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

# pytest's default import mode puts tests/ on sys.path, which makes ``import helpers`` work;
# this keeps it so under ``--import-mode=importlib`` too.
_TESTS = str(Path(__file__).resolve().parent)
if _TESTS not in sys.path:
    sys.path.insert(0, _TESTS)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)
