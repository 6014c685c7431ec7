"""Flexible links in the legs of parallel robots (``[[legs.links]]``, stiffmap.models.legs).

- Without links, the Delta, the 3PRR, the hexapod and the 3-RPS give the numbers of before
  (tests/data/legs_before_links.json, computed at 8a1e20e) to 1e-12.
- A planar five-bar whose upper arms and forearms are beams equals a frame finite-element
  model (anastruct: Euler-Bernoulli frame elements for the upper arms, pin-jointed bars for the
  forearms, rotational springs at the motors) to 1e-6.
- A hexapod whose legs carry a beam in series with the actuator: the axial compliances add,
  K6 = sum a_i a_i^T / (1/k_i + L/(EA)), Gosselin's closed form written in the test.
- The TOML: round trip through legs_text, links of one name sharing their parameters, and
  every mistake one line naming the file and the key.
- The fit: a Delta with flexible upper arms, k_theta and E recovered from noise-free (1e-6)
  and noisy (within 3 standard errors) static errors; what the data cannot separate named.
"""

from __future__ import annotations

import json
import math
import tempfile
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
from helpers.fuzz_campaign import mutated_spec, toml_text_mutations
from helpers.poses import rps_pose, rpy_matrix
from hypothesis import given
from hypothesis import strategies as st

from stiffmap.errors import DesignError, InputError
from stiffmap.models.fit import fit_deflections6, fit_static_errors
from stiffmap.models.legs import LegRobot
from stiffmap.models.legs6 import HEXAPOD, RPS3, gough_stewart_points, hexapod_toml, rps3_toml
from stiffmap.models.legs_convert import legs_toml

ROBOTS = files("stiffmap.models") / "robots"
BEFORE = Path(__file__).with_name("data") / "legs_before_links.json"


def _with_links(text: str, link_tables: str) -> str:
    """A legs TOML with ``link_tables`` (``[[legs.links]]`` ...) appended to every leg."""
    head, *legs = text.split("\n[[legs]]\n")
    return head + "".join(f"\n[[legs]]\n{lg.rstrip()}\n{link_tables}" for lg in legs)


# ---------------------------------------------------------------------- without links: as before


def test_without_links_every_number_is_as_before():
    ref = json.loads(BEFORE.read_text(encoding="utf-8"))
    for key in ("delta", "3prr", "hexapod", "3rps"):
        r = ref[key]
        m = LegRobot.from_toml(ROBOTS / f"{key}.toml").evaluate(np.array(r["points"]))
        np.testing.assert_array_equal(m.valid, r["valid"])
        for field in ("K", "K6"):
            if field in r:
                got, want = np.nan_to_num(getattr(m, field)), np.array(r[field])
                assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max(), (key, field)


# ---------------------------------------------------------------------- a planar five-bar: frame FE

L1, L2, HALF = 300.0, 400.0, 100.0  # upper arm, forearm, half the motors' distance (mm)


def _beam_table(after: str, name: str, b: dict) -> str:
    return f"""
[[legs.links]]
after = "{after}"
name = "{name}"
[legs.links.beam]
length_mm = {b["L"]}
E_MPa = {b["E"]}
G_MPa = 26000.0
area_mm2 = {b["A"]}
Iy_mm4 = 1e5
Iz_mm4 = {b["I"]}
J_mm4 = 2e5
"""


def _five_bar(k: float, upper: dict, fore: dict) -> LegRobot:
    """Two legs: a motor at (-+HALF, 0) turning an upper arm (along its x), a pin, a forearm to the
    tool point (the two forearms pinned there); both links beams."""
    text = f"dim = 2\n[params]\nk = {k}\n"
    for i, (x, q0, e0) in enumerate(((-HALF, 1.9, -1.0), (HALF, 1.2, 1.0)), start=1):
        text += f"""
[[legs]]
name = "leg{i}"
attach_mm = [0.0, 0.0]
tip_offset_mm = [{L2}, 0, 0]
[[legs.joints]]
name = "motor"
type = "revolute"
axis = [0, 0, 1]
xyz_mm = [{x}, 0, 0]
role = "actuated"
stiffness = "k"
q0 = {q0}
[[legs.joints]]
name = "elbow"
type = "revolute"
axis = [0, 0, 1]
xyz_mm = [{L1}, 0, 0]
role = "passive"
q0 = {e0}
"""
        text += _beam_table("motor", "upper", upper) + _beam_table("elbow", "fore", fore)
    return LegRobot.from_toml_text(text, source="five_bar.toml")


