"""Serial robots from URDF with joint springs (stiffmap.models.serial), their files and commands."""

from __future__ import annotations

import json
import math
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
from helpers import urdf_reference as ref
from helpers.cli_process import run_in_process as _cli
from scipy.spatial.transform import Rotation

from stiffmap.errors import InputError
from stiffmap.models.base import Mechanism
from stiffmap.models.fit import fit_stiffness
from stiffmap.models.io import read_configurations
from stiffmap.models.serial import SerialRobot

ARM6 = str(files("stiffmap.models") / "robots" / "arm6.urdf")
K_ARM = (2.0e9, 1.5e9, 1.0e9, 3.0e8, 2.5e8, 2.0e8)  # N*mm/rad: 2000 ... 200 N*m/rad
OFFSET = (30.0, -20.0, 120.0)  # mm in tool0: off the wrist axes, so every joint moves the point
L1, L2 = 400.0, 300.0  # mm, the planar arm's links

PLANAR_URDF = f"""<?xml version="1.0"?>
<robot name="planar2">
  <link name="base"/><link name="upper"/><link name="fore"/><link name="hand"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/><axis xyz="0 0 1"/>
    <limit lower="-3.14" upper="3.14" effort="1" velocity="1"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="upper"/><child link="fore"/><origin xyz="{L1 / 1000} 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3.14" upper="3.14" effort="1" velocity="1"/>
  </joint>
  <joint name="wrist_mount" type="fixed">
    <parent link="fore"/><child link="hand"/><origin xyz="{L2 / 1000} 0 0"/>
  </joint>
</robot>
"""


def _good_configurations(rng, m: int) -> np.ndarray:
    """Random arm6 configurations away from its singularities (elbow bent, wrist not straight), rad."""
    lo = np.radians([-150, -30, -60, -120, 25, -150])
    hi = np.radians([150, 60, 20, 120, 90, 150])
    Q = rng.uniform(lo, hi, size=(m, 6))
    Q[:, 4] *= rng.choice([-1.0, 1.0], m)
    return Q


def _arm(**kw) -> SerialRobot:
    return SerialRobot.from_urdf(ARM6, "tool0", OFFSET, k_theta=K_ARM, **kw)


def test_planar_two_link_arm_matches_the_closed_form(tmp_path, rng):
    """C6[:2, :2]^-1 = J^-T K_theta J^-1 with the textbook 2x2 Jacobian, to 1e-9 relative."""
    urdf = tmp_path / "planar2.urdf"
    urdf.write_text(PLANAR_URDF)
    for _ in range(5):
        k = rng.uniform(1e7, 1e9, 2)
        robot = SerialRobot.from_urdf(urdf, "hand", k_theta=k)
        assert isinstance(robot, Mechanism) and robot.param_names() == ("k1", "k2")
        q1, q2 = rng.uniform(-3.0, 3.0), rng.choice([-1, 1]) * rng.uniform(0.3, 2.8)
        s1, c1, s12, c12 = math.sin(q1), math.cos(q1), math.sin(q1 + q2), math.cos(q1 + q2)
        J = np.array([[-L1 * s1 - L2 * s12, -L2 * s12], [L1 * c1 + L2 * c12, L2 * c12]])
        Jinv = np.linalg.inv(J)
        K_closed = Jinv.T @ np.diag(k) @ Jinv
        K = np.linalg.inv(robot.compliance6([q1, q2])[:2, :2])
        assert np.linalg.norm(K - K_closed) / np.linalg.norm(K_closed) < 1e-9
        np.testing.assert_allclose(
            robot.chain.forward([q1, q2])[0], [L1 * c1 + L2 * c12, L1 * s1 + L2 * s12, 0]
        )
    # Its joints cannot move the point along z: no 3x3 K there (a joint-spring model is rigid along z).
    m = robot.evaluate_configurations([[0.3, 1.0]])
    assert not m.valid[0] and "cannot move the point along (0, 0, 1)" in m.reasons[0]
    with pytest.raises(InputError, match=r"planar2\.urdf: singular: the joints cannot move the point"):
        robot.stiffness3([0.3, 1.0])


