"""Files and grids of poses of a platform that turns (dim = 6): maps written, fitted back, refused."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from helpers.fuzz import mutated_text
from helpers.poses import rpy_matrix
from hypothesis import given
from hypothesis import strategies as st

from stiffmap.errors import InputError
from stiffmap.models import DeltaRobot
from stiffmap.models.io import fit_measurements_file, map_csv, map_records, read_measurements, read_points
from stiffmap.models.legs import LegRobot
from stiffmap.models.legs6 import gough_stewart_points, ups_legs
from stiffmap.models.legs_file import legs_text
from stiffmap.models.poses import orientations_from_text, poses_from

K_LEGS = np.array([420.0, 610.0, 380.0, 900.0, 505.0, 730.0])  # N/mm, six different legs
HOME = np.array([0.0, 0.0, 300.0])
_K33 = ",".join(f"k{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3))


def _closed_form(base, attach, k, pose) -> np.ndarray:
    """K6 = sum k_i a_i a_i^T, a_i = (n_i, r_i x n_i) (Gosselin), written here."""
    R = rpy_matrix(*pose[3:])
    K6 = np.zeros((6, 6))
    for b, a, ki in zip(base, attach, k, strict=True):
        r = R @ a
        d = pose[:3] + r - b
        n = d / np.linalg.norm(d)
        w = np.concatenate([n, np.cross(r, n)])
        K6 += ki * np.outer(w, w)
    return K6


@pytest.fixture(scope="module")
def hexapod():
    base, attach = gough_stewart_points(250.0, 150.0, 20.0, 100.0)
    names = tuple(f"k_leg{i}" for i in range(1, 7))
    legs = ups_legs(base, attach, HOME, names)
    text = legs_text("hex", 6, dict(zip(names, K_LEGS, strict=True)), legs, 1e-3)
    return LegRobot.from_toml_text(text, source="hex.toml"), base, attach


@pytest.fixture(scope="module")
def poses():
    """Shifted and turned poses, whole degrees (exact in a CSV)."""
    pos = HOME + np.array([[0.0, 0.0, 0.0], [25.0, -10.0, 15.0], [-20.0, 30.0, -25.0]])
    return poses_from(pos, orientations_from_text("-6:6:2,4,0:10:2"))


def test_orientations_from_text_spans_each_angle_roll_fastest():
    A = np.degrees(orientations_from_text("-10:10:3,5,0:30:2"))
    assert A.shape == (6, 3)
    np.testing.assert_allclose(A[:3, 0], [-10.0, 0.0, 10.0], atol=1e-12)
    np.testing.assert_allclose(A[:, 1], 5.0, atol=1e-12)
    np.testing.assert_allclose(A[:, 2], [0, 0, 0, 30, 30, 30], atol=1e-12)
    P = poses_from([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], np.radians([[0, 0, 0], [0, 0, 90.0]]))
    np.testing.assert_array_equal(P[:, 0], [1.0, 4.0, 1.0, 4.0])
    np.testing.assert_allclose(P[:, 5], [0, 0, math.pi / 2, math.pi / 2])


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("0,0", "expected roll,pitch,yaw"),
        ("0,x,0", "pitch: 'x' is not a number"),
        ("0,0,200", r"yaw: 200 deg is not within \+-180"),
        ("0:10,0,0", "roll: '0:10' is neither"),
        ("0:10:0,0,0", "roll: N = 0"),
        ("0:1:1000,0:1:1000,0", "1000000 orientations"),
    ],
)
def test_bad_orientations_are_named(text, message):
    with pytest.raises(ValueError, match=message):
        orientations_from_text(text)


def test_map_of_a_hexapod_gives_K6_and_the_wrenchs_displacement(hexapod, poses):
    robot, base, attach = hexapod
    m = robot.evaluate(poses)
    assert m.n_valid == len(poses)
    F, M = np.array([3.0, -5.0, 10.0]), np.array([400.0, -250.0, 900.0])
    recs = map_records(m, F, M)
    for p, rec in zip(poses, recs, strict=True):
        K6 = _closed_form(base, attach, K_LEGS, p)
        assert rec["roll_deg"] == pytest.approx(math.degrees(p[3]), abs=1e-9)
        np.testing.assert_allclose(rec["K6"], K6, rtol=1e-9, atol=1e-9 * np.abs(K6).max())
        d = np.linalg.solve(K6, np.concatenate([F, M]))
        got = [rec[c] for c in ("ux", "uy", "uz", "rx_rad", "ry_rad", "rz_rad")]
        np.testing.assert_allclose(got, d, rtol=1e-8, atol=1e-12)
        C = np.linalg.inv(K6)  # K: a pure force's (the platform free to turn); K_rot: a moment's
        np.testing.assert_allclose(rec["K"], np.linalg.inv(C[:3, :3]), rtol=1e-8)
        assert rec["min_principal_rot"] == pytest.approx(np.linalg.eigvalsh(np.linalg.inv(C[3:, 3:]))[0])
    with pytest.raises(ValueError, match="a moment needs a platform that turns"):
        map_records(DeltaRobot().evaluate([[0.0, 0.0, -300.0]]), [0, 0, -1.0], M)


def test_map_csv_is_a_K6_file_that_fits_back_to_the_legs(hexapod, poses, tmp_path):
    robot, _, _ = hexapod
    path = tmp_path / "k6.csv"
    path.write_text(map_csv(robot.evaluate(poses), [0.0, 0.0, -10.0]))
    data = read_measurements(path, 6)
    assert data.K.shape == (len(poses), 6, 6)
    np.testing.assert_allclose(data.points, poses, atol=1e-12)
    names = robot.param_names()
    start = robot.with_params(**dict.fromkeys(names, 1000.0))
    f, _ = fit_measurements_file(start, path, names)
    assert f.kind == "stiffness6"
    np.testing.assert_allclose(f.estimate, K_LEGS, rtol=1e-6)  # the CSV's 9 digits


def test_static_errors_at_poses_fit_back_to_the_legs(hexapod, poses, tmp_path):
    # A dial gauge along each axis under a 20 N force at the tool point, at each pose:
    # u = (K6^-1 (F, 0))[:3], the platform free to turn.
    robot, base, attach = hexapod
    rows = ["x,y,z,roll_deg,pitch_deg,yaw_deg,fx,fy,fz,nx,ny,nz,value_mm"]
    for p in poses[::3]:
        C = np.linalg.inv(_closed_form(base, attach, K_LEGS, p))
        for F in np.eye(3) * 20.0:
            u = C[:3, :3] @ F
            for n in np.eye(3):
                cells = [*p[:3], *np.degrees(p[3:]), *F, *n, u @ n]
                rows.append(",".join(f"{v:.12g}" for v in cells))
    path = tmp_path / "errors.csv"
    path.write_text("\n".join(rows) + "\n")
    names = robot.param_names()
    f, _ = fit_measurements_file(robot.with_params(**dict.fromkeys(names, 1000.0)), path, names)
    assert f.kind == "static_error"
    np.testing.assert_allclose(f.estimate, K_LEGS, rtol=1e-7)


@pytest.mark.parametrize(
    ("dim", "header", "message"),
    [
        (3, "x,y,z,roll_deg,pitch_deg,yaw_deg,k11", "a turning platform's"),
        (3, "x,y,z,k11,k33,k44,k55,k66", "'k44', 'k55', 'k66' are a turning platform's"),
        (6, "x,y,z,roll_deg," + _K33, "has roll_deg but not pitch_deg, yaw_deg"),
        (6, "x,y,z,k11,k22", "stop at k22.*or k11..k66"),
        (6, "x,y,z,a", "k11..k33 \\(or k11..k66: K6\\)"),
    ],
)
def test_measurement_files_of_the_wrong_kind_are_named(tmp_path, dim, header, message):
    path = tmp_path / "m.csv"
    n = len(header.split(","))
    path.write_text(header + "\n" + ",".join(["1"] * n) + "\n")
    with pytest.raises(InputError, match=message) as e:
        read_measurements(path, dim)
    assert str(path) in str(e.value)


def test_6dof_deflections_under_wrenches_fit_back_to_the_legs(hexapod, poses):
    # Nine loads hung at three points of the platform (20 N along x, y, -z at each): wrenches
    # (F, r x F) spanning all six directions; the deflections (u, rotation) = K6^-1 w.
    from stiffmap.models.fit import fit_deflections6

    robot, base, attach = hexapod
    P = poses[::2]
    pts = np.array([[0.0, 0.0, -80.0], [120.0, 0.0, -80.0], [0.0, 120.0, -80.0]])
    forces = 20.0 * np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]])
    rows, W, D = [], [], []
    for p in P:
        R, K6 = rpy_matrix(*p[3:]), _closed_form(base, attach, K_LEGS, p)
        for r in pts:
            for F in forces:
                w = np.concatenate([F, np.cross(R @ r, F)])
                rows.append(p)
                W.append(w)
                D.append(np.linalg.solve(K6, w))
    names = robot.param_names()
    start = robot.with_params(**dict.fromkeys(names, 1000.0))
    f = fit_deflections6(start, rows, W, D, params=names)
    assert f.kind == "deflection6"
    np.testing.assert_allclose(f.estimate, K_LEGS, rtol=1e-8)
    rng = np.random.default_rng(7)
    std = np.tile([2e-4, 2e-4, 2e-4, 5e-6, 5e-6, 5e-6], (len(D), 1))  # 0.2 um, 5 urad
    noisy = np.array(D) + std * rng.normal(size=std.shape)
    f = fit_deflections6(start, rows, W, noisy, params=names, std=std, absolute_sigma=True)
    assert np.all(np.abs(f.estimate - K_LEGS) < 4 * f.std), (f.estimate, f.std)
    assert np.all(f.std < 0.01 * K_LEGS)


_POSES_SEED = "x,y,z,roll_deg,pitch_deg,yaw_deg\n0,0,300,0,0,0\n10,-5,310,3,-2,8\n"
_K6_SEED = (
    "x,y,z,roll_deg,pitch_deg,yaw_deg,"
    + ",".join(f"k{i}{j}" for i in range(1, 7) for j in range(1, 7))
    + "\n0,0,300,0,0,5,"
    + ",".join("400" if i == j else "1" for i in range(6) for j in range(6))
    + "\n"
)


@pytest.mark.fuzz
@given(data=st.data())
def test_mutated_pose_and_K6_files_are_read_or_refused_by_name(data):
    # A malformed poses or K6 file is read as finite poses (rad within +-pi) and matrices, or
    # refused with an InputError naming the file; never another exception.
    kind = data.draw(st.sampled_from(["poses", "k6"]))
    raw = data.draw(mutated_text(_POSES_SEED if kind == "poses" else _K6_SEED))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "f.csv"
        path.write_bytes(raw)
        try:
            got = read_points(path, 6) if kind == "poses" else read_measurements(path, 6)
        except InputError as e:
            assert str(path) in str(e)
            return
    P = got if kind == "poses" else got.points
    assert P.shape[1] == 6 and np.all(np.isfinite(P)) and np.all(np.abs(P[:, 3:]) <= math.pi)
    if kind == "k6":
        assert got.K.shape[1:] in ((6, 6), (3, 3)) and np.all(np.isfinite(got.K))


@pytest.mark.fuzz
@given(text=st.text(alphabet="0123456789:,.-+e x", max_size=30))
def test_orientation_texts_give_angles_or_a_value_error(text):
    try:
        A = orientations_from_text(text)
    except ValueError:
        return
    assert A.ndim == 2 and A.shape[1] == 3 and np.all(np.abs(A) <= math.pi + 1e-12)