def _frame_fe_stiffness(motor_angles, tip, k: float, upper: dict, fore: dict) -> np.ndarray:
    """K (2 x 2) at the tool point of the five-bar as a plane frame: each upper arm an
    Euler-Bernoulli element from a hinged support with a rotational spring k, each forearm a
    pin-jointed bar (axial only) to the tool point; unit loads Fx, Fy there."""
    from anastruct import SystemElements  # lazy: it loads matplotlib, for this test only

    C = np.zeros((2, 2))
    T = [float(tip[0]), float(tip[1])]
    for col, load in enumerate(({"Fx": 1.0}, {"Fy": 1.0})):
        ss = SystemElements()
        for x, q in zip((-HALF, HALF), motor_angles, strict=True):
            E = [x + L1 * math.cos(q), L1 * math.sin(q)]
            ss.add_element([[x, 0.0], E], EA=upper["E"] * upper["A"], EI=upper["E"] * upper["I"])
            ss.add_element([E, T], EA=fore["E"] * fore["A"], element_type="truss")
        for x in (-HALF, HALF):
            node = ss.find_node_id([x, 0.0])
            ss.add_support_hinged(node)
            ss.add_support_spring(node, translation=3, k=k)
        ss.point_load(ss.find_node_id(T), **load)
        ss.solve()
        r = ss.get_node_displacements(ss.find_node_id(T))
        C[:, col] = (r["ux"], r["uy"])
    return np.linalg.inv(C)


def test_five_bar_with_flexible_links_equals_a_frame_finite_element_model(rng):
    for _ in range(3):
        k = rng.uniform(2e6, 2e7)  # N*mm/rad
        upper = {"L": L1, "E": rng.uniform(5e4, 2.1e5), "A": rng.uniform(50, 400), "I": rng.uniform(2e3, 1e4)}
        fore = {"L": L2, "E": rng.uniform(5e4, 2.1e5), "A": rng.uniform(5, 20), "I": 1e4}
        robot = _five_bar(k, upper, fore)
        P = np.column_stack([rng.uniform(-60, 60, 3), rng.uniform(420, 520, 3)])
        st = robot.legs(P)
        K = robot.stiffness(P)
        K_joints = robot.with_params(E_upper=1e7, E_fore=1e7).stiffness(P)
        for i, p in enumerate(P):
            K_fe = _frame_fe_stiffness((st.joints[0][i, 0], st.joints[1][i, 0]), p, k, upper, fore)
            assert np.linalg.norm(K[i] - K_fe) < 1e-6 * np.linalg.norm(K_fe), (p, K[i], K_fe)
            # the links' share is not small: with (nearly) rigid links the robot is much stiffer
            assert np.linalg.norm(K_joints[i] - K[i]) > 0.1 * np.linalg.norm(K_fe)


# ---------------------------------------------------------------------- a hexapod: springs in series

ROD = {"L": 250.0, "E": 7e4, "A": 3.0}  # a thin rod in series with each actuator: EA/L = 840 N/mm

_ROD_TABLE = f"""
[[legs.links]]
after = "stroke"
name = "rod"
[legs.links.beam]
length_mm = {ROD["L"]}
E_MPa = {ROD["E"]}
G_MPa = 2.6e4
area_mm2 = {ROD["A"]}
Iy_mm4 = 50.0
Iz_mm4 = 80.0
J_mm4 = 130.0
axis = "z"
"""


def _hexapod_with_rods(k) -> LegRobot:
    text = _with_links(hexapod_toml(), _ROD_TABLE)
    return LegRobot.from_toml_text(text, source="hexapod_rods.toml").with_params(
        **{f"k_leg{i}": float(v) for i, v in enumerate(k, start=1)}
    )