def test_arm_stiffness_and_compliance_identities(rng):
    """K6 C6 = I; K6 = J^-T K_theta J^-1; K = C6[:3,:3]^-1 = the Schur complement of K6's rotation block."""
    robot = _arm()
    Q = _good_configurations(rng, 6)
    C = robot.compliance6(Q)
    K6 = robot.stiffness6(Q)
    K3 = robot.stiffness3(Q)
    for i, q in enumerate(Q):
        np.testing.assert_allclose(K6[i] @ C[i], np.eye(6), atol=1e-9)
        J = robot.chain.jacobian(q)
        Jinv = np.linalg.inv(J)
        K6_closed = Jinv.T @ np.diag(K_ARM) @ Jinv
        assert np.linalg.norm(K6[i] - K6_closed) / np.linalg.norm(K6_closed) < 1e-9
        np.testing.assert_allclose(K3[i], np.linalg.inv(C[i][:3, :3]), rtol=1e-9)
        schur = K6[i][:3, :3] - K6[i][:3, 3:] @ np.linalg.solve(K6[i][3:, 3:], K6[i][3:, :3])
        assert np.linalg.norm(K3[i] - schur) / np.linalg.norm(K3[i]) < 1e-8
        # One configuration at a time gives the same as the stack.
        np.testing.assert_allclose(robot.compliance6(q), C[i], rtol=1e-14)
    # The map over the configurations' points holds the same K, and it is symmetric positive definite.
    m = robot.evaluate_configurations(Q)
    assert m.valid.all() and np.all(m.eigenvalues > 0)
    np.testing.assert_allclose(m.K, K3, rtol=1e-12)


def test_deflection_matches_the_joints_turned_by_their_torques(rng):
    """d = C6 w against FK(q + dq) with dq = K_theta^-1 J^T w (central, first order), for a small wrench."""
    robot = _arm()
    for q in _good_configurations(rng, 4):
        w = np.concatenate([rng.normal(0, 50, 3), rng.normal(0, 5e3, 3)])  # N, N*mm
        d = robot.deflection(q, w)
        dq = (robot.chain.jacobian(q).T @ w) / np.asarray(K_ARM)
        pp, Rp = robot.chain.forward(q + dq)
        pm, Rm = robot.chain.forward(q - dq)
        d_fd = np.concatenate([(pp - pm) / 2, Rotation.from_matrix(Rp @ Rm.T).as_rotvec() / 2])
        assert np.abs(dq).max() < 1e-4  # a small load: second-order terms are ~1e-8 of d
        np.testing.assert_allclose(d[:3], d_fd[:3], rtol=1e-6, atol=1e-9 * np.abs(d[:3]).max())
        np.testing.assert_allclose(d[3:], d_fd[3:], rtol=1e-6, atol=1e-9 * np.abs(d[3:]).max())
        # The static error of a pure force is K^-1 F through the position interface too.
        p = robot.chain.forward(q)[0]
        r = _arm(configurations=q[None])
        np.testing.assert_allclose(r.static_error(p, w[:3]), robot.deflection(q, [*w[:3], 0, 0, 0])[:3])


def test_wrist_singularity_is_flagged_with_the_joints_named(rng):
    robot = _arm()
    q = np.radians([10.0, 20.0, -30.0, 15.0, 0.0, 40.0])
    m = robot.evaluate_configurations(
        np.array([q, q + np.radians([0, 0, 0, 0, 1e-2, 0]), q + np.radians([0, 0, 0, 0, 5, 0])])
    )
    assert m.valid.tolist() == [False, False, True]
    for reason in m.reasons[:2]:
        assert reason.startswith(
            "singular: joints joint_4 and joint_6 move the tip alike (wrist singularity)"
        )
        assert "inverse condition" in reason and "< 0.001" in reason
    assert np.isnan(m.K[0]).all() and m.conditioning[0] < 1e-12 and m.conditioning[2] > 1e-3
    with pytest.raises(
        InputError, match=r"arm6\.urdf: singular: joints joint_4 and joint_6 move the tip alike"
    ):
        robot.stiffness6(q)
    # The force stiffness exists there (the point, off the wrist axis, still moves every way).
    assert np.all(np.linalg.eigvalsh(robot.stiffness3(q)) > 0)
    # Elbow stretched (upper arm and forearm aligned: q3 = -90 deg): the point loses the arm's direction.
    stretched = robot.evaluate_configurations(np.radians([0.0, 20.0, -90.0, 0.0, 45.0, 0.0]))
    assert "singular: " in stretched.reasons[0] and "joint_2" in stretched.reasons[0]


