"""Parallel robots whose platform turns (dim = 6): the 6-D assembly, hexapods, the 3-RPS."""

from __future__ import annotations

import itertools
import json
import math
import tempfile
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
from helpers.frame_fe import beam_global, condensed, rps_leg_platform_stiffness
from helpers.fuzz_campaign import mutated_spec, toml_text_mutations
from helpers.poses import rps_pose, rpy_matrix
from hypothesis import given
from hypothesis import strategies as st

from stiffmap.errors import InputError
from stiffmap.models import PRR3, DeltaRobot, Mechanism, PoseError
from stiffmap.models.base import arm_map, as_points, platform_stiffness6
from stiffmap.models.fit import fit_stiffness
from stiffmap.models.io import read_points
from stiffmap.models.legs import LegRobot
from stiffmap.models.legs6 import (
    RPS3,
    LegRobot6,
    gough_stewart_points,
    hexapod_toml,
    rps3_toml,
    ups_legs,
)
from stiffmap.models.legs_file import LegDescription, LegJoint, legs_text

ROBOTS = files("stiffmap.models") / "robots"
BEFORE = Path(__file__).with_name("data") / "legs_before_6d.json"


# ---------------------------------------------------------------------- written here, not from stiffmap


def _rpy(R: np.ndarray) -> tuple[float, float, float]:
    """The inverse of :func:`rpy_matrix` away from pitch = +-90 deg."""
    return math.atan2(R[2, 1], R[2, 2]), -math.asin(R[2, 0]), math.atan2(R[1, 0], R[0, 0])


def _exp(theta) -> np.ndarray:
    """Rodrigues: the rotation of rotation vector theta (rad)."""
    t = np.asarray(theta, dtype=float)
    a = float(np.linalg.norm(t))
    if a == 0:
        return np.eye(3)
    k = t / a
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(a) * Kx + (1 - math.cos(a)) * Kx @ Kx


def _closed_form_ups(base, attach, k, pose) -> np.ndarray:
    """Gosselin's K6 = sum k_i a_i a_i^T, a_i = (n_i, r_i x n_i): springs along the legs' lines."""
    R = rpy_matrix(*pose[3:])
    K6 = np.zeros((6, 6))
    for b, a, ki in zip(base, attach, k, strict=True):
        r = R @ a
        d = pose[:3] + r - b
        n = d / np.linalg.norm(d)
        w = np.concatenate([n, np.cross(r, n)])
        K6 += ki * np.outer(w, w)
    return K6


def _relative(A, B, length_mm: float | None = None) -> float:
    """Relative Frobenius distance; for 6 x 6 stiffnesses with ``length_mm``, of ``D A D`` with
    D = diag(1, 1, 1, 1/L, 1/L, 1/L) (rad as L mm), so that no block drowns the others."""
    if length_mm is not None:
        d = np.array([1.0, 1.0, 1.0, *(3 * [1.0 / length_mm])])
        A, B = A * d[:, None] * d[None, :], B * d[:, None] * d[None, :]
    return float(np.linalg.norm(A - B) / np.linalg.norm(B))


def _robot(legs, params: dict, name: str = "test") -> LegRobot6:
    r = LegRobot.from_toml_text(legs_text(name, 6, params, tuple(legs), 1e-3), source=f"{name}.toml")
    assert isinstance(r, LegRobot6)
    return r


def _hexapod(rb, rp, pair_b, pair_p, h, k):
    base, attach = gough_stewart_points(rb, rp, pair_b, pair_p)
    names = tuple(f"k{i}" for i in range(1, 7))
    robot = _robot(ups_legs(base, attach, (0.0, 0.0, h), names), dict(zip(names, k, strict=True)))
    return robot, base, attach


@pytest.fixture(scope="module")
def hexapods():
    rng = np.random.default_rng(3030)
    out = []
    for rb, rp, pb, pp, h in ((250.0, 150.0, 20.0, 100.0, 300.0), (400.0, 180.0, 30.0, 80.0, 450.0)):
        k = rng.uniform(200.0, 5000.0, size=6)  # legs of different axial stiffness
        out.append((*_hexapod(rb, rp, pb, pp, h, k), k, h))
    return out