def _series_closed_form(k, E: float, pose) -> np.ndarray:
    """K6 = sum a_i a_i^T / (1/k_i + L/(E A)), a_i = (n_i, r_i x n_i): each leg's actuator and rod
    in series along its line (Gosselin's J^T K J with the series stiffness)."""
    p = HEXAPOD
    base, attach = gough_stewart_points(
        p["base_radius_mm"], p["platform_radius_mm"], p["base_pair_deg"], p["platform_pair_deg"]
    )
    R = rpy_matrix(*pose[3:])
    K6 = np.zeros((6, 6))
    for b, a, ki in zip(base, attach, k, strict=True):
        r = R @ a
        n = pose[:3] + r - b
        n /= np.linalg.norm(n)
        w = np.concatenate([n, np.cross(r, n)])
        K6 += np.outer(w, w) / (1 / ki + ROD["L"] / (E * ROD["A"]))
    return K6


def _scaled(A, L=150.0):
    d = np.array([1.0, 1.0, 1.0, 1 / L, 1 / L, 1 / L])
    return A * d[:, None] * d[None, :]


def _hexapod_poses(rng, n):
    P = np.zeros((n, 6))
    P[:, :3] = [0.0, 0.0, HEXAPOD["height_mm"]] + rng.uniform(-30.0, 30.0, size=(n, 3))
    P[:, 3:] = np.radians(rng.uniform(-8.0, 8.0, size=(n, 3)))
    return P


def test_hexapod_legs_with_a_rod_in_series_add_their_axial_compliances(rng):
    k = rng.uniform(300.0, 3000.0, size=6)
    robot = _hexapod_with_rods(k)
    assert robot.params()["E_rod"] == ROD["E"]  # one parameter shared by the six rods
    P = _hexapod_poses(rng, 5)
    K6 = robot.stiffness6(P)
    for E in (ROD["E"], 2.1e5):
        K6 = robot.with_params(E_rod=E).stiffness6(P)
        for K, pose in zip(K6, P, strict=True):
            want = _scaled(_series_closed_form(k, E, pose))
            assert np.linalg.norm(_scaled(K) - want) < 1e-9 * np.linalg.norm(want), pose


def test_hexapod_fit_names_the_leg_spring_and_rod_it_cannot_separate(rng):
    # A rod in series with the actuator is only axial, as the actuator's spring: the data
    # cannot tell k_leg_i and E_rod apart; with E_rod known the legs are recovered.
    k = rng.uniform(300.0, 3000.0, size=6)
    robot = _hexapod_with_rods(k)
    P = _hexapod_poses(rng, 8)
    W = np.column_stack([rng.normal(0, 20, (8, 3)), rng.normal(0, 2000, (8, 3))])
    D = robot.static_error6(P, W)
    legs = tuple(f"k_leg{i}" for i in range(1, 7))
    start = robot.with_params(**dict.fromkeys(legs, 1000.0), E_rod=1e5)
    with pytest.raises(DesignError, match=r"cannot tell .*k_leg.*E_rod|cannot tell .*E_rod"):
        fit_deflections6(start, P, W, D, params=(*legs, "E_rod"))
    f = fit_deflections6(start.with_params(E_rod=ROD["E"]), P, W, D, params=legs)
    np.testing.assert_allclose(f.estimate, k, rtol=1e-6)


# ---------------------------------------------------------------------- the Delta with flexible arms: fit

ARM = """
[[legs.links]]
after = "actuator"
name = "arm"
[legs.links.beam]
length_mm = 300.0
E_MPa = 70000.0
G_MPa = 26000.0
area_mm2 = 200.0
Iy_mm4 = 1500.0
Iz_mm4 = 800.0
J_mm4 = 4000.0
"""


def _delta_with_arms() -> LegRobot:
    text = _with_links((ROBOTS / "delta.toml").read_text(encoding="utf-8"), ARM)
    return LegRobot.from_toml_text(text, source="delta_links.toml")


def _static_error_data(robot, rng, n=6):
    P = np.column_stack([rng.uniform(-120, 120, (n, 2)), rng.uniform(-360, -240, n)])
    P = np.repeat(P, 6, axis=0)
    F = rng.normal(0.0, 30.0, (P.shape[0], 3))
    U = np.tile(np.repeat(np.eye(3), 2, axis=0), (n, 1))
    y = np.einsum("ij,ij->i", robot.static_error(P, F), U)
    return P, F, U, y