def test_configurations_for_round_trip_and_inverse_kinematics(rng):
    Q = _good_configurations(rng, 3)
    robot = _arm(configurations=Q)
    P, R = robot.chain.forward_many(Q)
    ik = robot.configurations_for(P + 1e-4)  # written with 6 significant digits, say
    assert ik.reachable.all()
    np.testing.assert_array_equal(ik.q, Q)
    # A new point: inverse kinematics from the nearest configuration, holding its orientation.
    target = P[1] + [15.0, -10.0, 20.0]
    sol = robot.configurations_for(target)
    assert sol.reachable[0], sol.reasons
    p, Rq = robot.chain.forward(sol.q[0])
    np.testing.assert_allclose(p, target, atol=1e-6)
    np.testing.assert_allclose(Rq, R[1], atol=1e-9)
    m = robot.evaluate(np.vstack([P, target, [5000.0, 0.0, 0.0]]))
    assert m.valid.tolist() == [True, True, True, True, False]
    np.testing.assert_allclose(m.K[:3], robot.stiffness3(Q), rtol=1e-12)
    assert m.reasons[4].startswith("unreachable: inverse kinematics from configuration")
    # A configuration beyond its joint limits is named, as is a position two configurations share.
    beyond = robot.evaluate_configurations(np.radians([0.0, 150.0, -30.0, 0.0, 45.0, 0.0]))
    assert "unreachable: joint joint_2 at 150 deg beyond its limits" in beyond.reasons[0]
    twin = Q[0].copy()
    twin[5] += 2 * math.pi  # same pose, another joint-6 turn
    amb = _arm(configurations=np.vstack([Q, twin])).configurations_for(P[0])
    assert not amb.reachable[0] and "configurations 1 and 4 both put the point here" in amb.reasons[0]


def test_parameters_by_name_and_a_fit_recovers_them(rng):
    Q = _good_configurations(rng, 8)
    robot = _arm(configurations=Q)
    assert robot.params() == {f"k{i + 1}": k for i, k in enumerate(K_ARM)}
    assert robot.with_params(k3=7e8).k_theta == (*K_ARM[:2], 7e8, *K_ARM[3:])
    assert robot.with_params(k_theta=5e8, k2=6e8).k_theta == (5e8, 6e8, 5e8, 5e8, 5e8, 5e8)
    with pytest.raises(
        ValueError, match=r"unknown urdf parameter\(s\) kk; valid: k1, k2, k3, k4, k5, k6, k_theta"
    ):
        robot.with_params(kk=1.0)
    with pytest.raises(ValueError, match=r"k2 \(joint_2\) must be a positive number \(or inf for rigid\)"):
        robot.with_params(k2=-1.0)
    with pytest.raises(InputError, match=r"arm6\.urdf: k_theta has 5 value\(s\); stiffmap_arm6 has 6 joints"):
        SerialRobot.from_urdf(ARM6, "tool0", k_theta=K_ARM[:5])
    # A rigid joint: no compliance of its own; K6 needs six compliant joints.
    rigid = robot.with_params(k6=math.inf)
    J = robot.chain.jacobian(Q[0])
    C5 = J[:, :5] @ np.diag(1 / np.asarray(K_ARM[:5])) @ J[:, :5].T
    np.testing.assert_allclose(rigid.compliance6(Q[0]), C5, rtol=1e-12, atol=1e-15 * np.abs(C5).max())
    with pytest.raises(InputError, match="K6 needs six compliant joints"):
        rigid.stiffness6(Q[0])
    # Finite but absurdly stiff joints (a fit running away): flagged, not inverted into noise.
    stiff = robot.with_params(k_theta=[1e9, 1e9, 1e300, 1e300, 1e300, 1e300])
    m = stiff.evaluate_configurations(Q[:2])
    assert not m.valid.any() and "leave the point almost rigid along" in m.reasons[0]
    with pytest.raises(InputError, match="leave the point almost rigid"):
        stiff.stiffness3(Q[0])
    # Fitting k1..k6 to exact matrices at the configurations' points (the generic fit) finds them.
    P = robot.chain.forward_many(Q)[0]
    start = robot.with_params(
        k_theta=[v * f for v, f in zip(K_ARM, (0.6, 1.5, 0.7, 1.4, 0.8, 1.3), strict=True)]
    )
    f = fit_stiffness(start, P, robot.stiffness(P), params=[f"k{i}" for i in range(1, 7)])
    np.testing.assert_allclose(f.estimate, K_ARM, rtol=1e-6)


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg\n0,0,0,0,0\n",
            "has q1_deg..q5_deg; stiffmap_arm6 has 6 joints "
            "(joint_1, joint_2, joint_3, joint_4, joint_5, joint_6): expected q1_deg..q6_deg",
        ),
        ("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg\n0,0,0,0,0,0,0\n", "has q1_deg..q7_deg"),
        (
            "q1_deg,q2_mm,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0,0\n",
            "(joint 2, joint_2, is revolute: its column is q2_deg, degrees)",
        ),
        (
            "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,x,0\n",
            "line 2, column 'q5_deg': 'x' is not a number",
        ),
        ("", "empty file; expected a header with columns q1_deg..q6_deg"),
        ("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n", "no data rows after the header"),
    ],
)
def test_configurations_file_errors_name_the_file_and_the_item(tmp_path, text, message):
    f = tmp_path / "CONFIGS.csv"
    f.write_text(text)
    chain = _arm().chain
    with pytest.raises(InputError) as e:
        read_configurations(f, chain)
    assert str(e.value).startswith(f"{f}: ") and message in str(e.value)