# ---------------------------------------------------------------------- the hexapod: closed forms


def test_hexapod_K6_is_the_sum_over_its_legs_lines(hexapods):
    rng = np.random.default_rng(7)
    for robot, base, attach, k, h in hexapods:
        assert isinstance(robot, Mechanism) and robot.dim == 6
        poses = np.zeros((5, 6))
        poses[:, :3] = [0.0, 0.0, h] + rng.uniform(-40.0, 40.0, size=(5, 3))  # shifted
        poses[:, 3:] = np.radians(rng.uniform(-12.0, 12.0, size=(5, 3)))  # and turned
        poses[0] = [0.0, 0.0, h, 0.0, 0.0, 0.0]
        m = robot.evaluate(poses)
        assert m.valid.all(), m.reasons
        for i, p in enumerate(poses):
            K6 = _closed_form_ups(base, attach, k, p)
            assert _relative(m.K6[i], K6) < 1e-9 and _relative(m.K6[i], K6, h) < 1e-9
            C6 = np.linalg.inv(K6)
            assert _relative(m.K[i], np.linalg.inv(C6[:3, :3])) < 1e-9  # a pure force's K
            assert _relative(m.K_rot[i], np.linalg.inv(C6[3:, 3:])) < 1e-9
            lengths = np.linalg.norm(p[:3] + attach @ rpy_matrix(*p[3:]).T - base, axis=1)
            np.testing.assert_allclose(m.q[i], lengths, rtol=0, atol=1e-7)  # the legs' lengths, mm
            w = np.array([10.0, -20.0, 30.0, 800.0, -500.0, 1200.0])  # N, N*mm
            np.testing.assert_allclose(robot.static_error6(p, w), C6 @ w, rtol=1e-9, atol=1e-14)
            np.testing.assert_allclose(
                robot.static_error(p, w[:3]), C6[:3, :3] @ w[:3], rtol=1e-9, atol=1e-14
            )


def _cube_legs(a: float, centre):
    """The cubic hexapod: six legs along the edges of a cube of side a not meeting the
    diagonal's ends, the diagonal along z, the cube's centre at ``centre`` (base frame)."""
    z = np.ones(3) / math.sqrt(3)
    x = np.array([1.0, -1.0, 0.0]) / math.sqrt(2)
    Rc = np.stack([x, np.cross(z, x), z])  # cube axes to base axes: rows
    V = np.array(list(itertools.product((-0.5, 0.5), repeat=3))) * a
    base, attach = [], []
    for i, j in itertools.combinations(range(8), 2):
        if np.count_nonzero(V[i] != V[j]) != 1:
            continue  # not an edge
        if any(abs(abs(V[m].sum()) - 1.5 * a) < 1e-9 for m in (i, j)):
            continue  # meets an end of the diagonal
        lo, hi = (i, j) if V[i].sum() < V[j].sum() else (j, i)
        base.append(Rc @ V[lo] + centre)
        attach.append(Rc @ V[hi])
    return np.array(base), np.array(attach)