def test_delta_arm_links_fitted_beside_the_actuators(rng):
    truth = _delta_with_arms()
    k_theta, E = truth.params()["k_theta"], truth.params()["E_arm"]
    P, F, U, y = _static_error_data(truth, rng)
    # the arms' share is not small
    rigid = truth.with_params(E_arm=1e7, G_arm=1e7)
    y_rigid = np.einsum("ij,ij->i", rigid.static_error(P, F), U)
    assert np.linalg.norm(y - y_rigid) > 0.2 * np.linalg.norm(y)
    start = truth.with_params(k_theta=1e5, E_arm=1.5e5)
    f = fit_static_errors(start, P, F, U, y, params=("k_theta", "E_arm"))
    np.testing.assert_allclose(f.estimate, [k_theta, E], rtol=1e-6)
    # noisy: 1 micrometre on each reading, estimates within 3 standard errors
    std = np.full(y.shape, 1e-3)
    f = fit_static_errors(
        start,
        P,
        F,
        U,
        y + std * rng.normal(size=y.shape),
        params=("k_theta", "E_arm"),
        std=std,
        absolute_sigma=True,
    )
    assert np.all(np.abs(f.estimate - [k_theta, E]) < 3 * f.std), (f.estimate, f.std)
    assert np.all(f.std < 0.05 * np.array([k_theta, E]))
    # the arm's torsion never loads the ball-jointed elbow (and an Euler-Bernoulli arm has no
    # shear): G_arm is named as undeterminable
    with pytest.raises(DesignError, match="cannot determine G_arm"):
        fit_static_errors(start, P, F, U, y, params=("k_theta", "E_arm", "G_arm"))


# ---------------------------------------------------------------------- the TOML


def test_links_round_trip_through_legs_text():
    compliance = np.diag([2e-4, 3e-4, 3e-4, 1e-8, 2e-8, 2e-8])
    compliance[1, 5] = compliance[5, 1] = 1e-6
    matrix = _matrix(compliance)
    extra = f"""
[[legs.links]]
after = "elbow_z"
xyz_mm = [0.0, 0.0, -200.0]
rpy = [0.1, -0.2, 0.3]
compliance = {matrix}
"""
    timoshenko = ARM.replace("J_mm4 = 4000.0", "J_mm4 = 4000.0\nshear_factor = 0.5")
    text = _with_links((ROBOTS / "delta.toml").read_text(encoding="utf-8"), timoshenko + extra)
    with pytest.raises(InputError, match=r"legs\[2\]\.links\[1\]\.name: 'arm' .*legs\[1\]\.links\[1\]"):
        LegRobot.from_toml_text(
            text.replace("E_MPa = 70000.0", "E_MPa = 71000.0", 2).replace(
                "E_MPa = 71000.0", "E_MPa = 70000.0", 1
            ),
            source="d.toml",
        )
    robot = LegRobot.from_toml_text(text, source="d.toml").with_params(f_leg2_elbow_z=2.0, E_arm=8e4)
    names = robot.param_names()
    assert names[:3] == ("k_theta", "k_arm", "k_forearm") and "f_leg1_elbow_z" in names
    again = LegRobot.from_toml_text(legs_toml(robot))  # the links' tables, the current values
    assert again.params() == robot.params() | {"f_leg2_elbow_z": 1.0}  # written as C / f
    P = np.array([[0.0, 0.0, -300.0], [80.0, -40.0, -260.0]])
    want = robot.stiffness(P)
    assert np.abs(again.stiffness(P) - want).max() <= 1e-12 * np.abs(want).max()
    # the links count: without them the robot is stiffer
    assert (
        np.abs(LegRobot.from_toml(ROBOTS / "delta.toml").stiffness(P) - want).max()
        > 0.05 * np.abs(want).max()
    )


_HEAD = """dim = 2
[params]
k = 1000.0
[[legs]]
attach_mm = [0.0, 0.0]
tip_offset_mm = [100.0, 0.0, 0.0]
[[legs.joints]]
name = "slide"
type = "prismatic"
axis = [1, 0, 0]
role = "actuated"
stiffness = "k"
[[legs.joints]]
name = "pin"
type = "revolute"
axis = [0, 0, 1]
role = "passive"
"""


def _matrix(C) -> str:
    return "[" + ", ".join("[" + ", ".join(repr(float(v)) for v in r) + "]" for r in C) + "]\n"


_BEAM = """[legs.links.beam]
length_mm = 100.0
E_MPa = 7e4
G_MPa = 2.6e4
area_mm2 = 20.0
Iy_mm4 = 100.0
Iz_mm4 = 100.0
J_mm4 = 200.0
"""