def test_configurations_file_in_degrees_and_mm(tmp_path):
    f = tmp_path / "c.csv"
    f.write_text(
        "# measured 2026-05\nlabel,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\nA,90,0,-30,0,45,-180\n"
    )
    np.testing.assert_allclose(read_configurations(f, _arm().chain), [np.radians([90, 0, -30, 0, 45, -180])])


def _write_configs(path, Q_deg) -> None:
    rows = [
        "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg",
        *(",".join(repr(float(v)) for v in q) for q in Q_deg),
    ]
    path.write_text("\n".join(rows) + "\n")


def test_model_urdf_json_per_configuration(tmp_path, monkeypatch, capsys):
    Q_deg = np.array(
        [[10.0, 20.0, -30.0, 15.0, 50.0, 40.0], [-40, 10, -50, -30, -60, 0], [0, 0, -30, 0, 0, 0]]
    )
    cfg = tmp_path / "configs.csv"
    _write_configs(cfg, Q_deg)
    k = ",".join(f"{v:g}" for v in K_ARM)
    args = ["model", "urdf", ARM6, "--tip", "tool0", "--tip-offset-mm", "30,-20,120", "--configs", cfg]
    code, out, err = _cli([*args, "--param", f"k_theta={k}", "--json"], monkeypatch, capsys)
    # The third is a wrist singularity: K given (the point still moves every way), K6 not.
    assert code == 0 and "note: 1 of 3 configuration(s) at a joint singularity: K given" in err, err
    recs = json.loads(out)
    robot = _arm()
    Q = np.radians(Q_deg[:2])
    for r, q, qd in zip(recs[:2], Q, Q_deg[:2], strict=True):
        assert set(r) == {"q_deg", "position", "K", "K6"}
        np.testing.assert_allclose(r["q_deg"], qd, rtol=1e-12)
        np.testing.assert_allclose(r["position"], robot.chain.forward(q)[0], rtol=1e-12)
        np.testing.assert_allclose(r["K"], robot.stiffness3(q), rtol=1e-12)
        np.testing.assert_allclose(r["K6"], robot.stiffness6(q), rtol=1e-12)
    assert set(recs[2]) == {"q_deg", "position", "K", "K6", "note"} and recs[2]["K6"] is None
    q2 = np.radians(Q_deg[2])
    np.testing.assert_allclose(recs[2]["position"], robot.chain.forward(q2)[0], rtol=1e-12)
    # K = (J K^-1 J^T)[:3, :3]^-1 computed here from the Jacobian: it exists at the wrist singularity
    J = robot.chain.jacobian(q2)
    C = J @ np.diag(1.0 / np.asarray(K_ARM)) @ J.T
    np.testing.assert_allclose(recs[2]["K"], np.linalg.inv(C[:3, :3]), rtol=1e-9)
    assert recs[2]["note"].startswith(
        f"{cfg} line 4: singular: joints joint_4 and joint_6 move the tip alike"
    )
    # The table: the tip positions and principal stiffnesses; k3 alone changes joint 3's spring.
    code, out, err = _cli([*args, "--param", f"k_theta={k}", "--param", "k3=5e8"], monkeypatch, capsys)
    flat = "".join(out.split())  # rich wraps the header at the terminal's width
    # (the singular configuration's reason is in the table too, folded to the terminal's width)
    assert code == 0 and "k_theta=(2e+09,1.5e+09,5e+08,3e+08" in flat and "Konly:singular:" in flat