def test_cubic_hexapod_has_the_published_diagonal_stiffness():
    # Legs along six edges of a cube of side a, all of stiffness k: at the cube's centre
    # K6 = k diag(2, 2, 2, a^2/2, a^2/2, 2 a^2) (Geng and Haynes, IEEE Trans. Control Syst.
    # Technol. 2(1), 1994; Jafari and McInroy, IEEE Trans. Robot. Autom. 19(4), 2003).
    a, k, centre = 200.0, 800.0, np.array([0.0, 0.0, 250.0])
    base, attach = _cube_legs(a, centre)
    assert len(base) == 6
    names = tuple(f"k{i}" for i in range(1, 7))
    robot = _robot(ups_legs(base, attach, centre, names), dict.fromkeys(names, k), "cube")
    K6 = robot.stiffness6([*centre, 0.0, 0.0, 0.0])
    expected = k * np.diag([2.0, 2.0, 2.0, a * a / 2, a * a / 2, 2 * a * a])
    assert _relative(K6, expected) < 1e-9
    # The same legs with the tool point c away from the centre: the frame shift's coupling,
    # K6' = [[Kt, Kt [c]x], [-[c]x Kt, -[c]x Kt [c]x + Kr]] with Kt = 2k I.
    c = np.array([30.0, -50.0, 80.0])
    shifted = _robot(ups_legs(base, attach - c, centre, names), dict.fromkeys(names, k), "cube")
    Kt, Kr = 2 * k * np.eye(3), expected[3:, 3:]
    cx = np.array([[0, -c[2], c[1]], [c[2], 0, -c[0]], [-c[1], c[0], 0]])
    expected = np.block([[Kt, Kt @ cx], [-cx @ Kt, -cx @ Kt @ cx + Kr]])
    K6 = shifted.stiffness6([*(centre + c), 0.0, 0.0, 0.0])
    assert _relative(K6, expected) < 1e-9
    assert np.abs(K6[:3, 3:]).max() > 0.1 * k * np.abs(c).max()  # the coupling is there


def test_universal_platform_joint_holds_the_moment_about_its_cross(hexapods):
    # Leg 1 ends in a universal joint (axes x of the leg, y of the platform: the base's U
    # turned onto the platform) with a torsion spring about the leg: besides its axial force
    # it holds the moment about its cross's normal -- the leg's axis n -- with stiffness
    # k_t: K6 = sum k_i a_i a_i^T + k_t (0, n)(0, n)^T at the home pose.
    robot, base, attach, k, h = hexapods[0]
    legs = list(robot.description)
    leg = legs[0]
    twist = LegJoint("twist", "spring", "k_twist", type="revolute", axis=(0.0, 0.0, 1.0))
    u_frame = rpy_matrix(*leg.joints[0].rpy)
    legs[0] = LegDescription(
        leg.name,
        leg.attach_mm,
        (*leg.joints, twist),
        platform_joint="universal",
        platform_axes=((1.0, 0.0, 0.0), tuple(u_frame @ [0.0, 1.0, 0.0])),
    )
    kt = 3.0e6  # N*mm/rad
    robot_u = _robot(legs, {**robot.params(), "k_twist": kt})
    home = np.array([0.0, 0.0, h, 0.0, 0.0, 0.0])
    n = home[:3] + attach[0] - base[0]
    n /= np.linalg.norm(n)
    K6 = _closed_form_ups(base, attach, k, home)
    K6[3:, 3:] += kt * np.outer(n, n)
    assert (
        _relative(robot_u.stiffness6(home), K6) < 1e-9 and _relative(robot_u.stiffness6(home), K6, h) < 1e-9
    )
    # Turned, the platform's axis leaves the cross's plane: that leg cannot be assembled.
    m = robot_u.evaluate([0.0, 0.0, h, 0.0, 0.0, math.radians(5.0)])
    assert not m.valid[0]
    assert "leg 1 (leg1) its universal platform joint cannot be assembled" in m.reasons[0]


# ---------------------------------------------------------------------- finite differences


def test_arm_map_and_the_legs_jacobian_by_finite_differences(hexapods):
    robot, base, attach, _, h = hexapods[1]
    pose = np.array([15.0, -25.0, h + 20.0, *np.radians([6.0, -4.0, 9.0])])
    R0 = rpy_matrix(*pose[3:])
    eps = 1e-6

    def moved(delta):
        """The pose after the small displacement delta = (u mm, theta rad) at the tool point."""
        R = _exp(delta[3:]) @ R0
        return np.array([*(pose[:3] + delta[:3]), *_rpy(R)])

    # arm_map: the platform joint r = R a moves by A delta.
    r = R0 @ attach[2]
    A = arm_map(r)
    J = np.zeros((3, 6))
    for j in range(6):
        e = np.zeros(6)
        e[j] = eps
        up, dn = moved(e), moved(-e)
        J[:, j] = (up[:3] + rpy_matrix(*up[3:]) @ attach[2] - dn[:3] - rpy_matrix(*dn[3:]) @ attach[2]) / (
            2 * eps
        )
    np.testing.assert_allclose(J, A[:3], rtol=0, atol=1e-7)
    # The legs' lengths (the IK's actuated joints) change by a_i . delta, a_i = (n_i, r_i x n_i).
    Jq = np.zeros((6, 6))
    for j in range(6):
        e = np.zeros(6)
        e[j] = eps
        Jq[:, j] = (robot.inverse_kinematics(moved(e)).q[0] - robot.inverse_kinematics(moved(-e)).q[0]) / (
            2 * eps
        )
    rows = []
    for b, a in zip(base, attach, strict=True):
        ri = R0 @ a
        n = pose[:3] + ri - b
        n /= np.linalg.norm(n)
        rows.append(np.concatenate([n, np.cross(ri, n)]))
    np.testing.assert_allclose(Jq, np.array(rows), rtol=0, atol=1e-5)  # mm per mm, mm per rad


