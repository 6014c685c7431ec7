"""A platform's mobility from its legs and the poses it reaches (stiffmap.models.mobility)."""

from __future__ import annotations

import json
from importlib.resources import files

import numpy as np
import pytest
from helpers.cli_process import run_in_process
from helpers.poses import rps_pose, rpy_matrix

from stiffmap.models.legs import LegRobot
from stiffmap.models.legs6 import RPS3, rps_legs
from stiffmap.models.legs_file import legs_text
from stiffmap.models.mobility import held_as_given, platform_mobility, reachable_poses

ROBOTS = files("stiffmap.models") / "robots"


def _rps_geometry(angles_deg, base_r=RPS3["base_radius_mm"], plat_r=RPS3["platform_radius_mm"]):
    """Base revolute centres, their axes (tangent to the base circle) and the ball joints (platform frame)."""
    a = np.radians(angles_deg)
    e = np.stack([np.cos(a), np.sin(a), 0 * a], axis=1)
    return base_r * e, np.stack([-np.sin(a), np.cos(a), 0 * a], axis=1), plat_r * e


def _asymmetric_rps(tmp_path):
    """A 3-RPS whose legs stand at 90, 200 and 340 deg (not symmetric: its parasitic motion is not)."""
    base, axes, attach = _rps_geometry([90.0, 200.0, 340.0])
    ks, kb = ("k1", "k2", "k3"), ("b1", "b2", "b3")
    legs = rps_legs(base, axes, attach, (0.0, 0.0, 250.0), ks, kb, stroke_mm=(150.0, 400.0))
    path = tmp_path / "rps_asym.toml"
    params = {**dict.fromkeys(ks, 500.0), **dict.fromkeys(kb, 130.0)}
    path.write_text(legs_text("rps_asym", 6, params, legs, 1e-3, "an asymmetric 3-RPS"))
    return LegRobot.from_toml(path), (base, axes, attach)


def _plane_distances(pose, base, axes, attach) -> np.ndarray:
    """Each ball joint's distance from its leg's plane (through the revolute joint, normal to its axis)."""
    tips = pose[:3] + attach @ rpy_matrix(*pose[3:]).T
    return np.einsum("ij,ij->i", tips - base, axes)


@pytest.mark.parametrize("shape", ["shipped", "asymmetric"])
def test_3rps_moves_in_z_roll_pitch_and_its_solved_poses_close_every_leg(shape, tmp_path):
    if shape == "shipped":
        robot, geometry = LegRobot.from_toml(ROBOTS / "3rps.toml"), _rps_geometry([90.0, 210.0, 330.0])
    else:
        robot, geometry = _asymmetric_rps(tmp_path)
    mob = platform_mobility(robot)
    assert (mob.rank, mob.free, mob.follow) == (3, (2, 3, 4), (0, 1, 5))
    rng = np.random.default_rng(7)
    n = 6
    asked = np.c_[
        rng.uniform(-5, 5, (n, 2)),
        rng.uniform(230, 270, n),
        np.radians(rng.uniform(-10, 10, (n, 2))),
        np.radians(rng.uniform(-3, 3, n)),
    ]
    got, gap = reachable_poses(robot, asked, mob)
    np.testing.assert_array_equal(got[:, [2, 3, 4]], asked[:, [2, 3, 4]])  # the free ones as given
    assert np.all(gap < 1e-9)
    for p in got:
        # The independent check: every ball joint in its leg's plane (to 1e-9 mm), and the same
        # pose as a least-squares solve of those planes written in the test (helpers.poses).
        assert np.abs(_plane_distances(p, *geometry)).max() < 1e-9
        np.testing.assert_allclose(p, rps_pose(p[2], p[3], p[4], geometry[2], geometry[1]), atol=1e-8)
    assert robot.evaluate(got).valid.all()


