"""``stiffmap simulate OUT --robot MY_ROBOT.toml``: a user's own legs TOML on the virtual test-bed."""

from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
from helpers.cli_process import run_in_process as _cli
from helpers.fitted_campaign import k6_error, run_and_fit
from helpers.own_hexapod import OWN_K, write_own_hexapod
from helpers.own_hexapod import gosselin_k6 as _gosselin
from helpers.poses import rpy_matrix

from stiffmap.campaign.robot import campaign_model
from stiffmap.campaign.spec import load_spec
from stiffmap.kinds.parallel import HEXAPOD_TESTBED_K, legs_default_grid, legs_default_poses
from stiffmap.loads import paper9
from stiffmap.models.legs import LegRobot
from stiffmap.models.mobility import platform_mobility

ROBOTS = files("stiffmap.models") / "robots"
HEXAPOD = str(ROBOTS / "hexapod.toml")
TESTBED_PARAMS = ",".join(f"k_leg{i}={k:g}" for i, k in enumerate(HEXAPOD_TESTBED_K, start=1))


@pytest.fixture(scope="module")
def own_toml(tmp_path_factory) -> Path:
    """The 6-UPS of helpers.own_hexapod, its legs' stroke 180-380 mm."""
    return write_own_hexapod(tmp_path_factory.mktemp("own") / "my_hexapod.toml", stroke_mm=(180.0, 380.0))


def _truth(out: Path) -> dict:
    return json.loads((out / "truth.json").read_text())


@pytest.mark.slow  # about 10 s on one core: two truths of 18 positions
def test_the_shipped_hexapod_as_a_file_is_the_testbed_hexapod(monkeypatch, capsys, tmp_path):
    # The same TOML with the test-bed's legs: the same default positions (the 3 x 3 x 2 grid about
    # its home, 40 mm apart, is HEXAPOD_TESTBED_POSITIONS), loads, load point and truth.
    runs = {}
    for name, robot in (("file", [HEXAPOD, "--param", TESTBED_PARAMS]), ("testbed", ["hexapod"])):
        code, _, err = _cli(
            ["simulate", tmp_path / name, "--robot", *robot, "--truth-only", "--json"], monkeypatch, capsys
        )
        assert code == 0, err
        runs[name] = _truth(tmp_path / name)
    a, b = runs["file"], runs["testbed"]
    assert len(a["positions"]) == len(b["positions"]) == 18
    assert a["loads"] == b["loads"] and a["robot"]["load_point_mm"] == [0.0, 0.0, -100.0]
    for p, q in zip(a["positions"], b["positions"], strict=True):
        assert p["position"] == q["position"]
        K6p, K6q = np.array(p["K_tcp"]), np.array(q["K_tcp"])
        assert np.abs(K6p - K6q).max() <= 1e-12 * np.abs(K6q).max()
    spec = load_spec(tmp_path / "file" / "campaign.toml")  # reads back; the TOML copied beside it
    assert spec.robot.model == "legs" and (tmp_path / "file" / spec.robot.legs).is_file()
    model = campaign_model(spec, tmp_path / "file")
    assert model.params() == {f"k_leg{i}": k for i, k in enumerate(HEXAPOD_TESTBED_K, start=1)}