# ---------------------------------------------------------------------- the 3-RPS against frame FE


def test_frame_fe_cantilever_is_the_textbook_one():
    # The FE helper itself: a cantilever of one and of three elements under tip loads.
    E, G, A, I, J, L = 2.1e5, 8.1e4, 113.1, 4637.0, 9274.0, 270.0
    for n in (1, 3):
        K = np.zeros((6 * (n + 1), 6 * (n + 1)))
        for e in range(n):
            p1, p2 = np.array([0, 0, e * L / n]), np.array([0, 0, (e + 1) * L / n])
            K[6 * e : 6 * e + 12, 6 * e : 6 * e + 12] += beam_global(p1, p2, E, G, A, I, J)
        tip = list(range(6 * n, 6 * n + 6))
        free = list(range(6, 6 * (n + 1)))
        Kf = K[np.ix_(free, free)]
        order = [free.index(i) for i in tip] + [i for i in range(len(free)) if free[i] not in tip]
        Kt = condensed(Kf[np.ix_(order, order)], 6)
        C = np.linalg.inv(Kt)
        np.testing.assert_allclose(np.diag(C)[:3], [L**3 / (3 * E * I)] * 2 + [L / (E * A)], rtol=1e-10)
        np.testing.assert_allclose(C[5, 5], L / (G * J), rtol=1e-10)
        np.testing.assert_allclose(abs(C[0, 4]), L**2 / (2 * E * I), rtol=1e-10)


def test_3rps_matches_a_frame_finite_element_model():
    # The legs as steel tubes (beams), a revolute joint at the base and a ball at the top, the
    # platform rigid: condensed on the platform, K6 of the FE model equals the virtual joint
    # method's with each leg's axial stiffness E A / L_i and lateral 3 E I / L_i^3.
    robot = LegRobot.from_toml(ROBOTS / "3rps.toml")
    E, G, A, I, J = 2.1e5, 8.1e4, 113.1, 4637.0, 9274.0  # 20 x 2 mm steel tube
    ang = np.radians([90.0, 210.0, 330.0])
    base = RPS3["base_radius_mm"] * np.stack([np.cos(ang), np.sin(ang), 0 * ang], axis=1)
    axes = np.stack([-np.sin(ang), np.cos(ang), 0 * ang], axis=1)
    attach = RPS3["platform_radius_mm"] * np.stack([np.cos(ang), np.sin(ang), 0 * ang], axis=1)
    for z, roll, pitch in ((250.0, 0.0, 0.0), (270.0, 0.12, -0.08), (230.0, -0.15, 0.1)):
        pose = rps_pose(z, roll, pitch, attach, axes)
        R = rpy_matrix(*pose[3:])
        tips = pose[:3] + attach @ R.T
        lengths = np.linalg.norm(tips - base, axis=1)
        params = {f"k_leg{i + 1}": E * A / L for i, L in enumerate(lengths)}
        params |= {f"k_bend{i + 1}": 3 * E * I / L**3 for i, L in enumerate(lengths)}
        K6 = robot.with_params(**params).stiffness6(pose)
        K6_fe = rps_leg_platform_stiffness(base, axes, tips, pose[:3], E, G, A, I, J, n_elements=3)
        assert _relative(K6, K6_fe) < 1e-9 and _relative(K6, K6_fe, 100.0) < 1e-9, pose