def test_finite_differences_of_the_solved_poses_span_the_mobility_found():
    # At home (the platform level, Euler rates = angular velocity) the solved pose's derivative
    # in z, roll, pitch (central differences) is a twist the legs allow: the held wrenches do no
    # work on it, and the three span the mobility's basis. The held wrenches are the forces along
    # the revolute axes through the ball joints (a 3-RPS leg's one constraint), written here.
    robot = LegRobot.from_toml(ROBOTS / "3rps.toml")
    mob = platform_mobility(robot)
    L = robot.length_mm
    home = np.r_[robot.home()[0], 0.0, 0.0, 0.0]
    D = np.zeros((6, 3))
    for c, j in enumerate(mob.free):
        h = 1e-3 if j < 3 else 1e-5
        step = np.zeros(6)
        step[j] = h
        plus, _ = reachable_poses(robot, home + step, mob)
        minus, _ = reachable_poses(robot, home - step, mob)
        D[:, c] = (plus - minus) / (2 * h) * np.array([1, 1, 1, L, L, L]) / (1.0 if j < 3 else L)
    D /= np.linalg.norm(D, axis=0)
    assert np.abs(mob.held.T @ D).max() < 1e-6
    np.testing.assert_allclose(np.abs(np.linalg.svd(mob.twists.T @ D)[1]), 1.0, atol=1e-6)
    _, axes, attach = _rps_geometry([90.0, 210.0, 330.0])
    W = np.concatenate([axes, np.cross(attach, axes) / L], axis=1).T  # (f, (r - P) x f / L)
    assert np.linalg.matrix_rank(np.c_[W, mob.held], tol=1e-9) == 3 == mob.held.shape[1]
    assert np.abs(W.T @ mob.twists).max() < 1e-9


def test_a_hexapod_moves_in_all_six_coordinates_and_keeps_its_poses_bit_for_bit():
    robot = LegRobot.from_toml(ROBOTS / "hexapod.toml")
    mob = platform_mobility(robot)
    assert (mob.rank, mob.free, mob.follow, mob.held.shape) == (6, tuple(range(6)), (), (6, 0))
    asked = np.array([[12.5, -7.25, 290.0, 0.07, -0.11, 0.05], [0.0, 0.0, 300.0, 0.0, 0.0, 0.0]])
    got, gap = reachable_poses(robot, asked, mob)
    assert np.array_equal(got, asked) and np.all(gap == 0.0)
    assert held_as_given(robot, asked) is not None


def test_held_as_given_names_the_first_pose_a_3rps_cannot_hold_and_where_it_is():
    robot = LegRobot.from_toml(ROBOTS / "3rps.toml")
    level = np.array([[0.0, 0.0, 240.0, 0.0, 0.0, 0.0], [0.0, 0.0, 260.0, 0.0, 0.0, 0.0]])
    np.testing.assert_array_equal(held_as_given(robot, level), level)
    _, axes, attach = _rps_geometry([90.0, 210.0, 330.0])
    near = rps_pose(240.0, np.radians(5.0), 0.0, attach, axes)  # x and yaw 0 by symmetry
    with pytest.raises(ValueError) as e:
        held_as_given(robot, np.r_[level, [[0.0, 0.0, 240.0, np.radians(5.0), 0.0, 0.0]]])
    msg = str(e.value)
    assert msg.startswith(
        "3rps moves in z, roll, pitch: x, y, yaw follow: it cannot hold pose 3 (0, 0, 240) mm"
    )
    assert f"it holds (0, {round(near[1], 6):.12g}, 240) mm, roll/pitch/yaw (5, 0, 0) deg there" in msg


def test_held_as_given_names_no_pose_the_model_cannot_evaluate(monkeypatch, capsys):
    # Rolled 179 deg the 3-RPS's legs close at y = -100 mm (the platform's radius: its ball joint
    # under the base's revolute), but leg 1 would be 361 mm long, beyond its 360 mm stroke. The
    # grid refusal once said "it holds (0, -99.99, 250) mm ... there"; now the pose passes to the
    # evaluation, which names the leg and its stroke.
    robot = LegRobot.from_toml(ROBOTS / "3rps.toml")
    asked = np.array([[0.0, 0.0, 250.0, np.radians(179.0), 0.0, 0.0]])
    near, gap = reachable_poses(robot, asked[0])
    assert gap < 1e-9 and near[1] == pytest.approx(-99.99, abs=0.01)
    assert not robot.evaluate(near).valid[0]
    np.testing.assert_array_equal(held_as_given(robot, asked), asked)
    args = ["model", "legs", str(ROBOTS / "3rps.toml"), "--grid", "0,0,250", "--orientation", "179,0,0"]
    code, out, err = run_in_process([*args, "--json"], monkeypatch, capsys)
    assert code == 2 and "holds" not in err, err
    assert "joint stroke at 361" in json.loads(out)[0]["error"]