@pytest.mark.slow  # about 5 s on one core: the truth of 18 positions
def test_own_hexapod_truth_is_the_closed_form_and_its_stiff_legs_get_heavier_loads(
    own_toml, monkeypatch, capsys, tmp_path
):
    out = tmp_path / "own"
    code, stdout, err = _cli(
        ["simulate", out, "--robot", own_toml, "--truth-only", "--json"], monkeypatch, capsys
    )
    assert code == 0, err
    summary = json.loads(stdout)
    truth = _truth(out)
    P = np.array([p["position"] for p in truth["positions"]])
    # The default grid: 3 x 3 x 2 about the home (0, 0, 260), spacing 0.12 of the size
    # sqrt(120^2 + 260^2) = 286 mm, rounded: 35 mm.
    expected = [
        [x, y, 260.0 + z] for z in (-17.5, 17.5) for y in (-35.0, 0.0, 35.0) for x in (-35.0, 0.0, 35.0)
    ]
    np.testing.assert_allclose(P, expected, atol=1e-9)
    for p in truth["positions"]:
        K6 = _gosselin(p["position"])
        np.testing.assert_allclose(p["K_tcp"], K6, rtol=1e-9, atol=1e-9 * np.abs(K6).max())
    # Legs of 350-540 N/mm: paper9 moves the tool point by 0.025 mm at most, below what the camera
    # measures well; its masses are scaled (x 50 here) so that the largest displacement is about 1 mm.
    F = np.array([ld["force_n"] for ld in truth["loads"]])
    F0 = np.array([ld.force for ld in paper9()])
    scale = np.linalg.norm(F, axis=1) / np.linalg.norm(F0, axis=1)
    np.testing.assert_allclose(F, scale[0] * F0, rtol=1e-12)
    assert scale[0] in (10.0, 20.0, 50.0, 100.0)
    assert f"paper9 x {scale[0]:g}" in summary["setup"]["loads"]
    assert (
        "a 3 x 3 x 2 grid 35 mm apart about the home position (0, 0, 260) mm" in summary["setup"]["positions"]
    )
    lp = np.array([0.0, 0.0, -100.0])
    u = [np.linalg.norm(np.linalg.solve(_gosselin(p), np.r_[f, np.cross(lp, f)])[:3]) for p in P for f in F]
    assert 0.5 <= max(u) <= 4.0 and f"{max(u):.3g} mm" in summary["setup"]["loads"]
    spec = load_spec(out / "campaign.toml")
    np.testing.assert_allclose([ld.force for ld in spec.loads.resolve(spec.g)], F)