# ---------------------------------------------------------------------- measures, limits, the same as before


def test_singularity_measures_are_the_jacobians_inverse_condition(hexapods):
    robot, base, attach, _, h = hexapods[0]
    L = robot.length_mm
    poses = np.array([[0.0, 0.0, h, 0.0, 0.0, y] for y in np.radians([0.0, 30.0, 60.0, 80.0, 89.0])])
    poses[:, 3] = 0.05
    st = robot.legs(poses)
    serial, parallel = robot.singularity_measures(poses)
    np.testing.assert_allclose(serial, 1.0, rtol=1e-12)  # each actuator along the force its leg holds
    for i, p in enumerate(poses):
        R = rpy_matrix(*p[3:])
        rows = []
        for b, a in zip(base, attach, strict=True):
            r = R @ a
            n = (p[:3] + r - b) / np.linalg.norm(p[:3] + r - b)
            rows.append(np.concatenate([n, np.cross(r, n) / L]))
        s = np.linalg.svd(np.array(rows), compute_uv=False)
        assert parallel[i] == pytest.approx(s[-1] / s[0], rel=1e-9)
    assert st.reachable[:3].all()
    assert parallel[-1] < 0.05 * parallel[0]  # turned towards Fichter's singularity (yaw 90 deg)


def test_a_pose_beyond_a_legs_stroke_is_named():
    robot = LegRobot.from_toml(ROBOTS / "hexapod.toml")
    # The continuation from the seed stops where the leg leaves its stroke (the joint and its limits named).
    stroke = r"joint stroke at [\d.]+ mm beyond its limits \[260, 440\] mm"
    with pytest.raises(PoseError, match=r"unreachable: leg 1 \(leg1\) cannot reach it .*\(" + stroke):
        robot.stiffness([0.0, 0.0, 520.0, 0.0, 0.0, 0.0])
    m = robot.evaluate([[0.0, 0.0, 300.0, 0.0, 0.0, 0.0], [0.0, 0.0, 300.0, 0.0, math.radians(50.0), 0.0]])
    assert m.valid[0] and not m.valid[1]
    assert m.reasons[1] == (
        "unreachable: leg 6 (leg6): joint stroke at 453.861 mm beyond its limits [260, 440] mm"
    )  # tilted 50 deg, leg 6 is 453.86 mm long: the geometry's own
    assert "roll-pitch-yaw (0, 50, 0) deg" in str(
        pytest.raises(PoseError, robot.stiffness, m.points[1]).value
    )


