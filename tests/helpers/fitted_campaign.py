"""``stiffmap run`` on a simulated campaign, then the model it fitted: the end of the
simulate-run tests of the robots whose parameters a campaign fits."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from helpers.cli_process import run_in_process
from stiffmap.campaign.robot import campaign_model
from stiffmap.campaign.spec import load_spec
from stiffmap.campaign.store import DB_NAME, Store


def run_and_fit(out: Path, monkeypatch, capsys, *, workers: int = 2):
    """``stiffmap run OUT`` (status 0 or 1: the fit's notes and warnings are the test's to check),
    the model fit it stored (status ``ok``) and the campaign's model with the fitted parameters."""
    code, _, err = run_in_process(["run", out, "--workers", str(workers)], monkeypatch, capsys)
    assert code in (0, 1), err
    with Store(out / DB_NAME) as st:
        fit = st.model_fit("stiffness")
    assert fit is not None and fit.status == "ok", fit
    return fit, campaign_model(load_spec(out / "campaign.toml"), out).with_params(**fit.params)


def k6_error(K6, truth, length_mm: float) -> float:
    """Relative Frobenius error of a 6x6 stiffness over (mm, rad), rotations taken as ``length_mm``
    mm (D K6 D, D = diag(1, 1, 1, 1/L, 1/L, 1/L)): translations and rotations weigh alike."""
    d = np.r_[np.ones(3), np.full(3, 1.0 / length_mm)]
    D = np.outer(d, d)
    return float(
        np.linalg.norm((np.asarray(K6) - np.asarray(truth)) * D) / np.linalg.norm(np.asarray(truth) * D)
    )
