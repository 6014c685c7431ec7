"""A sensor campaign end to end: simulated LDV traces of the 3PRR -> static errors -> K_j fit."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from helpers.cli_process import run_here, run_stiffmap

from stiffmap.models.presets import PRR3_MIDDLE_LINE, prr3_points22
from stiffmap.models.prr3 import PRR3
from stiffmap.report import load_report_data
from stiffmap.report.figure_data import sensor_lines
from stiffmap.sim.traces import simulate_point_traces


def _campaign(tmp_path, kj_true=600.0, seed=3):
    model = PRR3(kj=kj_true)
    pts = prr3_points22()[np.asarray(PRR3_MIDDLE_LINE) - 1]
    points = np.repeat(pts, 2, axis=0)
    dirs = np.tile([[1.0, 0.0], [0.0, 1.0]], (len(pts), 1))
    signs = np.tile([-1, 1], len(pts))  # horizontal loads through a mirror, as the milling study
    truths = simulate_point_traces(tmp_path / "rec", points, dirs, model, axis_signs=signs, seed=seed)
    recs = "\n".join(
        f'  {{point = [{p[0]:.6f}, {p[1]:.6f}], direction = "{"x" if d[0] else "y"}", '
        f'file = "rec/trace_{i:03d}.csv", sign = {s}}},'
        for i, (p, d, s) in enumerate(zip(points, dirs, signs, strict=True))
    )
    (tmp_path / "campaign.toml").write_text(
        f"""name = "3PRR static error"
kind = "sensor"
g = 9.81

[robot]
model = "3prr"

[sensor]
scale_um_per_v = 640.0
reference_load_n = 490.5
recordings = [
{recs}
]
"""
    )
    return truths, model


def test_sensor_campaign_recovers_kj_and_static_errors(tmp_path):
    truths, model = _campaign(tmp_path)
    proc = run_here("run", tmp_path, "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    fit = next(f for f in summary["model_fits"] if f["name"] == "static_error")
    assert fit["status"] == "ok"
    # The traces carry noise, drift and 16-bit quantisation; 16 recordings fix K_j well.
    assert fit["params"]["kj"] == pytest.approx(600.0, rel=0.01)
    # The report's linearity figure: every recording's plateaus and the line fitted to them
    # (least squares with an intercept: what it leaves sums to zero and is orthogonal to the load).
    data = load_report_data(tmp_path / "report" / "data.json")
    lin = sensor_lines(data)
    assert len(lin.rows) == 16
    for f, u, r in zip(lin.load, lin.displacement, lin.residual, strict=True):
        assert len(f) >= 5 and np.ptp(f) > 400.0  # N: the stepped load up to 50 kgf
        tol = 1e-9 * np.abs(u).max() * len(u)
        assert abs(r.sum()) < tol and abs((r * (f - f.mean())).sum()) < tol * np.abs(f).max()
    setup = {s.what: s.value for s in data.setup}
    assert setup["recordings"] == "16 of 16 analysed, 0 failed" and setup["failures"] == "none"
    rows = {r["file"]: r for r in _csv(tmp_path / "exports" / "sensor_results.csv")}
    for i, t in enumerate(truths):
        measured_um = float(rows[f"rec/trace_{i:03d}.csv"]["static_error_um"])
        true_um = 1e3 * t.static_error_mm
        assert abs(measured_um - true_um) <= 1.0 + 0.01 * abs(true_um)
    # A second run reuses every recording.
    again = run_here("run", tmp_path, columns=80)
    assert again.returncode == 0, again.stderr
    assert "16 recordings: 0 analysed, 16 unchanged" in again.stdout


def test_a_bad_recording_is_named_and_the_others_go_on(tmp_path):
    _campaign(tmp_path)
    bad = tmp_path / "rec" / "trace_003.csv"
    lines = bad.read_text().splitlines()
    head, rows = lines[0], lines[1:]
    cols = head.split(",")
    j = cols.index("displacement_v")
    for k in range(len(rows) // 3, len(rows) // 3 + 200):  # saturate a span
        cells = rows[k].split(",")
        cells[j] = "8.0"
        rows[k] = ",".join(cells)
    bad.write_text("\n".join([head, *rows]) + "\n")
    proc = run_stiffmap("run", tmp_path, merged=True)  # stdout and stderr as a terminal shows them
    assert proc.returncode == 1
    assert "rec/trace_003.csv" in proc.stdout and "satur" in proc.stdout
    assert "Traceback" not in proc.stdout
    warnings = [ln for ln in proc.stdout.splitlines() if ln.startswith("warning:")]
    assert not any("model fit" in ln for ln in warnings)  # the fit went on with the 15 others
    # The warnings come before the summary, which ends with "done" (issue 26: a warning after it).
    lines = proc.stdout.strip().splitlines()
    assert lines[-1].startswith("done in"), proc.stdout
    assert max(i for i, ln in enumerate(lines) if ln.startswith("warning:")) < lines.index(lines[-1])
    assert max(i for i, ln in enumerate(lines) if ln.startswith("warning:")) < min(
        i for i, ln in enumerate(lines) if ln.startswith("results:")
    )


def test_sign_mistakes_and_unreachable_points_are_left_out_of_the_fit_by_name(tmp_path):
    _campaign(tmp_path)
    spec = (tmp_path / "campaign.toml").read_text()
    # A mirror forgotten on one recording, one point moved out of reach, one recording dropped.
    spec = spec.replace('file = "rec/trace_000.csv", sign = -1', 'file = "rec/trace_000.csv", sign = 1')
    lines = spec.splitlines()
    i5 = next(i for i, ln in enumerate(lines) if "trace_005.csv" in ln)
    lines[i5] = '  {point = [400.0, 900.0], direction = "y", file = "rec/trace_005.csv", sign = 1},'
    lines = [ln for ln in lines if "trace_007.csv" not in ln]
    (tmp_path / "campaign.toml").write_text("\n".join(lines) + "\n")
    proc = run_here("run", tmp_path, "--no-report")
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert "rec/trace_000.csv: negative stiffness" in proc.stderr and "sign" in proc.stderr
    assert "rec/trace_005.csv: point [400.0, 900.0] outside the model" in proc.stderr
    assert "model fit:" not in proc.stderr  # fitted on the 13 others
    summary = json.loads((tmp_path / "exports" / "summary.json").read_text())
    fit = next(f for f in summary["model_fits"] if f["name"] == "static_error")
    assert fit["status"] == "ok" and fit["params"]["kj"] == pytest.approx(600.0, rel=0.01)
    files = [r["file"] for r in _csv(tmp_path / "exports" / "sensor_results.csv")]
    assert "rec/trace_007.csv" not in files and len(files) == 15
    # Correcting the sign re-analyses that recording only.
    (tmp_path / "campaign.toml").write_text(
        (tmp_path / "campaign.toml")
        .read_text()
        .replace('trace_000.csv", sign = 1', 'trace_000.csv", sign = -1')
    )
    proc = run_here("run", tmp_path, "--no-report")
    assert "15 recordings: 1 analysed, 14 unchanged" in proc.stdout
    assert "negative stiffness" not in proc.stderr


def _csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))
