"""``stiffmap model legs`` and ``stiffmap fit legs`` of a platform that turns (a dim = 6 legs TOML)."""

from __future__ import annotations

import csv
import io
import json
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
from helpers.cli_process import run_in_process as _cli
from helpers.poses import rpy_matrix

from stiffmap.models.legs import LegRobot

HEXAPOD = str(files("stiffmap.models") / "robots" / "hexapod.toml")


def _gosselin(robot, k, pose_deg) -> np.ndarray:
    """K6 = sum k_i a_i a_i^T, a_i = (n_i, r_i x n_i), from the TOML's joints (written here)."""
    p = np.asarray(pose_deg, dtype=float)
    R = rpy_matrix(*np.radians(p[3:]))
    K6 = np.zeros((6, 6))
    for d, ki in zip(robot.description, k, strict=True):
        r = R @ np.asarray(d.attach_mm)
        n = p[:3] + r - np.asarray(d.joints[0].xyz_mm)
        n /= np.linalg.norm(n)
        a = np.r_[n, np.cross(r, n)]
        K6 += ki * np.outer(a, a)
    return K6


def test_model_legs_of_a_hexapod_gives_K6_per_pose_and_names_the_leg_out_of_stroke(
    monkeypatch, capsys, tmp_path
):
    f = tmp_path / "poses.csv"
    f.write_text("x,y,z,roll_deg,pitch_deg,yaw_deg\n0,0,300,0,0,0\n15,-10,320,4,-3,12\n0,0,600,0,0,0\n")
    args = ["model", "legs", HEXAPOD, "--points", f, "--param", "k_leg2=700", "--json"]
    code, out, err = _cli(
        [*args, "--load-n", "20", "--direction", "x", "--moment-nmm", "0,0,3000"], monkeypatch, capsys
    )
    assert code == 1, err  # one pose beyond the legs' stroke
    recs = json.loads(out)
    robot = LegRobot.from_toml(HEXAPOD)
    k = [500.0, 700.0, 500.0, 500.0, 500.0, 500.0]
    for rec, pose in zip(recs[:2], ([0, 0, 300, 0, 0, 0], [15, -10, 320, 4, -3, 12]), strict=True):
        K6 = _gosselin(robot, k, pose)
        np.testing.assert_allclose(rec["K6"], K6, rtol=1e-9, atol=1e-9 * np.abs(K6).max())
        d = np.linalg.solve(K6, [20.0, 0, 0, 0, 0, 3000.0])
        got = [rec[c] for c in ("ux", "uy", "uz", "rx_rad", "ry_rad", "rz_rad")]
        np.testing.assert_allclose(got, d, rtol=1e-7, atol=1e-13)
        assert rec["yaw_deg"] == pytest.approx(pose[5])
    assert recs[2]["error"].startswith("unreachable: leg 1 (leg1)")
    assert "joint stroke at" in recs[2]["error"] and "beyond its limits [260, 440] mm" in recs[2]["error"]