@pytest.mark.parametrize(
    ("links", "message"),
    [
        (
            '[[legs.links]]\nafter = "knee"\n' + _BEAM,
            r"legs\[1\]\.links\[1\]\.after: expected the name of one of leg1's joints \(slide, pin\)",
        ),
        (
            '[[legs.links]]\nafter = "pin"\n' + _BEAM.replace("length_mm = 100.0", "length_mm = -5.0"),
            r"legs\[1\]\.links\[1\]\.beam\.length_mm: expected a positive number, got -5\.0",
        ),
        (
            '[[legs.links]]\nafter = "pin"\ncompliance = ' + _matrix(np.diag([1, 1, -1, 1, 1, 1])),
            r"legs\[1\]\.links\[1\]\.compliance: the compliance is not positive definite",
        ),
        (
            '[[legs.links]]\nafter = "pin"\ncompliance = [[1, 0], [0, 1]]\n',
            r"legs\[1\]\.links\[1\]\.compliance: expected a 6 x 6 matrix",
        ),
        ('[[legs.links]]\nafter = "pin"\n', r"legs\[1\]\.links\[1\]: give either beam .* or compliance"),
        (
            '[[legs.links]]\nafter = "pin"\nlenght = 3\n' + _BEAM,
            r"legs\[1\]\.links\[1\]\.lenght: unknown key; valid: after, link",
        ),
        ('[[legs.links]]\nlink = "pin"\n' + _BEAM, r"legs\[1\]\.links\[1\]\.link: only for a URDF leg"),
        (
            '[[legs.links]]\nafter = "pin"\nname = "k"\ncompliance = ' + _matrix(np.eye(6)),
            None,
        ),
        (
            '[[legs.links]]\nafter = "slide"\n' + _BEAM.replace("E_MPa = 7e4", 'E_MPa = "7e4"'),
            r"legs\[1\]\.links\[1\]\.beam\.E_MPa: expected a positive number",
        ),
        (
            '[[legs.links]]\nafter = "slide"\nname = "a-b"\n' + _BEAM,
            r"legs\[1\]\.links\[1\]\.name: expected letters, digits",
        ),
    ],
)
def test_bad_links_are_one_line_naming_the_file_and_the_key(links, message):
    text = _HEAD + links
    if message is None:  # a good one: f_k beside [params]' k
        robot = LegRobot.from_toml_text(text, source="bad.toml")
        assert robot.param_names() == ("k", "f_k")
        return
    with pytest.raises(InputError) as e:
        LegRobot.from_toml_text(text, source="bad.toml")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("bad.toml: "), msg
    assert __import__("re").search(message, msg), msg


def test_a_link_parameter_named_as_a_stiffness_is_refused():
    text = (
        _HEAD.replace("k = 1000.0", "k = 1000.0\nE_a = 10.0").replace(
            'role = "passive"\n', 'role = "passive"\n', 1
        )
        + '[[legs.joints]]\nname = "x"\ntype = "revolute"\naxis = [0, 0, 1]\n'
        + 'role = "spring"\nstiffness = "E_a"\n'
    )
    text += '[[legs.links]]\nafter = "pin"\nname = "a"\n' + _BEAM
    with pytest.raises(
        InputError, match=r"bad\.toml: legs\[1\]\.links\[1\]\.name: its parameter E_a is also in \[params\]"
    ):
        LegRobot.from_toml_text(text, source="bad.toml")


def _five_bar_urdf(x_mm: float) -> str:
    """One leg of the five-bar as a URDF (metres): motor, upper arm, elbow, forearm, tool pin."""
    lim = '<limit lower="-3.14" upper="3.14" effort="1" velocity="1"/>'
    return f"""<robot name="five_bar_leg">
  <link name="base"/><link name="upper"/><link name="fore"/><link name="pin"/>
  <transmission name="t"><joint name="motor"/></transmission>
  <joint name="motor" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="{x_mm / 1000} 0 0"/><axis xyz="0 0 1"/>{lim}
  </joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/>
    <origin xyz="{L1 / 1000} 0 0"/><axis xyz="0 0 1"/>{lim}
  </joint>
  <joint name="tool" type="fixed"><parent link="fore"/><child link="pin"/>
    <origin xyz="{L2 / 1000} 0 0"/></joint>
</robot>"""


