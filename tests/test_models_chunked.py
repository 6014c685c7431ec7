"""A model evaluated in chunks with progress is the model evaluated at once (issue 27: ``model legs
--grid`` over a million poses ran about 25 minutes printing nothing; it now shows a progress bar
fed between chunks)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from stiffmap.models.chunked import evaluate_in_chunks
from stiffmap.models.delta import DeltaRobot
from stiffmap.models.legs import LegRobot

ROBOTS = Path(__file__).resolve().parents[1] / "src" / "stiffmap" / "models" / "robots"


def _grid(n: int) -> np.ndarray:
    # Poses of the Delta's workspace and some beyond it (unreachable: their reasons must follow).
    x = np.linspace(-150.0, 600.0, n)
    return np.column_stack([x, 0.5 * x[::-1], np.full(n, -310.0)])


@pytest.mark.parametrize(
    "model", [DeltaRobot(), LegRobot.from_toml(ROBOTS / "delta.toml")], ids=["delta", "delta as legs"]
)
def test_chunks_give_the_map_of_one_call_and_report_progress(model):
    P = _grid(23)
    whole = model.evaluate(P)
    calls = []
    chunked = evaluate_in_chunks(model, P, lambda done, total: calls.append((done, total)), chunk=5)
    assert 0 < whole.n_valid < len(P)  # both reachable and unreachable poses
    for f in dataclasses.fields(whole):
        a, b = getattr(whole, f.name), getattr(chunked, f.name)
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b, err_msg=f.name)
            assert not b.flags.writeable
        else:
            assert a == b, f.name
    assert calls == [(0, 23), (5, 23), (10, 23), (15, 23), (20, 23), (23, 23)]
    # One chunk: one call, one progress report.
    calls.clear()
    evaluate_in_chunks(model, P[:4], lambda done, total: calls.append((done, total)), chunk=5)
    assert calls == [(4, 4)]