def test_a_dim3_legs_file_is_a_translational_platform(monkeypatch, capsys, tmp_path):
    # The Delta written as legs: a 3x3 field (its K per position is the model's), loads at the
    # tool point, --rot-stiffness-nmm-per-rad taken as for the Delta test-bed.
    out = tmp_path / "d"
    args = ["simulate", out, "--robot", ROBOTS / "delta.toml", "--truth-only", "--select", "1,18", "--json"]
    code, _, err = _cli(args, monkeypatch, capsys)
    assert code == 0, err
    model = LegRobot.from_toml(ROBOTS / "delta.toml")
    grid, home, s = legs_default_grid(model)
    truth = _truth(out)
    P = np.array([p["position"] for p in truth["positions"]])
    np.testing.assert_allclose(P, grid[[0, 17]])
    np.testing.assert_allclose([p["K"] for p in truth["positions"]], model.stiffness(P), rtol=1e-12)
    # Its home, the closed form at the actuators' seed 0.5 rad (delta.toml: base radius 150 mm,
    # arm 300 mm, forearm 425 mm, platform radius 40 mm); size hypot(40, 347) = 349 mm: spacing
    # 0.12 x 349 = 41.9 mm, rounded to 40.
    z = -300.0 * np.sin(0.5) - np.sqrt(425.0**2 - (150.0 + 300.0 * np.cos(0.5) - 40.0) ** 2)
    np.testing.assert_allclose(home, [0.0, 0.0, z], atol=1e-6)
    assert s == 40.0
    rot = ["--rot-stiffness-nmm-per-rad", "2e5", "--load-point-mm", "0,0,-50"]
    code, _, err = _cli([*args, "--force", *rot], monkeypatch, capsys)
    assert code == 0, err
    # As for the Delta test-bed: K6 = diag(K, 2e5 I) at the tool point, the loads 50 mm below it.
    truth = _truth(out)
    assert truth["robot"]["field"] == "6x6" and truth["robot"]["load_point_mm"] == [0.0, 0.0, -50.0]
    for p, K in zip(truth["positions"], model.stiffness(P), strict=True):
        K6 = np.zeros((6, 6))
        K6[:3, :3], K6[3:, 3:] = K, 2e5 * np.eye(3)
        np.testing.assert_allclose(p["K_tcp"], K6, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(
    ("make", "extra", "message"),
    [
        ("attach2", [], "legs[1].attach_mm: expected 3 numbers (dim = 6"),
        ("own", ["--positions", "0,0,500"], "position 1 (0, 0, 500) mm: the robot model has no "
         "stiffness there (unreachable: leg 1 (leg1)"),
        ("3prr", [], "dim = 2, a planar robot: the test-bed simulates planar robots as displacement-sensor "
         "recordings of its own 3PRR (--robot 3prr)"),
        ("missing", [], "no such file (a test-bed robot is one of"),
        ("own", ["--tip", "tool0"], "--tip is for 'urdf', not legs"),
        ("own", ["--rot-stiffness-nmm-per-rad", "1e6"], "rotations come from its joints; leave it out"),
        ("own", ["--directions", "x"], "--directions: not used when simulating"),
        ("testbed", ["--tip", "tool0"],
         "--tip: for a robot of your own (--robot FILE.urdf, .xacro or .toml)"),
        ("urdf_legs", [], "legs given by URDFs cannot be simulated yet"),
        ("campaign", [], "campaign.toml: a campaign.toml (kind, [robot]), not a legs TOML: that has dim"),
    ],
)  # fmt: skip
def test_bad_input_is_one_line(own_toml, monkeypatch, capsys, tmp_path, make, extra, message):
    text = Path(HEXAPOD).read_text(encoding="utf-8")
    robot = {"own": str(own_toml), "3prr": str(ROBOTS / "3prr.toml"), "testbed": "hexapod"}.get(make)
    if make == "attach2":
        robot = tmp_path / "bad.toml"
        first = next(line for line in text.splitlines() if line.startswith("attach_mm"))
        robot.write_text(text.replace(first, "attach_mm = [1.0, 2.0]", 1))
    elif make == "missing":
        robot = tmp_path / "nowhere.toml"
    elif make == "urdf_legs":
        robot = _urdf_legs_toml(tmp_path)
    elif make == "campaign":  # a simulated campaign's own file, taken for a robot
        robot = tmp_path / "campaign.toml"
        robot.write_text('name = "x"\nkind = "vision"\n[robot]\nmodel = "legs"\nlegs = "robot.toml"\n')
    code, out, err = _cli(
        ["simulate", tmp_path / "o", "--robot", robot, "--truth-only", *extra], monkeypatch, capsys
    )
    assert code == 2, (out, err)
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert message in err, err
    assert not (tmp_path / "o" / "campaign.toml").exists()


def _urdf_legs_toml(tmp_path: Path) -> Path:
    """A dim = 3 legs TOML whose legs are one URDF's chain (each leg a prismatic joint then a ball)."""
    urdf = tmp_path / "leg.urdf"
    urdf.write_text(
        """<robot name="leg"><link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/>
<joint name="x" type="prismatic"><parent link="base"/><child link="l1"/><axis xyz="1 0 0"/>
<limit lower="-500" upper="500" effort="1" velocity="1"/></joint>
<joint name="y" type="prismatic"><parent link="l1"/><child link="l2"/><axis xyz="0 1 0"/>
<limit lower="-500" upper="500" effort="1" velocity="1"/></joint>
<joint name="z" type="prismatic"><parent link="l2"/><child link="l3"/><axis xyz="0 0 1"/>
<limit lower="-500" upper="500" effort="1" velocity="1"/></joint></robot>"""
    )
    legs = "".join(
        f'[[legs]]\nname = "leg{i}"\nattach_mm = [0.0, 0.0, 0.0]\nurdf = "leg.urdf"\ntip_frame = "l3"\n'
        f'[[legs.joints]]\nname = "{j}"\nrole = "actuated"\nstiffness = "k{i}"\n\n'
        for i, j in enumerate("xyz", start=1)
    )
    path = tmp_path / "urdf_legs.toml"
    path.write_text(f'name = "cartesian"\ndim = 3\n[params]\nk1 = 1.0\nk2 = 1.0\nk3 = 1.0\n\n{legs}')
    return path


@pytest.mark.long  # about 60 s on 2 cores: 9 load cases at 2 positions rendered, measured, fitted
def test_own_hexapod_campaign_recovers_K6_and_its_legs(own_toml, monkeypatch, capsys, tmp_path):
    # simulate then run then report, two positions of the default grid, one repeat, the true camera:
    # each K6 within 2 % (relative Frobenius, rad as L mm), the six legs within 1 %.
    out = tmp_path / "own"
    args = ["simulate", out, "--robot", own_toml, "--select", "1,14", "--repeats", "1", "--true-camera"]
    code, _, err = _cli([*args, "--workers", "2"], monkeypatch, capsys)
    assert code == 0, err
    fit, model = run_and_fit(out, monkeypatch, capsys)
    for i, k in enumerate(OWN_K, start=1):
        assert abs(fit.params[f"k_leg{i}"] - k) < 0.01 * k, (i, fit.params)
    for p in _truth(out)["positions"]:
        K6 = model.stiffness6(np.r_[p["position"], 0.0, 0.0, 0.0])
        assert k6_error(K6, _gosselin(p["position"]), model.length_mm) < 0.02
    code, _, err = _cli(["report", out], monkeypatch, capsys)
    assert code in (0, 1), err
    assert (out / "report" / "index.html").is_file()


def test_a_load_file_too_light_for_stiff_legs_is_kept_with_a_warning(own_toml, monkeypatch, capsys, tmp_path):
    # paper9's forces as a file: used as given (the user chose them), with one warning saying how far
    # they move the tool point (the closed form's largest displacement) and the range measured well.
    loads = tmp_path / "light.csv"
    F = np.array([ld.force for ld in paper9()])
    loads.write_text("fx,fy,fz\n" + "".join(",".join(f"{v:.17g}" for v in f) + "\n" for f in F))
    out = tmp_path / "light"
    args = ["simulate", out, "--robot", own_toml, "--truth-only", "--loads", loads, "--select", "1,18"]
    code, _, err = _cli(args, monkeypatch, capsys)
    assert code == 1, err
    truth = _truth(out)
    np.testing.assert_allclose([ld["force_n"] for ld in truth["loads"]], F, rtol=1e-12)
    lp = np.array([0.0, 0.0, -100.0])
    P = [p["position"] for p in truth["positions"]]
    u = max(
        np.linalg.norm(np.linalg.solve(_gosselin(p), np.r_[f, np.cross(lp, f)])[:3]) for p in P for f in F
    )
    (line,) = [t for t in err.splitlines() if t.startswith("warning: ")]
    assert f"move the tool point by {u:.3g} mm at most, too small for the camera to measure well" in line
    assert "0.5 to 4 mm measure well" in line


def test_a_default_grid_out_of_reach_asks_for_positions(monkeypatch, capsys, tmp_path):
    # The shipped hexapod with legs whose stroke is 342-343.7 mm (home: 342.85 mm): no position of
    # its grid (z 280 and 320 mm) is reachable, so it asks for the positions, naming a leg and its
    # limit; the home position given is simulated.
    robot = tmp_path / "short_stroke.toml"
    text = Path(HEXAPOD).read_text(encoding="utf-8")
    robot.write_text(text.replace("lower = 260.0", "lower = 342.0").replace("upper = 440.0", "upper = 343.7"))
    args = ["simulate", tmp_path / "o", "--robot", robot, "--truth-only"]
    code, out, err = _cli(args, monkeypatch, capsys)
    assert (
        code == 2
        and err.startswith("error: --positions: no position of the default grid")
        and err.count("\n") == 1
    )
    assert "position 1 (-40, -40, 280) mm: unreachable: leg 1 (leg1)" in err and "[342, 343.7] mm" in err
    assert err.rstrip().endswith("; give them")
    code, out, err = _cli([*args, "--positions", "0,0,300"], monkeypatch, capsys)
    assert code == 0, err


def test_own_hexapod_at_turned_poses_from_a_csv(own_toml, monkeypatch, capsys, tmp_path):
    # x, y, z, roll_deg, pitch_deg, yaw_deg: the platform held turned, its truth the closed form
    # at the turned pose (r_i = R attach_i).
    poses = tmp_path / "poses.csv"
    rows = [[0.0, 0.0, 260.0, 6.0, -4.0, 0.0], [20.0, -10.0, 250.0, -3.0, 5.0, 8.0]]
    poses.write_text(
        "x,y,z,roll_deg,pitch_deg,yaw_deg\n" + "".join(",".join(map(str, r)) + "\n" for r in rows)
    )
    out = tmp_path / "turned"
    code, _, err = _cli(
        ["simulate", out, "--robot", own_toml, "--positions", poses, "--truth-only"], monkeypatch, capsys
    )
    assert code == 0, err
    for p, r in zip(_truth(out)["positions"], rows, strict=True):
        assert p["orientation_deg"] == pytest.approx(r[3:])
        K6 = _gosselin(r[:3], R=rpy_matrix(*np.radians(r[3:])))
        np.testing.assert_allclose(p["K_tcp"], K6, rtol=1e-9, atol=1e-9 * np.abs(K6).max())


def test_a_3rps_gets_a_grid_in_its_own_coordinates_and_a_pose_it_cannot_hold_names_the_nearest(
    monkeypatch, capsys, tmp_path
):
    # A 3-RPS moves in z, roll and pitch (x, y and yaw follow): its default grid is 3 x 3 x 2 in
    # those (roll and pitch -8, 0, 8 deg, z 235 and 265 mm about its home (0, 0, 250)), x, y and yaw
    # solved so that every ball joint lies in its leg's plane (checked here from the geometry of
    # rps3_toml: revolute axes tangent to the 200 mm circle at 90, 210, 330 deg, balls on 100 mm).
    code, out, err = _cli(
        ["simulate", tmp_path / "all", "--robot", ROBOTS / "3rps.toml", "--truth-only", "--json"],
        monkeypatch,
        capsys,
    )
    assert code == 0 and "note:" not in err, err
    assert (
        "3rps moves in z, roll, pitch: x, y, yaw follow, solved at each pose"
        in json.loads(out)["setup"]["positions"]
    )
    truth = _truth(tmp_path / "all")["positions"]
    poses = np.array([np.r_[p["position"], np.radians(p["orientation_deg"])] for p in truth])
    grid = [(r, p, z) for z in (235.0, 265.0) for p in (-8.0, 0.0, 8.0) for r in (-8.0, 0.0, 8.0)]
    np.testing.assert_allclose(poses[:, 2], [g[2] for g in grid], atol=1e-9)
    np.testing.assert_allclose(np.degrees(poses[:, 3:5]), [g[:2] for g in grid], atol=1e-9)
    ang = np.radians([90.0, 210.0, 330.0])
    e = np.stack([np.cos(ang), np.sin(ang), 0 * ang], axis=1)
    axes = np.stack([-np.sin(ang), np.cos(ang), 0 * ang], axis=1)
    for p in poses:
        tips = p[:3] + 100.0 * e @ rpy_matrix(*p[3:]).T
        assert np.abs(np.einsum("ij,ij->i", tips - 200.0 * e, axes)).max() < 1e-9
    assert np.abs(poses[:, :2]).max() > 0.4  # the parasitic shift of 8 deg: about 0.5 mm
    model = LegRobot.from_toml(ROBOTS / "3rps.toml")
    np.testing.assert_allclose([p["K_tcp"] for p in truth], model.stiffness6(poses), rtol=1e-9)
    # A pose it cannot hold: one line naming the legs and the nearest pose it holds.
    args = [
        "simulate",
        tmp_path / "o",
        "--robot",
        ROBOTS / "3rps.toml",
        "--truth-only",
        "--positions",
        "10,0,250",
    ]
    code, _, err = _cli(args, monkeypatch, capsys)
    assert code == 2 and err.count("\n") == 1 and "leg 1 (leg1) cannot reach it" in err, err
    assert err.rstrip().endswith(
        "3rps moves in z, roll, pitch: x, y, yaw follow: the nearest pose it holds is (0, 0, 250) mm, "
        "roll/pitch/yaw (0, 0, 0) deg)"
    )


def test_poses_for_a_platform_that_keeps_its_orientation_are_refused(monkeypatch, capsys, tmp_path):
    # The Delta as legs (dim = 3) given a poses CSV: a roll of 5 deg would be left out (it was:
    # the positions alone simulated), so it is one line naming the file, the line and the column;
    # orientations of 0 are the positions themselves.
    poses = tmp_path / "poses.csv"
    poses.write_text("x,y,z,roll_deg,pitch_deg,yaw_deg\n0,0,-347,0,0,0\n10,0,-347,5,0,0\n")
    for robot in (ROBOTS / "delta.toml", "delta"):
        args = ["simulate", tmp_path / "o", "--robot", robot, "--positions", poses, "--truth-only"]
        code, _, err = _cli(args, monkeypatch, capsys)
        assert code == 2 and err.count("\n") == 1, err
        assert err.startswith(f"error: {poses}: line 3, column 'roll_deg': 5 deg, but this robot's platform")
    poses.write_text("x,y,z,roll_deg,pitch_deg,yaw_deg\n0,0,-347,0,0,0\n10,0,-347,0,0,0\n")
    code, _, err = _cli([*args[:3], ROBOTS / "delta.toml", *args[4:]], monkeypatch, capsys)
    assert code == 0, err
    P = [p["position"] for p in _truth(tmp_path / "o")["positions"]]
    np.testing.assert_allclose(P, [[0.0, 0.0, -347.0], [10.0, 0.0, -347.0]])


@pytest.mark.long  # 49 s of CPU (3.5 min on the shared machine): 9 loads at 3 turned poses rendered, fitted
def test_3rps_campaign_recovers_its_six_springs_and_K6(monkeypatch, capsys, tmp_path):
    # The shipped 3-RPS with two springs changed, three of its default poses (roll and pitch -8 and
    # +8 deg at z 235 mm, level at 265 mm; x, y, yaw solved), one repeat, the true camera: its six
    # springs within 1 %, and the fitted model's K6 at all 18 default poses within 2 % of the truth's
    # (relative Frobenius, rad as L mm).
    out = tmp_path / "rps"
    truth = {"k_leg2": 400.0, "k_bend3": 100.0}
    args = ["simulate", out, "--robot", ROBOTS / "3rps.toml", "--param", "k_leg2=400,k_bend3=100"]
    args += ["--select", "1,9,14", "--repeats", "1", "--true-camera", "--workers", "2"]
    code, _, err = _cli(args, monkeypatch, capsys)
    assert code == 0, err
    fit, model = run_and_fit(out, monkeypatch, capsys)
    true_model = LegRobot.from_toml(ROBOTS / "3rps.toml")
    true_model = true_model.with_params(**{**true_model.params(), **truth})
    for name, k in true_model.params().items():
        assert abs(fit.params[name] - k) < 0.01 * k, (name, fit.params)
    poses = [np.r_[p["position"], np.radians(p["orientation_deg"])] for p in _truth(out)["positions"]]
    np.testing.assert_allclose(
        [p["K_tcp"] for p in _truth(out)["positions"]], true_model.stiffness6(poses), rtol=1e-9
    )
    grid, _ = legs_default_poses(true_model, platform_mobility(true_model))
    for K6, T in zip(model.stiffness6(grid), true_model.stiffness6(grid), strict=True):
        assert k6_error(K6, T, model.length_mm) < 0.02