def test_urdf_legs_take_their_links_by_urdf_link(tmp_path, rng):
    upper = {"L": L1, "E": 7e4, "A": 200.0, "I": 5e3}
    fore = {"L": L2, "E": 2.1e5, "A": 10.0, "I": 1e4}
    by_joints = _five_bar(5e6, upper, fore)
    text = "dim = 2\n[params]\nk = 5000000.0\n"
    for i, (x, q0, e0) in enumerate(((-HALF, 1.9, -1.0), (HALF, 1.2, 1.0)), start=1):
        (tmp_path / f"leg{i}.urdf").write_text(_five_bar_urdf(x))
        text += (
            f'\n[[legs]]\nname = "leg{i}"\nurdf = "leg{i}.urdf"\ntip_frame = "pin"\nattach_mm = [0.0, 0.0]\n'
            f'[[legs.joints]]\nname = "motor"\nrole = "actuated"\nstiffness = "k"\nq0 = {q0}\n'
            f'[[legs.joints]]\nname = "elbow"\nrole = "passive"\nq0 = {e0}\n'
        )
        for link, b in (("upper", upper), ("fore", fore)):
            text += _beam_table("x", link, b).replace('after = "x"', f'link = "{link}"')
    robot = LegRobot.from_toml_text(text, source="urdf_legs.toml", base_dir=tmp_path)
    assert robot.param_names() == by_joints.param_names()
    P = np.column_stack([rng.uniform(-60, 60, 4), rng.uniform(420, 520, 4)])
    want = by_joints.stiffness(P)
    assert np.abs(robot.stiffness(P) - want).max() <= 1e-9 * np.abs(want).max()
    with pytest.raises(
        InputError, match=r"urdf_legs\.toml: legs\[1\]\.links\[1\]\.link: 'uper' is not a link of"
    ):
        LegRobot.from_toml_text(
            text.replace('link = "upper"', 'link = "uper"', 1), source="urdf_legs.toml", base_dir=tmp_path
        )
    with pytest.raises(InputError, match=r"legs\[1\]\.links\[1\]\.after: only for a leg given by joints"):
        LegRobot.from_toml_text(
            text.replace('link = "upper"', 'after = "motor"', 1), source="u.toml", base_dir=tmp_path
        )


def test_cli_fits_the_shipped_delta_links_arms_and_names_g(tmp_path, rng, monkeypatch, capsys):
    from helpers.cli_process import run_in_process as cli

    truth = LegRobot.from_toml(ROBOTS / "delta_links.toml").with_params(k_theta=2.5e5, E_arm=6e4)
    P, F, U, y = _static_error_data(truth, rng, n=5)
    rows = ["x,y,z,fx,fy,fz,nx,ny,nz,value_mm"]
    rows += [",".join(repr(float(v)) for v in (*p, *f, *u, v)) for p, f, u, v in zip(P, F, U, y, strict=True)]
    meas = tmp_path / "meas.csv"
    meas.write_text("\n".join(rows) + "\n")
    code, out, err = cli(["fit", "legs", "delta_links", meas, "--json"], monkeypatch, capsys)
    assert code == 0, err
    est = {k: v["estimate"] for k, v in json.loads(out)["parameters"].items()}
    assert set(est) == {"k_theta", "E_arm"}  # the default: stiffnesses and E, not G
    np.testing.assert_allclose([est["k_theta"], est["E_arm"]], [2.5e5, 6e4], rtol=1e-6)
    code, out, err = cli(
        ["fit", "legs", "delta_links", meas, "--param-to-fit", "k_theta,E_arm,G_arm"], monkeypatch, capsys
    )
    assert code == 2 and err.count("\n") == 1 and "cannot determine G_arm" in err, err


# ---------------------------------------------------------------------- a 3-RPS with tube legs: 6-D fit

TUBE = """
[[legs.links]]
after = "stroke"
name = "tube"
[legs.links.beam]
length_mm = 270.0
E_MPa = 210000.0
G_MPa = 81000.0
area_mm2 = 113.1
Iy_mm4 = 4637.0
Iz_mm4 = 4637.0
J_mm4 = 9274.0
axis = "z"
"""