def test_fit_urdf_recovers_joint_stiffnesses_from_a_matrices_file(tmp_path, monkeypatch, capsys, rng):
    Q = _good_configurations(rng, 6)
    cfg = tmp_path / "configs.csv"
    _write_configs(cfg, np.degrees(Q))
    robot = _arm(configurations=Q)
    m = robot.evaluate_configurations(Q)
    rows = ["x,y,z," + ",".join(f"k{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3))]
    rows += [",".join(f"{v:.6g}" for v in (*p, *K.ravel())) for p, K in zip(m.points, m.K, strict=True)]
    meas = tmp_path / "meas.csv"
    meas.write_text("\n".join(rows) + "\n")
    args = ["fit", "urdf", ARM6, meas, "--tip", "tool0", "--tip-offset-mm", "30,-20,120", "--configs", cfg]
    # k6 is weakly felt here (the point is 36 mm off its axis): fixed at its value, k1..k5 fitted.
    fixed = ["--param", "k_theta=1e9", "--param", "k6=2e8", "--param-to-fit", "k1,k2,k3,k4,k5"]
    code, out, err = _cli([*args, *fixed, "--json"], monkeypatch, capsys)
    assert code == 0, err
    res = json.loads(out)
    est = [res["parameters"][f"k{i}"]["estimate"] for i in range(1, 6)]
    np.testing.assert_allclose(est, K_ARM[:5], rtol=1e-4)  # the file's 6 significant digits
    assert res["mechanism"] == "urdf" and res["n_poses"] == 6


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["--tip", "tool0", "--configs", "{cfg}"],
            "--param: give the stiffness of every joint of stiffmap_arm6: k1",
        ),
        (
            ["--tip", "tool0", "--configs", "{cfg}", "--param", "k_theta=1,2,3"],
            "--param: k_theta has 3 values; {urdf} (stiffmap_arm6) has 6 joints (joint_1",
        ),
        (
            ["--configs", "{cfg}", "--param", "k_theta=1e9"],
            "--tip is required for urdf: the link that carries the measured point",
        ),
        (
            ["--tip", "tool9", "--configs", "{cfg}", "--param", "k_theta=1e9"],
            "{urdf}: no frame 'tool9' for the measured point; the links are: base_link",
        ),
        (
            ["--tip", "tool0", "--configs", "{bad}", "--param", "k_theta=1e9"],
            "{bad}: the file has q1_deg..q5_deg; stiffmap_arm6 has 6 joints",
        ),
        (
            ["--tip", "tool0", "--configs", "{sing}", "--param", "k_theta=1e9"],
            "its stiffness there is infinite in a joint-spring model (translation measure",
        ),
    ],
)
def test_model_urdf_bad_input_is_one_line(tmp_path, monkeypatch, capsys, args, message):
    names = {"urdf": ARM6, "cfg": tmp_path / "c.csv", "bad": tmp_path / "c5.csv", "sing": tmp_path / "s.csv"}
    _write_configs(names["cfg"], [[10.0, 20.0, -30.0, 15.0, 50.0, 40.0]])
    names["bad"].write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg\n0,0,0,0,0\n")
    _write_configs(names["sing"], [[0.0, 20.0, -90.0, 0.0, 0.0, 0.0]])  # arm stretched to the tool: no K
    code, out, err = _cli(["model", "urdf", ARM6, *(a.format(**names) for a in args)], monkeypatch, capsys)
    assert code == 2 and err.startswith("error: ") and err.count("\n") == 1, err
    assert message.format(**names) in err


