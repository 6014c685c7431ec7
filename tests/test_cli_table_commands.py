"""Every command's tables at 80 and 100 columns: wrapped, split or stacked, never a number cut.

Each command runs once in this process on a small real or simulated input; every table it
prints is kept (the consoles pass each through :func:`stiffmap.cli.common.fit_table`) and
drawn again at 80 and 100 columns, where every line must fit, nothing may end in ``…`` and
every number of the table drawn 400 columns wide must appear whole
(:func:`helpers.table_width.assert_fits`). The commands whose inputs take long to make
(``calibrate-rig``, ``pose``, ``displacement``, ``validate``, ``run`` on images, ``demo``)
are checked where their own tests already run them, at 80 or 100 columns
(``run_stiffmap(..., columns=...)``, which refuses a ``…`` in any output and a table line
wider than the terminal); ``init`` and ``capture`` print no table, ``report`` only lines.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers.cli_process import run_in_process
from helpers.sensor_traces import quick_trace
from helpers.shared_data import CALIB_DIR
from helpers.table_width import assert_fits

from stiffmap.cli import common
from stiffmap.cli.main import COMMANDS
from stiffmap.loads import forces_matrix, paper9
from stiffmap.models import PRR3, prr3_points22
from stiffmap.models.fit import static_error_predictions
from stiffmap.sensors import write_recording

#: Where each command's tables are checked (this module, or the test that runs it at 80/100).
WHERE = {
    "identify": "here",
    "calibrate": "here",
    "model": "here",
    "fit": "here",
    "sensor": "here",
    "simulate": "test_sim_cli.py::test_3prr_sensor_campaign_round_trip",
    "run": "test_campaign_sensor.py (recordings); test_campaign_run.py (images)",
    "calibrate-rig": "test_rig_calibration_cli.py (the stereo result)",
    "pose": "test_vision_cli.py::test_pose_table_wrong_board_size_and_all_failed; test_rig_measure.py",
    "displacement": "test_vision_cli.py::test_displacement_camera_and_base_frames",
    "validate": "test_vision_cli.py::test_validate_table_json_and_plot",
    "demo": "test_campaign_run.py (the quick demo, long profile)",
    "report": "no table",
    "init": "no table",
    "capture": "no table (its live view is a screen of its own)",
    "compensate": "here",
}


def test_every_command_is_accounted_for():
    assert set(WHERE) == set(COMMANDS)


@pytest.fixture
def tables(monkeypatch):
    """Every table the command prints (through the consoles' render hook)."""
    seen = []
    real = common.fit_table

    def keep(table, console, width=None):
        seen.append(table)
        return real(table, console, width)

    monkeypatch.setattr(common, "fit_table", keep)
    return seen


def _check(tables, n_least: int = 1) -> None:
    assert len(tables) >= n_least, "the command printed fewer tables than expected"
    for t in tables:
        for width in (80, 100):
            assert_fits(t, width)


def _run(args, monkeypatch, capsys, codes=(0,)):
    code, out, err = run_in_process(args, monkeypatch, capsys)
    assert code in codes, err
    assert "…" not in out
    return out


def test_identify_tables(tmp_path, monkeypatch, capsys, tables):
    F = forces_matrix(paper9())
    K = np.array([[3.1, 0.4, 0.2], [0.4, 2.2, -0.3], [0.2, -0.3, 5.0]])  # N/mm
    rng = np.random.default_rng(3)
    D = np.concatenate(
        [np.linalg.solve(K, F) + rng.normal(scale=2e-3, size=F.shape) for _ in range(2)], axis=1
    )
    (tmp_path / "f.csv").write_text("fx,fy,fz\n" + "\n".join(",".join(map(str, r)) for r in F.T) + "\n")
    rows = [[*D[:, i], i // 9 + 1] for i in range(D.shape[1])]
    (tmp_path / "d.csv").write_text(
        "dx,dy,dz,repeat\n" + "\n".join(",".join(map(str, r)) for r in rows) + "\n"
    )
    _run(["identify", tmp_path / "f.csv", tmp_path / "d.csv"], monkeypatch, capsys)
    _check(tables, 3)


def test_model_tables(tmp_path, monkeypatch, capsys, tables):
    _run(["model", "delta"], monkeypatch, capsys)  # the reference study's 48 positions, 10 columns
    _run(["model", "3prr", "--direction", "y"], monkeypatch, capsys)
    _check(tables, 2)


def test_fit_tables(tmp_path, monkeypatch, capsys, tables):
    P = prr3_points22()
    pts = np.vstack([P, P])
    F = np.vstack([np.tile([490.5, 0.0], (22, 1)), np.tile([0.0, 490.5], (22, 1))])  # N
    y = static_error_predictions(PRR3(), pts, F, F / 490.5)
    y = y * (1 + 0.02 * np.random.default_rng(5).standard_normal(y.size))
    lines = ["x,y,fx,fy,value_mm,std_mm"] + [
        f"{pts[i, 0]},{pts[i, 1]},{F[i, 0]},{F[i, 1]},{float(y[i])!r},{0.02 * abs(float(y[i]))!r}"
        for i in range(y.size)
    ]
    (tmp_path / "s.csv").write_text("\n".join(lines) + "\n")
    _run(["fit", "3prr", tmp_path / "s.csv", "--param-to-fit", "kj,kb"], monkeypatch, capsys)
    _check(tables, 2)


def test_sensor_tables(tmp_path, monkeypatch, capsys, tables):
    paths = [write_recording(quick_trace(0.8, seed=s).recording, tmp_path / f"r{s}.csv") for s in (1, 2)]
    _run(["sensor", *paths], monkeypatch, capsys)
    _check(tables, 1)


def test_calibrate_tables_on_real_photographs(tmp_path, monkeypatch, capsys, tables):
    """Four of Bouguet's calib_example views: the parameters' table and the views' (long paths)."""
    files = [CALIB_DIR / f"Image{i}.tif" for i in (1, 2, 3, 4)]
    args = ["calibrate", *files, "--board", "13x12", "--square-mm", "30", "--out", tmp_path / "c.json"]
    _run(args, monkeypatch, capsys)
    _check(tables, 2)


def test_compensate_summary_table(tmp_path, monkeypatch, capsys, tables):
    prog = tmp_path / "p.nc"
    prog.write_text("G21 G90\nG0 X0 Y0 Z5\nG1 Z0 F100\nG1 X10\nG1 Y10\n")
    args = ["compensate", "3prr", "--path", prog, "--out", tmp_path / "o.nc", "-q", "--place", "380,200"]
    _run([*args, "--force-n", "0,-490.5", "--no-figures"], monkeypatch, capsys)
    _check(tables, 1)