def test_2d_and_3d_robots_give_the_numbers_of_before():
    # Computed on main at e83d1d9, before the 6-D assembly (tests/data/make_legs_before_6d.py).
    ref = json.loads(BEFORE.read_text(encoding="utf-8"))
    models = {
        "delta_builtin": DeltaRobot(),
        "delta_legs": LegRobot.from_toml(ROBOTS / "delta.toml"),
        "prr3_builtin": PRR3(),
        "prr3_legs": LegRobot.from_toml(ROBOTS / "3prr.toml"),
    }
    for key, model in models.items():
        r = ref[key]
        P = np.array(r["points"])
        m = model.evaluate(P)
        s, p = model.singularity_measures(P)
        np.testing.assert_array_equal(m.valid, r["valid"])
        K = np.array(r["K"])
        assert np.abs(m.K - K).max() <= 1e-12 * np.abs(K).max(), key
        np.testing.assert_allclose(m.q, r["q"], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(s, r["serial"], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(p, r["parallel"], rtol=1e-12, atol=1e-15)
        assert m.K6 is None


# ---------------------------------------------------------------------- files and bad input


def test_shipped_files_are_what_the_builders_write():
    assert (ROBOTS / "hexapod.toml").read_text(encoding="utf-8") == hexapod_toml()
    assert (ROBOTS / "3rps.toml").read_text(encoding="utf-8") == rps3_toml()
    hexa = LegRobot.from_toml(ROBOTS / "hexapod.toml")
    assert isinstance(hexa, LegRobot6) and len(hexa.param_names()) == 6
    K6 = hexa.stiffness6([0.0, 0.0, 300.0, 0.0, 0.0, 0.0])
    # The semi-regular hexapod at home: symmetric about z, x and y alike.
    assert K6[0, 0] == pytest.approx(K6[1, 1], rel=1e-9) and K6[3, 3] == pytest.approx(K6[4, 4], rel=1e-9)
    again = LegRobot.from_toml_text(legs_text(hexa.name, 6, hexa.params(), hexa.description, 1e-3))
    np.testing.assert_allclose(again.stiffness6([0.0, 0.0, 300.0, 0.0, 0.0, 0.0]), K6, rtol=1e-12)


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            "attach_mm = [-114.906666467847, -96.4181414529809, 0.0]",
            "attach_mm = [-114.906666467847, -96.4181414529809]",
            r"legs\[1\]\.attach_mm: expected 3 numbers \(dim = 6: the leg's joint in the platform's frame, "
            r"mm\), got 2",
        ),
        ("\ndim = 6\n", "\ndim = 4\n", r"dim: Input should be 2, 3 or 6, got 4"),
        (
            'tip_offset_mm = [0.0, 0.0, 0.0]\n\n[[legs.joints]]\nname = "u1"',
            'tip_offset_mm = [0.0, 0.0, 0.0]\nplatform_joint = "universal"\n\n[[legs.joints]]\nname = "u1"',
            r"legs\[1\]\.platform_axes: missing key: a universal platform joint gives its two axes",
        ),
        (
            'tip_offset_mm = [0.0, 0.0, 0.0]\n\n[[legs.joints]]\nname = "u1"',
            'tip_offset_mm = [0.0, 0.0, 0.0]\nplatform_joint = "hinge"\n\n[[legs.joints]]\nname = "u1"',
            r"legs\[1\]\.platform_joint: Input should be 'ball' or 'universal'",
        ),
    ],
)
def test_bad_6d_leg_files_are_named(old, new, message):
    text = (ROBOTS / "hexapod.toml").read_text(encoding="utf-8")
    assert old in text
    with pytest.raises(InputError, match=r"^bad\.toml: " + message):
        LegRobot.from_toml_text(text.replace(old, new, 1), source="bad.toml")


def test_platform_joint_keys_are_only_for_dim_6():
    text = (ROBOTS / "delta.toml").read_text(encoding="utf-8")
    bad = text.replace(
        "tip_offset_mm = [0.0, 0.0, -425.0]", 'tip_offset_mm = [0.0, 0.0, -425.0]\nplatform_joint = "ball"', 1
    )
    with pytest.raises(InputError, match=r"^d\.toml: legs\[1\]\.platform_joint: only for dim = 6"):
        LegRobot.from_toml_text(bad, source="d.toml")