def test_urdf_arguments_are_refused_where_they_do_not_belong(tmp_path, monkeypatch, capsys):
    bad = tmp_path / "broken.urdf"
    bad.write_text("<robot name='x'><link name='a'/><joint")
    cases = [
        (
            ["model", "urdf", bad, "--tip", "a", "--configs", "c.csv", "--param", "k_theta=1"],
            "broken.urdf: not a valid XML",
        ),
        (["model", "urdf", "--tip", "a"], "urdf needs the robot's URDF file: stiffmap model urdf ROBOT.urdf"),
        (["model", "delta", ARM6], "a robot file is only for 'stiffmap model urdf ROBOT.urdf'"),
        (["model", "3prr", "--configs", "c.csv"], "--configs is for 'urdf'"),
        (
            ["fit", "urdf", ARM6, "--tip", "tool0"],
            "urdf takes two files, the robot's URDF then the measurements",
        ),
        (["fit", "delta", ARM6, "m.csv"], "delta takes one file, the measurements"),
    ]
    for args, message in cases:
        code, _, err = _cli(args, monkeypatch, capsys)
        assert code == 2 and err.count("\n") == 1 and message in err, (args, err)


def test_near_a_wrist_singularity_k_is_given_with_a_note(tmp_path, monkeypatch, capsys):
    """q5 = 0.3 deg: the joint measure (9e-4) is below singular_tol, the configuration flagged,
    but the point still moves every way: K is printed with the reason as a note and equals
    C = J K^-1 J^T of the URDF's numbers (helpers.urdf_reference: its own forward kinematics,
    central differences) inverted, there and at q5 = 0; K6 is null (within 1e-3 of the
    singularity it hangs on the Jacobian's last digits). Wrist springs 300 times the arm's
    make C6's raw principal values (mm/N beside rad/(N*mm)) span 2e13: the rigidity check
    compares them with rotations taken times L, so K6 stays where the measure allows it
    (q5 = 0.8 deg: raw span 3e12, refused whole as "almost rigid" before)."""
    k = np.array([2e7, 2e7, 1e7, 3e9, 3e9, 3e9])
    Q_deg = np.array([[10.0, 20.0, -30.0, 15.0, 0.3, 40.0], [0.0, 0.0, -30.0, 0.0, 0.0, 0.0]])
    cfg = tmp_path / "configs.csv"
    _write_configs(cfg, np.vstack([Q_deg, [[10.0, 20.0, -30.0, 15.0, 0.8, 40.0]]]))
    args = ["model", "urdf", ARM6, "--tip", "tool0", "--tip-offset-mm", "30,-20,120", "--configs", cfg]
    code, out, err = _cli(
        [*args, "--param", "k_theta=" + ",".join(map(str, k)), "--json"], monkeypatch, capsys
    )
    assert code == 0 and "note: 2 of 3 configuration(s) at a joint singularity: K given, K6 not" in err, err
    recs = json.loads(out)
    _, joints = ref.read_joints(Path(ARM6).read_text())
    chain = ref.path(joints, "tool0")
    coords = ref.coordinates(joints, chain)
    for rec, qd in zip(recs, [*Q_deg, [10.0, 20.0, -30.0, 15.0, 0.8, 40.0]], strict=True):
        _, K, K6, _ = ref.stiffness(joints, chain, coords, np.radians(qd), k, (30.0, -20.0, 120.0))
        assert _rel(rec["K"], K) < 1e-7
        if qd[4] < 0.5:
            assert "wrist singularity" in rec["note"] and rec["K6"] is None
        else:  # q5 = 0.8 deg (measure 2.5e-3): K6, C6's raw values spanning 3e12
            assert "note" not in rec and _rel(rec["K6"], K6) < 1e-6


def _rel(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def test_past_joint_singularity_gives_k_only_where_the_joints_alone_are_singular():
    # A wrist singularity (q5 = 0: joints 4 and 6 aligned): K = (J K^-1 J^T)[:3, :3]^-1 computed
    # here; a regular configuration and the arm stretched to tool0 (no K at all): None.
    robot = _arm()
    wrist = np.radians([0.0, 0.0, -30.0, 0.0, 0.0, 0.0])
    J = robot.chain.jacobian(wrist)
    C = J @ np.diag(1.0 / np.asarray(K_ARM)) @ J.T
    np.testing.assert_allclose(robot.past_joint_singularity(wrist), np.linalg.inv(C[:3, :3]), rtol=1e-9)
    assert robot.past_joint_singularity(np.radians([10.0, 20.0, -30.0, 15.0, 50.0, 40.0])) is None
    at_tool0 = SerialRobot.from_urdf(ARM6, "tool0", (0.0, 0.0, 0.0), k_theta=K_ARM)
    stretched = np.radians([0.0, 20.0, -90.0, 0.0, 0.0, 0.0])  # translation measure 5e-17 there
    assert at_tool0.past_joint_singularity(stretched) is None
