"""Degenerate report data the report must still draw (beside the library's own examples)."""

from __future__ import annotations

import numpy as np

from stiffmap.report.data import CampaignInfo, LoadData, MeasuredStiffness, ReportData


def all_positions_failed() -> ReportData:
    """A vision campaign of three positions where every position failed (no K, no load data)."""
    pos = np.array([[0.0, 0.0, -200.0], [100.0, 0.0, -200.0], [0.0, 0.0, -300.0]])
    return ReportData(
        CampaignInfo("all failed", "vision"),
        measured=MeasuredStiffness.from_K(
            pos, np.full((3, 3, 3), np.nan), messages=["a.png", "b.png", "c.png"]
        ),
        loads=LoadData(("l1",), np.array([[1.0, 0.0, 0.0]]), np.full((3, 1, 2), np.nan)),
    )