def test_model_legs_grid_of_a_3rps_held_as_given_or_refused_in_one_line(monkeypatch, capsys):
    # Level on its axis: held as given (two poses evaluated); tilted by --orientation: x, y and yaw
    # follow, so one line naming the pose and the one it holds.
    robot = str(ROBOTS / "3rps.toml")
    code, out, err = run_in_process(
        ["model", "legs", robot, "--grid", "0,0,240:260:2", "--json"], monkeypatch, capsys
    )
    assert code == 0, err
    assert [p["z"] for p in json.loads(out)] == [240.0, 260.0]
    args = ["model", "legs", robot, "--grid", "0,0,240", "--orientation", "0,-5:5:3,0"]
    code, _, err = run_in_process(args, monkeypatch, capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith(
        "error: --grid: 3rps moves in z, roll, pitch: x, y, yaw follow: it cannot hold pose 1 (0, 0, 240) "
        "mm, roll/pitch/yaw (0, -5, 0) deg as given (it holds ("
    )


def _numbers(text: str) -> list[float]:
    return [float(v) for v in text.split(", ")]


def test_the_pose_a_refusal_names_can_be_copied(monkeypatch, capsys, tmp_path):
    # The pose a --grid refusal names, written into a POSES.csv as printed, is evaluated (its
    # legs close): to 4 significant digits (0.2283, -0.1212, yaw -0.131 deg) they missed and the
    # model could not evaluate it.
    robot = str(ROBOTS / "3rps.toml")
    args = ["model", "legs", robot, "--grid", "0,0,240", "--orientation", "5,-3,0"]
    code, _, err = run_in_process(args, monkeypatch, capsys)
    held = err.split("(it holds (")[1]
    xyz, rpy = held.split(") mm, roll/pitch/yaw (")[0], held.split("roll/pitch/yaw (")[1].split(") deg")[0]
    csv = tmp_path / "poses.csv"
    csv.write_text(
        "x,y,z,roll_deg,pitch_deg,yaw_deg\n" + ",".join(map(repr, _numbers(xyz) + _numbers(rpy))) + "\n"
    )
    code, out, err = run_in_process(
        ["model", "legs", robot, "--points", str(csv), "--json"], monkeypatch, capsys
    )
    assert code == 0, err
    assert json.loads(out)[0]["yaw_deg"] == pytest.approx(-0.131013, abs=1e-6)


def test_model_legs_points_a_3rps_cannot_hold_name_the_nearest_pose_it_holds(tmp_path, monkeypatch, capsys):
    # A point off the axis with the platform level: unreachable (the legs named in the table), and
    # one note giving the pose the legs reach with the same z, roll, pitch (the independent solver).
    _, axes, attach = _rps_geometry([90.0, 210.0, 330.0])
    near = rps_pose(250.0, np.radians(4.0), 0.0, attach, axes)
    csv = tmp_path / "poses.csv"
    csv.write_text("x,y,z,roll_deg,pitch_deg,yaw_deg\n0,0,250,0,0,0\n10,0,250,4,0,0\n")
    args = ["model", "legs", str(ROBOTS / "3rps.toml"), "--points", str(csv)]
    code, _, err = run_in_process(args, monkeypatch, capsys)
    assert code == 1, err
    xyz = ", ".join(f"{v:.12g}" for v in np.round(near[:3], 6) + 0.0)  # to 1e-6 mm and deg
    deg = ", ".join(f"{v:.12g}" for v in np.round(np.degrees(near[3:]), 6) + 0.0)
    assert (
        f"note: pose 2: 3rps moves in z, roll, pitch: x, y, yaw follow: the nearest pose it holds is "
        f"({xyz}) mm, roll/pitch/yaw ({deg}) deg\n" in err
    )
    assert err.endswith(f"warning: 1 of 2 point(s) cannot be evaluated (see 'error'); points from {csv}\n")