def test_3rps_tube_legs_fitted_from_6d_deflections(rng):
    # Each leg a steel tube in series with its actuator (the shipped bending spring made rigid):
    # the tube's E sets the leg's lateral compliance L^3/(3EI) alone, and adds L/(EA) to the
    # axial one, so k_leg1..3 and E_tube are all determined by the platform's 6-D deflections.
    text = _with_links(rps3_toml({"k_bend": math.inf}), TUBE)
    k = rng.uniform(300.0, 1500.0, size=3)
    truth = LegRobot.from_toml_text(text, source="3rps_tubes.toml").with_params(
        **{f"k_leg{i}": float(v) for i, v in enumerate(k, start=1)}, E_tube=1.9e5
    )
    P = np.zeros((4, 6))
    P[:, 2] = np.linspace(220.0, 290.0, 4)
    P = np.repeat(P, 3, axis=0)
    W = np.column_stack([rng.normal(0, 20, (12, 3)), rng.normal(0, 2000, (12, 3))])
    D = truth.static_error6(P, W)
    names = ("k_leg1", "k_leg2", "k_leg3", "E_tube")
    assert truth.default_fit() == ("k_leg1", "k_leg2", "k_leg3", "k_bend1", "k_bend2", "k_bend3", "E_tube")
    start = truth.with_params(k_leg1=800.0, k_leg2=800.0, k_leg3=800.0, E_tube=1e5)
    f = fit_deflections6(start, P, W, D, params=names)
    np.testing.assert_allclose(f.estimate, [*k, 1.9e5], rtol=1e-6)
    std = np.tile([1e-3, 1e-3, 1e-3, 1e-5, 1e-5, 1e-5], (12, 1))  # 1 micrometre, 10 microrad
    f = fit_deflections6(
        start, P, W, D + std * rng.normal(size=D.shape), params=names, std=std, absolute_sigma=True
    )
    assert np.all(np.abs(f.estimate - [*k, 1.9e5]) < 3 * f.std), (f.estimate, f.std)
    assert np.all(f.std < 0.05 * np.array([*k, 1.9e5]))


@pytest.mark.fuzz
@given(data=st.data())
def test_mutated_leg_files_with_links_load_or_are_refused_by_name(data):
    valid = (ROBOTS / "delta_links.toml").read_text(encoding="utf-8")
    valid += '\n[[legs.links]]\nafter = "elbow_z"\nname = "given"\nrpy = [0.1, 0.0, 0.2]\ncompliance = '
    valid += _matrix(np.diag([2e-4, 3e-4, 3e-4, 1e-8, 2e-8, 2e-8]))
    raw = data.draw(st.one_of(mutated_spec(valid), mutated_spec(valid), toml_text_mutations(valid)))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.toml"
        path.write_bytes(raw)
        try:
            lr = LegRobot.from_toml(path)
        except InputError as e:
            assert str(e).startswith(f"{path}: ") and "\n" not in str(e), str(e)
            return
    home = {3: [0.0, 0.0, -300.0], 2: [0.0, 0.0]}.get(lr.dim, [0.0, 0.0, -300.0, 0.0, 0.0, 0.0])
    m = lr.evaluate(np.array([home]))
    assert m.valid[0] or m.reasons[0].startswith(("unreachable: ", "singular: "))


def test_campaign_takes_link_parameters_and_refuses_bad_ones_before_measuring(tmp_path):
    import re

    from helpers.fuzz import run_argv
    from helpers.fuzz_campaign import bare_vision_seed

    from stiffmap.kinds import robot_kind

    model = LegRobot.from_toml(ROBOTS / "delta_links.toml")
    assert robot_kind("legs").fitted_names(model) == ("k_theta", "E_arm")  # k_arm, k_forearm inf; no G
    root = tmp_path / "c"
    for name, data in bare_vision_seed().items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_bytes(data)
    (root / "robot.toml").write_bytes((ROBOTS / "delta_links.toml").read_bytes())
    spec = root / "campaign.toml"
    robot = (
        '[robot]\nmodel = "legs"\nlegs = "robot.toml"\nparams = {E_arm = -5.0}\nfit = ["k_theta", "E_arm"]\n'
    )
    spec.write_text(re.sub(r"\[robot\]\n(?:.*\n)*?(?=\n\[)", robot, spec.read_text(), count=1))
    o = run_argv(["run", str(root), "--quiet", "--no-report", "--workers", "1"])
    (line,) = o.stderr.splitlines()
    assert o.code == 2 and "E_arm must be a positive finite number (MPa), got -5.0" in line, o.stderr
    assert not (root / "stiffmap.db").exists()


