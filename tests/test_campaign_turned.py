"""Campaigns of a platform that turns: ``positions.poses``, the turned test-bed, the runner's poses."""

from __future__ import annotations

import html
import json
from dataclasses import replace
from importlib.resources import files

import numpy as np
import pytest
from helpers.cli_process import run_in_process as _cli
from helpers.fitted_campaign import k6_error, run_and_fit

from stiffmap.campaign.platform import hung_force_stiffness
from stiffmap.campaign.positions import campaign_poses
from stiffmap.campaign.robot import campaign_model
from stiffmap.campaign.spec import load_spec, parse_spec
from stiffmap.campaign.spec_writer import EXAMPLE_TOML, dump_spec
from stiffmap.errors import InputError
from stiffmap.geometry import matrix_from_euler, transform_from
from stiffmap.loads import LoadCase
from stiffmap.models.legs import LegRobot
from stiffmap.sim.robot import delta_robot, platform_robot
from stiffmap.sim.scene import hexapod_scene
from stiffmap.sim.testbed import SimConfig, plan_campaign

ROBOTS = files("stiffmap.models") / "robots"
POSES = [[-40.0, -40.0, 280.0, 8.0, -6.0, 0.0], [0.0, 0.0, 320.0, -10.0, 5.0, 3.0]]


def _spec_text(robot: str, positions: str) -> str:
    """The example campaign.toml with its [robot] and [positions] replaced."""
    text = EXAMPLE_TOML.replace('model = "delta"', robot, 1)
    return text.replace('[positions]\npreset = "paper48"', f"[positions]\n{positions}", 1)


LEGS = 'model = "legs"\nlegs = "robot.toml"'