def test_poses_file_needs_the_three_orientation_columns_or_none(tmp_path):
    f = tmp_path / "poses.csv"
    f.write_text("x,y,z,roll_deg,pitch_deg,yaw_deg\n0,0,300,5,-3,10\n1,2,310,0,0,0\n", encoding="utf-8")
    P = read_points(f, 6)
    np.testing.assert_allclose(P[0], [0, 0, 300, *np.radians([5, -3, 10])], rtol=1e-15)
    f.write_text("x,y,z\n0,0,300\n", encoding="utf-8")
    np.testing.assert_array_equal(read_points(f, 6), [[0, 0, 300, 0, 0, 0]])
    f.write_text("x,y,z,pitch_deg\n0,0,300,5\n", encoding="utf-8")
    with pytest.raises(
        InputError, match=rf"^{f}: has pitch_deg but not roll_deg, yaw_deg: give the orientation's"
    ):
        read_points(f, 6)
    f.write_text("x,y,z,roll_deg,pitch_deg,yaw_deg\n0,0,300,5,200,0\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"line 2, column 'pitch_deg': 200 deg is beyond \+-180 deg"):
        read_points(f, 6)
    with pytest.raises(ValueError, match=r"roll, pitch, yaw .* must be radians within \+-pi"):
        as_points([0.0, 0.0, 300.0, 0.0, 30.0, 0.0], 6)


def test_platform_stiffness6_adds_a_legs_extra_compliance():
    # A leg's 6-D compliance beyond its spring columns (a link's, carried to the tip) adds to
    # C before the held directions are taken: a lone axial leg with an extra axial compliance
    # c has stiffness 1 / (1/k + c) along its line.
    n = np.array([0.0, 0.6, 0.8])
    springs = np.concatenate([n, np.zeros(3)])[None, None, :, None]
    passive = np.zeros((1, 1, 6, 5))
    t1 = np.cross(n, [1.0, 0.0, 0.0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    passive[0, 0, :3, 0], passive[0, 0, :3, 1] = t1, t2  # the leg turns about its base
    passive[0, 0, 3:, 2:] = np.eye(3)  # the ball
    extra = np.zeros((1, 1, 6, 6))
    extra[0, 0, :3, :3] = 2e-4 * np.outer(n, n) + 1e-3 * np.eye(3)  # mm/N
    arms = np.array([[[10.0, -20.0, 5.0]]])
    K6, rigid = platform_stiffness6(springs, [[1000.0]], passive, arms, np.array([True]), compliance=extra)
    k = 1 / (1 / 1000.0 + 2e-4 + 1e-3)
    w = np.concatenate([n, np.cross(arms[0, 0], n)])
    assert not rigid.any()
    np.testing.assert_allclose(K6[0], k * np.outer(w, w), rtol=1e-12, atol=1e-12 * k)


@pytest.mark.fuzz
@given(data=st.data())
def test_mutated_6d_leg_files_load_or_are_refused_by_name(data):
    name = data.draw(st.sampled_from(["hexapod", "3rps"]))
    valid = (ROBOTS / f"{name}.toml").read_text(encoding="utf-8")
    raw = data.draw(st.one_of(mutated_spec(valid), mutated_spec(valid), toml_text_mutations(valid)))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.toml"
        path.write_bytes(raw)
        try:
            lr = LegRobot.from_toml(path)
        except InputError as e:
            assert str(e).startswith(f"{path}: ")
            return
    home = {6: [0.0, 0.0, 280.0, 0.0, 0.02, 0.0], 3: [0.0, 0.0, 280.0], 2: [0.0, 0.0]}[lr.dim]
    m = lr.evaluate(np.array([home]))
    assert m.valid[0] or m.reasons[0].startswith(("unreachable: ", "singular: "))


def test_fit_recovers_the_six_leg_stiffnesses_from_K6(hexapods):
    # The identified K6 of a campaign fitted by the model's K6: noiseless data give the legs'
    # stiffnesses back; noisy entries (independent, 0.5 % of sqrt(K_ii K_jj)) give estimates
    # within 4 of their standard errors.
    robot, base, attach, k, h = hexapods[0]
    rng = np.random.default_rng(30)
    P = np.zeros((8, 6))
    P[:, :3] = [0.0, 0.0, h] + rng.uniform(-30.0, 30.0, size=(8, 3))
    P[:, 3:] = np.radians(rng.uniform(-8.0, 8.0, size=(8, 3)))
    K6 = np.array([_closed_form_ups(base, attach, k, p) for p in P])
    start = robot.with_params(**dict.fromkeys(robot.param_names(), 1000.0))
    names = robot.param_names()
    f = fit_stiffness(start, P, K6, params=names)
    assert f.kind == "stiffness6"
    np.testing.assert_allclose(f.estimate, k, rtol=1e-8)
    d = np.sqrt(np.abs(np.einsum("nii->ni", K6)))
    std = 0.005 * d[:, :, None] * d[:, None, :]
    noisy = K6 + std * rng.normal(size=K6.shape)
    f = fit_stiffness(start, P, noisy, params=names, K_std=std, absolute_sigma=True)
    assert np.all(np.abs(f.estimate - k) < 4 * f.std), (f.estimate, k, f.std)
    assert np.all(f.std < 0.02 * k)