def test_3rps_whose_legs_are_beam_links_equals_a_frame_finite_element_model():
    # Each leg a steel tube as a link (its actuator and bending spring made rigid), of the leg's
    # length at the pose: K6 equals tests/helpers/frame_fe's model of beams from revolute joints
    # at the base to balls at the platform (three elements a leg), condensed on the platform.
    from helpers.frame_fe import rps_leg_platform_stiffness

    E, G, A, I, J = 2.1e5, 8.1e4, 113.1, 4637.0, 9274.0
    ang = np.radians([90.0, 210.0, 330.0])
    ring = np.stack([np.cos(ang), np.sin(ang), 0 * ang], axis=1)
    base, attach = RPS3["base_radius_mm"] * ring, RPS3["platform_radius_mm"] * ring
    axes = np.stack([-np.sin(ang), np.cos(ang), 0 * ang], axis=1)
    head, *legs = rps3_toml({"k_leg": 1e12, "k_bend": math.inf}).split("\n[[legs]]\n")
    for z, roll, pitch in ((250.0, 0.0, 0.0), (270.0, 0.12, -0.08), (230.0, -0.15, 0.1)):
        pose = rps_pose(z, roll, pitch, attach, axes)
        tips = pose[:3] + attach @ rpy_matrix(*pose[3:]).T
        lengths = np.linalg.norm(tips - base, axis=1)
        text = head
        for i, (lg, L) in enumerate(zip(legs, lengths, strict=True), start=1):
            table = f"""
[[legs.links]]
after = "stroke"
name = "tube{i}"
[legs.links.beam]
length_mm = {float(L)!r}
E_MPa = {E}
G_MPa = {G}
area_mm2 = {A}
Iy_mm4 = {I}
Iz_mm4 = {I}
J_mm4 = {J}
axis = "z"
"""
            text += f"\n[[legs]]\n{lg.rstrip()}\n{table}"
        K6 = LegRobot.from_toml_text(text, source="3rps_beams.toml").stiffness6(pose)
        K6_fe = rps_leg_platform_stiffness(base, axes, tips, pose[:3], E, G, A, I, J, n_elements=3)
        # 1e-6: the actuators' 1e12 N/mm in series adds 1e-7 of the tubes' axial compliance
        err = np.linalg.norm(_scaled(K6 - K6_fe, 100.0)) / np.linalg.norm(_scaled(K6_fe, 100.0))
        assert err < 1e-6, pose


def test_cli_names_arms_the_data_cannot_separate_from_the_actuators(tmp_path, monkeypatch, capsys):
    """The shipped delta_links at 3 positions x 6 readings with 20 um of noise: k_theta and E_arm
    correlated -0.9997, E_arm's standard error several times its value (condition 89, below the
    1e3 warning): one warning naming the pair, exit 1, with --json too. The noise-free fit of
    the test above (same correlation, errors ~0) stays exit 0."""
    from helpers.cli_process import run_in_process as cli

    truth = LegRobot.from_toml(ROBOTS / "delta_links.toml")
    rng = np.random.default_rng(2)
    P, F, U, y = _static_error_data(truth, rng, n=3)
    y = y + rng.normal(0.0, 0.02, y.size)
    f = fit_static_errors(truth, P, F, U, y, params=("k_theta", "E_arm"))
    assert f.condition < 1e3 and f.correlation[0, 1] < -0.99 and f.std[1] > f.estimate[1]  # the case
    rows = ["x,y,z,fx,fy,fz,nx,ny,nz,value_mm"]
    rows += [",".join(repr(float(v)) for v in (*p, *q, *u, v)) for p, q, u, v in zip(P, F, U, y, strict=True)]
    meas = tmp_path / "meas.csv"
    meas.write_text("\n".join(rows) + "\n")
    for extra in ([], ["--json"]):
        code, out, err = cli(["fit", "legs", "delta_links", meas, *extra], monkeypatch, capsys)
        lines = [s for s in err.splitlines() if s.startswith("warning:")]
        assert code == 1 and len(lines) == 1, err
        assert "the data cannot separate E_arm from k_theta (correlation -0.99" in lines[0]