def test_spec_poses_round_trip_with_their_orientations():
    spec = parse_spec(_spec_text(LEGS, f"poses = {POSES}"))
    assert spec.positions.count() == 2
    np.testing.assert_array_equal(spec.positions.resolve(), np.array(POSES)[:, :3])
    np.testing.assert_array_equal(spec.positions.orientations_deg(), np.array(POSES)[:, 3:])
    again = parse_spec(dump_spec(spec))
    assert again.positions.poses == spec.positions.poses
    assert "poses = [[x, y, z, roll, pitch, yaw], ...]" in EXAMPLE_TOML
    # The runner's poses: the rows' positions (any order) with their rows' orientations, rad.
    P = campaign_poses(spec, [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], [2, 1])
    np.testing.assert_array_equal(P[:, :3], [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    np.testing.assert_allclose(np.degrees(P[:, 3:]), [POSES[1][3:], POSES[0][3:]], rtol=1e-14)


@pytest.mark.parametrize(
    ("robot", "positions", "expected"),
    [
        (
            'model = "delta"',
            f"poses = {POSES}",
            r"key 'positions.poses'.*not 'delta'",
        ),
        (LEGS, "poses = [[0.0, 0.0, 300.0, 5.0, 0.0]]", r"poses\[0\].* has 5 numbers"),
        (LEGS, "poses = [[0.0, 0.0, 300.0]]", r"poses\[0\].*without its orientation"),
        (LEGS, "poses = []", r"'poses' is empty"),
        (LEGS, "poses = [[0.0, 0.0, 300.0, 200.0, 0.0, 0.0]]", r"200.0 deg is beyond \+-180 deg"),
        (LEGS, f'poses = {POSES}\npreset = "paper48"', r"exactly one of .* \(got preset, poses\)"),
    ],
)
def test_spec_refuses_bad_poses_in_one_line_naming_the_key(robot, positions, expected):
    with pytest.raises(InputError, match=expected) as e:
        parse_spec(_spec_text(robot, positions))
    assert "\n" not in str(e.value) and "positions" in str(e.value)


@pytest.fixture(scope="module")
def hexapod():
    return LegRobot.from_toml(ROBOTS / "hexapod.toml").with_params(k_leg2=300.0, k_leg5=800.0)


def test_turned_platform_board_is_the_platform_pose_composed_with_its_mount(hexapod):
    # No repeatability, no jitter: each image's platform pose is the commanded pose (loaded: plus
    # the compliant motion of K6 at that pose), and the rendered board sits at tcp2base mobile2tcp.
    vr = platform_robot(hexapod, "legs", "legs", load_point_mm=(0.0, 0.0, -100.0))
    vr = replace(vr, repeatability_mm=0.0, repeatability_rad=0.0, jitter_mm=0.0)
    P = np.array(POSES)
    A = np.radians(P[:, 3:])
    scene = hexapod_scene()
    cfg = SimConfig(
        scene,
        vr,
        P[:, :3],
        (LoadCase(np.array([0.0, 4.905, 0.0]), np.zeros((3, 3))),),
        repeats=1,
        orientations=A,
    )
    plan = plan_campaign(cfg)
    np.testing.assert_array_equal(plan.K, hexapod.stiffness6(np.c_[P[:, :3], A]))
    for job in plan.jobs:
        i = job.position - 1
        T = transform_from(matrix_from_euler(A[i]), P[i, :3])
        if job.state == "loaded":
            F = np.array([0.0, 4.905, 0.0])
            d = np.linalg.solve(plan.K[i], np.r_[F, np.cross([0.0, 0.0, -100.0], F)])
            assert np.linalg.norm(d[3:]) > 1e-5  # the load turns it further
            np.testing.assert_allclose(job.tcp2base[:3, 3], P[i, :3] + d[:3], atol=1e-9)
        else:
            np.testing.assert_allclose(job.tcp2base, T, atol=1e-9)
        mobile = next(t for t in scene.targets(job.tcp2base) if t.name == "mobile")
        base2cam = np.linalg.inv(scene.cameras[0][2])
        np.testing.assert_allclose(mobile.board2cam, base2cam @ job.tcp2base @ scene.mobile2tcp, atol=1e-9)
    # Level is what it was: no orientations, the same plan as orientations of zeros.
    level = plan_campaign(SimConfig(scene, vr, P[:, :3], cfg.loads, repeats=1))
    zeros = plan_campaign(SimConfig(scene, vr, P[:, :3], cfg.loads, repeats=1, orientations=0 * A))
    np.testing.assert_array_equal(level.K, zeros.K)


def test_a_platform_that_does_not_turn_refuses_orientations():
    loads = (LoadCase(np.ones(3), np.zeros((3, 3))),)
    with pytest.raises(ValueError, match="platform does not turn"):
        SimConfig(hexapod_scene(), delta_robot(), [[0.0, 0.0, -300.0]], loads, orientations=[[0.1, 0, 0]])


@pytest.mark.slow  # about 4 s: the truth of two turned poses
def test_simulate_hexapod_at_turned_poses_writes_them_and_their_true_K6(monkeypatch, capsys, tmp_path):
    csv = tmp_path / "poses.csv"
    rows = "\n".join(",".join(map(str, p)) for p in POSES)
    csv.write_text(f"x,y,z,roll_deg,pitch_deg,yaw_deg\n{rows}\n")
    out = tmp_path / "hex"
    args = ["simulate", out, "--robot", "hexapod", "--truth-only", "--positions", csv]
    code, _, err = _cli(args, monkeypatch, capsys)
    assert code == 0, err
    spec = load_spec(out / "campaign.toml")
    assert spec.positions.poses == POSES
    model = campaign_model(spec, out)
    truth = json.loads((out / "truth.json").read_text())
    poses = np.c_[np.array(POSES)[:, :3], np.radians(np.array(POSES)[:, 3:])]
    K6 = model.stiffness6(poses)
    level = model.stiffness6(np.c_[poses[:, :3], np.zeros((2, 3))])
    for p, k6, k6_level, pose in zip(truth["positions"], K6, level, POSES, strict=True):
        np.testing.assert_allclose(p["orientation_deg"], pose[3:], atol=1e-12)
        np.testing.assert_allclose(p["K_tcp"], k6, rtol=1e-12)
        np.testing.assert_allclose(p["K"], hung_force_stiffness(k6, [0.0, 0.0, -100.0]), rtol=1e-10)
        assert np.linalg.norm(k6 - k6_level) > 1e-3 * np.linalg.norm(k6)  # turning it matters
    # capture --camera sim renders the platform level: it refuses a turned campaign.
    from stiffmap.capture.cameras import simulated_camera

    with pytest.raises(InputError, match=r"truth.json: .*holds the platform level; .*positions.poses"):
        simulated_camera(out, spec)


def test_simulate_refuses_an_orientation_column_without_the_others(monkeypatch, capsys, tmp_path):
    csv = tmp_path / "poses.csv"
    csv.write_text("x,y,z,roll_deg\n0,0,300,5\n")
    args = ["simulate", tmp_path / "o", "--robot", "hexapod", "--truth-only", "--positions", csv]
    code, _, err = _cli(args, monkeypatch, capsys)
    assert code == 2
    line = err.strip()
    assert "\n" not in line and str(csv) in line and "roll_deg" in line and "pitch_deg, yaw_deg" in line, err


def test_simulate_names_a_turned_pose_a_leg_cannot_reach(monkeypatch, capsys, tmp_path):
    csv = tmp_path / "poses.csv"
    csv.write_text("x,y,z,roll_deg,pitch_deg,yaw_deg\n0,0,300,0,0,0\n0,0,300,0,0,90\n")
    args = ["simulate", tmp_path / "o", "--robot", "hexapod", "--truth-only", "--positions", csv]
    code, _, err = _cli(args, monkeypatch, capsys)
    assert code == 2, err
    line = err.strip()
    assert "\n" not in line and line.startswith(
        f"error: {csv}: position 2 (0, 0, 300) mm, roll/pitch/yaw 0, 0, 90"
    )
    assert "leg 2 (leg2)" in line and "beyond its limits [260, 440] mm" in line


@pytest.mark.slow  # 5-15 s: the model at 225 poses, the example report
def test_report_orientation_map_is_the_models_hung_K_over_roll_and_pitch(hexapod):
    # Two orientations measured at (0, 0, 300), one elsewhere: the map is at (0, 0, 300); each
    # grid value is the smallest eigenvalue of the hung forces' K (and of K_rot) computed here.
    from stiffmap.campaign.platform import hung_force_stiffness as hung
    from stiffmap.report import data as rd
    from stiffmap.report.example import example_vision
    from stiffmap.report.html import build_html
    from stiffmap.report.orientations import map_poses, orientation_map, shared_orientation
    from stiffmap.report.static_figures import orientation_figure

    poses = [
        [0.0, 0.0, 300.0, 4.0, -2.0, 1.0],
        [0.0, 0.0, 300.0, -6.0, 12.0, 1.0],
        [20.0, 0.0, 300.0, 0, 0, 0],
    ]
    spec = parse_spec(
        _spec_text(LEGS, f"poses = {poses}").replace("[loads]", "[loads]\npoint_mm = [0.0, 0.0, -100.0]")
    )
    np.testing.assert_array_equal(shared_orientation(spec), [0.0, 0.0, 0.0])  # not shared: level
    np.testing.assert_array_equal(map_poses(spec, [[1.0, 2.0, 3.0]]), [[1.0, 2.0, 3.0, 0.0, 0.0, 0.0]])
    measured = np.array([5.0, np.nan, 6.0])
    om = orientation_map(hexapod, spec, np.array(poses)[:, :3], [1, 2, 3], measured)
    np.testing.assert_array_equal(om.position, [0.0, 0.0, 300.0])
    np.testing.assert_allclose(om.measured_rpy_deg, np.array(poses)[:2, 3:], rtol=1e-12)
    np.testing.assert_array_equal(om.measured_min_principal, [5.0, np.nan])
    assert om.roll_deg[0] == -10.0 and om.pitch_deg[-1] == pytest.approx(12.0) == om.yaw_deg * 12
    for j, i in ((0, 0), (7, 11), (14, 14)):
        pose = np.r_[0.0, 0.0, 300.0, np.radians([om.roll_deg[i], om.pitch_deg[j], 1.0])]
        K6 = hexapod.stiffness6(pose)
        K = hung(K6, [0.0, 0.0, -100.0])
        kt = np.linalg.eigvalsh(0.5 * (K + K.T))[0]
        C = np.linalg.inv(K6)
        kr = np.linalg.eigvalsh(np.linalg.inv(C[3:, 3:]))[0]
        np.testing.assert_allclose(om.min_principal[j, i], kt, rtol=1e-9)
        np.testing.assert_allclose(om.min_principal_rot[j, i], kr, rtol=1e-9)
    # Through the report's data contract: a JSON round trip, both figures.
    ex = example_vision()
    model = replace(ex.model, orientations=om)
    data = replace(ex, model=model)
    again = rd.ReportData.from_dict(json.loads(json.dumps(data.to_dict())))
    np.testing.assert_array_equal(again.model.orientations.min_principal, om.min_principal)
    assert orientation_figure(data) is not None and "fig-orientations" in build_html(data)
    assert orientation_figure(ex) is None  # no platform that turns: no such figure


@pytest.mark.long
def test_turned_hexapod_campaign_recovers_K6_and_its_legs_and_reports_them(monkeypatch, capsys, tmp_path):
    # simulate then run then report, three turned poses, one repeat: every K6 within 2 % (relative
    # Frobenius, rad as L mm) at its pose, the six legs within 1 %; the report maps over orientations.
    from stiffmap.kinds.parallel import HEXAPOD_TESTBED_K

    csv = tmp_path / "poses.csv"
    rows = [
        [0.0, 0.0, 300.0, 8.0, -6.0, 0.0],
        [0.0, 0.0, 300.0, -5.0, 10.0, 0.0],
        [40.0, -40.0, 280.0, 0, 5, 0],
    ]
    csv.write_text(
        "x,y,z,roll_deg,pitch_deg,yaw_deg\n" + "\n".join(",".join(map(str, r)) for r in rows) + "\n"
    )
    out = tmp_path / "hex"
    args = ["simulate", out, "--robot", "hexapod", "--positions", csv, "--repeats", "1", "--workers", "2"]
    code, _, err = _cli(args, monkeypatch, capsys)
    assert code == 0, err
    fit, model = run_and_fit(out, monkeypatch, capsys)
    # The extra noise the fit estimated is stored with it (model_fit.info) and on the report.
    assert len(fit.info) == 1 and "an extra noise was estimated" in fit.info[0], fit.info
    for i, k in enumerate(HEXAPOD_TESTBED_K, start=1):
        assert abs(fit.params[f"k_leg{i}"] - k) < 0.01 * k, (i, fit.params)
    truth = json.loads((out / "truth.json").read_text())
    for p, r in zip(truth["positions"], rows, strict=True):
        K6 = model.stiffness6(np.r_[r[:3], np.radians(r[3:])])
        assert k6_error(K6, p["K_tcp"], model.length_mm) < 0.02
    code, _, err = _cli(["report", out], monkeypatch, capsys)
    assert code in (0, 1), err
    page = (out / "report" / "index.html").read_text()
    assert "fig-orientations" in page
    assert f"<p class=note>Fit: {html.escape(fit.info[0])}</p>" in page
    assert (out / "report" / "model_over_orientations.png").is_file()