def test_a_grid_at_orientations_maps_tilts_and_fits_back(monkeypatch, capsys, tmp_path):
    o = tmp_path / "k6.csv"
    grid = ["--grid=-20:20:2,0,300", "--orientation=-6:6:3,0,10"]
    code, out, err = _cli(
        ["model", "legs", HEXAPOD, *grid, "--param", "k_leg5=650", "--csv", "-o", o], monkeypatch, capsys
    )
    assert code == 0, err
    rows = list(csv.DictReader(io.StringIO(o.read_text())))
    assert [(float(r["x"]), float(r["roll_deg"])) for r in rows] == [
        (x, roll) for roll in (-6.0, 0.0, 6.0) for x in (-20.0, 20.0)
    ]
    assert {float(r["yaw_deg"]) for r in rows} == {10.0}
    code, out, err = _cli(["fit", "legs", HEXAPOD, o, "--json"], monkeypatch, capsys)
    assert code == 0, err
    fit = json.loads(out)
    assert fit["kind"] == "stiffness6"
    est = {k: v["estimate"] for k, v in fit["parameters"].items()}
    np.testing.assert_allclose(
        [est[f"k_leg{i}"] for i in range(1, 7)], [500, 500, 500, 500, 650, 500], rtol=1e-6
    )
    code, out, err = _cli(["model", "legs", HEXAPOD, *grid], monkeypatch, capsys)  # the table
    assert code == 0 and "kr_min" in out and "rz (mrad)" in out


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--grid", "0,0,300", "--orientation", "0,0"], "--orientation '0,0': expected roll,pitch,yaw"),
        (["--grid", "0,0,300", "--orientation", "0,0,190"], "yaw: 190 deg is not within +-180 deg"),
        (["--grid", "0,0,300", "--moment-nmm", "1,2"], "--moment-nmm: expected MX,MY,MZ in N*mm"),
        (["--points", "{poses}", "--orientation", "0,0,0"], "--orientation goes with --grid"),
        (["--points", "{roll_only}"], "has roll_deg but not pitch_deg, yaw_deg"),
    ],
)
def test_bad_6d_input_is_one_line(monkeypatch, capsys, tmp_path, extra, message):
    (tmp_path / "poses.csv").write_text("x,y,z\n0,0,300\n")
    (tmp_path / "roll.csv").write_text("x,y,z,roll_deg\n0,0,300,5\n")
    extra = [e.format(poses=tmp_path / "poses.csv", roll_only=tmp_path / "roll.csv") for e in extra]
    code, out, err = _cli(["model", "legs", HEXAPOD, *extra], monkeypatch, capsys)
    assert code == 2, (out, err)
    assert message in err and err.startswith("error: ") and err.count("\n") == 1
    if "roll_deg" in message:
        assert str(tmp_path / "roll.csv") in err


def test_orientation_and_moment_are_refused_for_a_platform_that_only_translates(monkeypatch, capsys):
    for opt in (["--orientation", "0,0,0"], ["--moment-nmm", "0,0,1"]):
        code, _, err = _cli(["model", "delta", *opt], monkeypatch, capsys)
        assert code == 2 and f"{opt[0]} is for a platform that turns" in err and err.count("\n") == 1


def test_orientation_and_moment_are_refused_for_a_serial_arm(monkeypatch, capsys, tmp_path):
    """urdf evaluates configurations: the options were once silently ignored there."""
    configs = tmp_path / "q.csv"
    configs.write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,-30,-60,0,45,0\n")
    arm = ["model", "urdf", "arm6", "--tip", "tool0", "--configs", configs, "--param", "k_theta=1e7"]
    code, _, err = _cli(arm, monkeypatch, capsys)
    assert code == 0, err
    for opt in (["--orientation", "10,0,0"], ["--moment-nmm", "0,0,1"]):
        code, _, err = _cli([*arm, *opt], monkeypatch, capsys)
        assert code == 2 and f"{opt[0]} is for a platform that turns" in err and err.count("\n") == 1


def test_two_number_attach_mm_in_a_6d_file_names_file_and_key(monkeypatch, capsys, tmp_path):
    text = Path(HEXAPOD).read_text(encoding="utf-8")
    first = next(line for line in text.splitlines() if line.startswith("attach_mm"))
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace(first, "attach_mm = [1.0, 2.0]", 1))
    code, _, err = _cli(["model", "legs", bad, "--grid", "0,0,300"], monkeypatch, capsys)
    assert code == 2 and err.count("\n") == 1
    assert f"{bad}: legs[1].attach_mm: expected 3 numbers (dim = 6" in err


def test_the_shipped_hexapod_by_name(monkeypatch, capsys):
    code, out, err = _cli(["model", "legs", "hexapod", "--grid", "0,0,300", "--json"], monkeypatch, capsys)
    assert code == 0, err
    (rec,) = json.loads(out)
    np.testing.assert_allclose(
        rec["K6"], LegRobot.from_toml(HEXAPOD).stiffness6([0, 0, 300, 0, 0, 0]), rtol=1e-12
    )


def test_the_table_is_headed_by_the_legs_as_describe_gives_them(monkeypatch, capsys, tmp_path):
    """The first line names the legs in brackets: text, not markup (it lost '[leg1 ... ]')."""
    code, out, err = _cli(["model", "legs", "hexapod", "--grid", "0,0,300"], monkeypatch, capsys)
    assert code == 0, err
    assert out.splitlines()[0] == LegRobot.from_toml(HEXAPOD).describe()
    assert "6 legs [leg1 (3 joints), " in out.splitlines()[0]
