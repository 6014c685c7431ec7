"""Flexible links (stiffmap.models.links): beams and 6x6 compliances as 6-D springs on a chain.

- A planar two-link arm with flexible links and a compliant base joint equals a frame
  finite-element solution (anastruct: Euler-Bernoulli frame elements, a rotational support
  spring) to 1e-6.
- On the six-joint test arm with two flexible links (asymmetric sections, one Timoshenko) and
  a 6x6 compliance, C6 equals the independent computation with the links' springs as six
  virtual joints inserted in the URDF (helpers.urdf_reference: central differences) and the
  beam compliance written out in the test from the textbook formulas.
- LINKS.toml files: read, and every mistake one line naming the file and the table.
"""

from __future__ import annotations

import math
import tempfile
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
from helpers import urdf_reference as ref
from helpers.fuzz_campaign import mutated_spec, toml_text_mutations
from hypothesis import given
from hypothesis import strategies as st

from stiffmap.errors import InputError
from stiffmap.models.links import Beam, LinkSpring, beam_compliance
from stiffmap.models.robot_files import read_links_toml
from stiffmap.models.serial import SerialRobot

ARM6 = str(files("stiffmap.models") / "robots" / "arm6.urdf")
L1, L2 = 400.0, 300.0  # mm


def _planar_urdf(tmp_path: Path) -> Path:
    f = tmp_path / "planar2.urdf"
    f.write_text(
        f"""<robot name="planar2">
  <link name="base"/><link name="upper"/><link name="fore"/><link name="hand"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/><axis xyz="0 0 1"/>
    <limit lower="-3.14" upper="3.14" effort="1" velocity="1"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/>
    <origin xyz="{L1 / 1000} 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3.14" upper="3.14" effort="1" velocity="1"/></joint>
  <joint name="hand_mount" type="fixed"><parent link="fore"/><child link="hand"/>
    <origin xyz="{L2 / 1000} 0 0"/></joint>
</robot>"""
    )
    return f


def _beam(rng, length: float, **kw) -> Beam:
    return Beam(
        length_mm=length,
        E_MPa=rng.uniform(5e4, 2.1e5),
        G_MPa=rng.uniform(2e4, 8e4),
        area_mm2=rng.uniform(200, 2000),
        Iy_mm4=rng.uniform(1e5, 1e6),
        Iz_mm4=rng.uniform(1e5, 1e6),
        J_mm4=rng.uniform(2e5, 2e6),
        **kw,
    )


def _anastruct_tip_compliance(q1, q2, k1, b1: Beam, b2: Beam) -> np.ndarray:
    """(ux, uy, theta_z) per unit (Fx, Fy, Mz) at the tip: the arm as a frame of two
    Euler-Bernoulli elements, the shoulder a hinged support with a rotational spring k1."""
    from anastruct import SystemElements  # lazy: it loads matplotlib, for this test only

    E = (L1 * math.cos(q1), L1 * math.sin(q1))
    T = (E[0] + L2 * math.cos(q1 + q2), E[1] + L2 * math.sin(q1 + q2))
    C = np.zeros((3, 3))
    for col, load in enumerate(({"Fx": 1.0}, {"Fy": 1.0}, {"Tz": 1.0})):
        ss = SystemElements()
        ss.add_element([[0.0, 0.0], list(E)], EA=b1.E_MPa * b1.area_mm2, EI=b1.E_MPa * b1.Iz_mm4)
        ss.add_element([list(E), list(T)], EA=b2.E_MPa * b2.area_mm2, EI=b2.E_MPa * b2.Iz_mm4)
        ss.add_support_hinged(1)
        ss.add_support_spring(1, translation=3, k=k1)
        tip = ss.find_node_id(list(T))
        if "Tz" in load:
            ss.moment_load(tip, Tz=load["Tz"])
        else:
            ss.point_load(tip, **load)
        ss.solve()
        r = ss.get_node_displacements(tip)
        C[:, col] = (r["ux"], r["uy"], -r["phi_z"])  # anastruct's phi_z turns clockwise
    return C


def test_planar_arm_with_flexible_links_equals_a_frame_finite_element_solution(tmp_path, rng):
    urdf = _planar_urdf(tmp_path)
    for _ in range(4):
        q1, q2 = rng.uniform(-2.5, 2.5), rng.uniform(0.3, 2.5) * rng.choice([-1, 1])
        k1 = rng.uniform(2e7, 2e8)  # N*mm/rad
        b1, b2 = _beam(rng, L1), _beam(rng, L2)
        links = (
            LinkSpring("upper", "upper", None, np.eye(3), beam=b1),
            LinkSpring("fore", "fore", None, np.eye(3), beam=b2),
        )
        robot = SerialRobot.from_urdf(urdf, "hand", k_theta=(k1, math.inf), links=links)
        C6 = robot.compliance6(np.array([q1, q2]))
        C_planar = C6[np.ix_([0, 1, 5], [0, 1, 5])]
        C_fe = _anastruct_tip_compliance(q1, q2, k1, b1, b2)
        assert np.linalg.norm(C_planar - C_fe) < 1e-6 * np.linalg.norm(C_fe)
        # The links' part is not small: without them the arm is several times stiffer.
        C_rigid = SerialRobot.from_urdf(urdf, "hand", k_theta=(k1, math.inf)).compliance6(np.array([q1, q2]))
        assert np.linalg.norm(C_planar - C_rigid[np.ix_([0, 1, 5], [0, 1, 5])]) > 0.1 * np.linalg.norm(C_fe)


def _textbook_beam(b: Beam) -> np.ndarray:
    """A cantilever's tip compliance along its axis x (Timoshenko & Gere): axial L/EA, torsion
    L/GJ, bending PL^3/3EI and PL/kGA for the shear (Timoshenko), the couplings L^2/2EI."""
    L, E, G = b.length_mm, b.E_MPa, b.G_MPa
    C = np.zeros((6, 6))
    C[0, 0] = L / (E * b.area_mm2)
    C[3, 3] = L / (G * b.J_mm4)
    shear = 0.0 if b.shear_factor is None else L / (b.shear_factor * G * b.area_mm2)
    # bending in the x-y plane about z: a force along y turns the end about +z
    C[1, 1] = L**3 / (3 * E * b.Iz_mm4) + shear
    C[5, 5] = L / (E * b.Iz_mm4)
    C[1, 5] = C[5, 1] = L**2 / (2 * E * b.Iz_mm4)
    # bending in the x-z plane about y: a force along z turns the end about -y
    C[2, 2] = L**3 / (3 * E * b.Iy_mm4) + shear
    C[4, 4] = L / (E * b.Iy_mm4)
    C[2, 4] = C[4, 2] = -(L**2) / (2 * E * b.Iy_mm4)
    return C


def _with_virtual_joints(text: str, link: str, next_joint: str) -> str:
    """The URDF with six virtual joints (slides along x, y, z, turns about x, y, z) where
    ``next_joint`` (the joint after ``link`` on the chain) starts: the link's spring."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(text)
    nj = next(j for j in root.findall("joint") if j.get("name") == next_joint)
    origin = nj.find("origin")
    names = ["vx", "vy", "vz", "wx", "wy", "wz"]
    parent = link
    for i, nm in enumerate(names):
        ET.SubElement(root, "link", name=f"{link}_{nm}")
        j = ET.SubElement(root, "joint", name=f"{link}_{nm}", type="prismatic" if i < 3 else "revolute")
        ET.SubElement(j, "parent", link=parent)
        ET.SubElement(j, "child", link=f"{link}_{nm}")
        if i == 0 and origin is not None:
            ET.SubElement(j, "origin", xyz=origin.get("xyz", "0 0 0"))  # the spring keeps the link's axes
        ET.SubElement(j, "axis", xyz=" ".join("1" if k == i % 3 else "0" for k in range(3)))
        parent = f"{link}_{nm}"
    nj.find("parent").set("link", parent)
    if origin is not None:  # the joint's own orientation stays; its offset moved to the springs
        origin.set("xyz", "0 0 0")
    return ET.tostring(root, encoding="unicode")


def test_spatial_arm_with_flexible_links_equals_virtual_joints_inserted_in_its_urdf(tmp_path, rng):
    text = Path(ARM6).read_text()
    upper = _beam(rng, 360.0)
    fore = _beam(rng, 190.0, shear_factor=0.5)  # a thin tube, Timoshenko
    A = rng.normal(size=(6, 6))
    C_wrist = A @ A.T * 1e-7 + np.diag([1e-4, 1e-4, 1e-4, 1e-9, 1e-9, 1e-9])  # mm/N, rad/(N*mm)
    links = (
        LinkSpring("link_2", "upper", None, np.eye(3), beam=upper),
        LinkSpring("link_3", "fore", None, np.eye(3), beam=fore),
        LinkSpring("link_4", "wrist", None, np.eye(3), compliance=C_wrist),
    )
    k = np.array([2e7, 1.6e7, 1.2e7, 5e6, 4e6, 3e6])
    offset = (30.0, -20.0, 120.0)
    robot = SerialRobot.from_urdf(ARM6, "tool0", offset, k_theta=k, links=links)
    assert robot.param_names()[6:] == ("E_upper", "G_upper", "E_fore", "G_fore", "f_wrist")
    # the beams run along the links: the upper arm along z to joint 3, the forearm along x to joint 4
    assert [lk.beam.axis for lk in robot.links[:2]] == ["z", "x"]
    for link, nxt in (("link_2", "joint_3"), ("link_3", "joint_4"), ("link_4", "joint_5")):
        text = _with_virtual_joints(text, link, nxt)
    _, joints = ref.read_joints(text)
    chain = ref.path(joints, "tool0")
    coords = ref.coordinates(joints, chain)
    assert len(coords) == 6 + 18
    # each beam's axis x along the link (z for the upper arm: its y, z are the link's x, y)
    P = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], dtype=float).T  # beam axes in link_2's frame
    T6 = np.zeros((6, 6))
    T6[:3, :3] = T6[3:, 3:] = P
    C_upper = T6 @ _textbook_beam(upper) @ T6.T
    C_fore = _textbook_beam(fore)
    for _ in range(3):
        q = rng.uniform(robot.chain.lower, robot.chain.upper) * 0.8
        qv = np.concatenate([q[:2], np.zeros(6), q[2:3], np.zeros(6), q[3:4], np.zeros(6), q[4:]])
        order = [c for c in coords]
        J = ref.jacobian_fd(joints, chain, order, qv, offset)
        idx = {c: i for i, c in enumerate(order)}
        Jj = J[:, [idx[f"joint_{i}"] for i in range(1, 7)]]
        C = Jj @ np.diag(1 / k) @ Jj.T
        for link, Cs in (("link_2", C_upper), ("link_3", C_fore), ("link_4", C_wrist)):
            Jv = J[:, [idx[f"{link}_{nm}"] for nm in ("vx", "vy", "vz", "wx", "wy", "wz")]]
            C += Jv @ Cs @ Jv.T
        got = robot.compliance6(q)
        assert np.linalg.norm(got - C) < 1e-6 * np.linalg.norm(C), np.linalg.norm(got - C) / np.linalg.norm(C)
        assert np.linalg.norm(robot.stiffness6(q) @ got - np.eye(6)) < 1e-9
    # Parameters by name: E_upper doubled halves that beam's bending and axial compliance.
    stiff = robot.with_params(E_upper=2 * upper.E_MPa, f_wrist=4.0)
    assert stiff.links[0].beam.E_MPa == 2 * upper.E_MPa and stiff.links[2].factor == 4.0
    np.testing.assert_allclose(stiff.links[2].matrix(), C_wrist / 4, rtol=1e-15)


def test_beam_axes_follow_the_spring_frame():
    b = Beam(500.0, 7e4, 2.6e4, 300.0, 2e5, 5e5, 4e5)
    Cx = beam_compliance(Beam(**{**b.__dict__, "axis": "x"}))
    np.testing.assert_allclose(Cx, _textbook_beam(b), rtol=1e-14)
    for axis, cols in (("y", [1, 2, 0]), ("z", [2, 0, 1]), ("-x", None)):
        C = beam_compliance(Beam(**{**b.__dict__, "axis": axis}))
        if cols is not None:  # axis y: the beam's x, y, z are the frame's y, z, x
            P = np.eye(3)[:, cols]
            T = np.zeros((6, 6))
            T[:3, :3] = T[3:, 3:] = P
            np.testing.assert_allclose(C, T @ Cx @ T.T, rtol=1e-14)
        else:  # reversed: the same diagonal, the bending couplings change sign
            np.testing.assert_allclose(np.diag(C), np.diag(Cx), rtol=1e-14)
            assert C[1, 5] == pytest.approx(-Cx[1, 5]) and C[2, 4] == pytest.approx(-Cx[2, 4])


LINKS_TOML = """# the six-joint test arm's upper arm and forearm
[[links]]
link = "link_2"
name = "upper"
[links.beam]
length_mm = 360.0
E_MPa = 70000.0
G_MPa = 26000.0
area_mm2 = 1200.0
Iy_mm4 = 9.0e5
Iz_mm4 = 6.0e5
J_mm4 = 1.2e6

[[links]]
link = "link_3"
xyz_mm = [190.0, 0.0, 0.0]
compliance = [
  [2e-4, 0, 0, 0, 0, 0],
  [0, 3e-4, 0, 0, 0, 1e-6],
  [0, 0, 3e-4, 0, -1e-6, 0],
  [0, 0, 0, 1e-8, 0, 0],
  [0, 0, -1e-6, 0, 1e-8, 0],
  [0, 1e-6, 0, 0, 0, 1e-8],
]
"""


def test_a_links_file_reads_into_springs(tmp_path):
    f = tmp_path / "LINKS.toml"
    f.write_text(LINKS_TOML)
    upper, fore = read_links_toml(f)
    assert (upper.link, upper.name, fore.name) == ("link_2", "upper", "link_3")
    assert upper.origin_mm is None and upper.beam.Iz_mm4 == 6e5
    np.testing.assert_allclose(fore.origin_mm, [190, 0, 0])
    robot = SerialRobot.from_urdf(ARM6, "tool0", k_theta=1e7, links=(upper, fore))
    assert robot.link_param_names() == ("E_upper", "G_upper", "f_link_3")
    np.testing.assert_allclose(robot.links[0].origin_mm, [0, 0, 360.0])  # joint 3, where the link ends


@pytest.mark.parametrize(
    "old, new, message",
    [
        (
            'link = "link_2"',
            'link = "link_9"',
            "links[1]: link 'link_9' is not on the chain from 'base_link'",
        ),
        ("E_MPa = 70000.0", "E_MPa = -7.0", "links[1].beam.E_MPa: expected a positive number, got -7.0"),
        ("J_mm4 = 1.2e6\n", "", "links[1].beam: missing J_mm4"),
        ("Iy_mm4", "Ix_mm4", "links[1].beam.Ix_mm4: unknown key"),
        (
            "[0, 0, 0, 1e-8, 0, 0]",
            "[0, 0, 0, -1e-8, 0, 0]",
            "links[2].compliance: the compliance is not positive",
        ),
        (
            "[0, 1e-6, 0, 0, 0, 1e-8]",
            "[0, 2e-6, 0, 0, 0, 1e-8]",
            "links[2].compliance: a compliance matrix must be sym",
        ),
        ("[0, 1e-6, 0, 0, 0, 1e-8],\n", "", "links[2].compliance: expected a 6 x 6 matrix"),
        (
            "xyz_mm = [190.0, 0.0, 0.0]",
            "xyz_mm = [190.0, 0.0]",
            "links[2].xyz_mm: expected three finite numbers",
        ),
        ('name = "upper"', 'name = "upper arm"', "links[1].name: expected letters, digits and '_'"),
        ('name = "upper"', 'name = "link_3"', "links[2]: name 'link_3' is already used by links[1]"),
        (
            "[links.beam]",
            "compliance = 1\n[links.beam]",
            "links[1]: give either beam (its data) or compliance",
        ),
        (
            '[[links]]\nlink = "link_3"',
            '[[links]]\nlink = "link_3"\nstiffness = 1',
            "links[2].stiffness: unknown",
        ),
    ],
)
def test_bad_links_files_are_one_line_naming_the_file_and_the_table(tmp_path, old, new, message):
    assert old in LINKS_TOML
    f = tmp_path / "LINKS.toml"
    f.write_text(LINKS_TOML.replace(old, new, 1))
    with pytest.raises(InputError) as e:
        springs = read_links_toml(f)
        SerialRobot.from_urdf(ARM6, "tool0", k_theta=1e7, links=springs)
    assert str(e.value).startswith(f"{f}: ") and message in str(e.value), str(e.value)
    assert "\n" not in str(e.value)


def test_a_beam_at_its_links_origin_needs_its_axis(tmp_path):
    spring = LinkSpring(
        "link_5",
        "w",
        np.zeros(3),
        np.eye(3),
        beam=Beam(50.0, 7e4, 2.6e4, 300.0, 2e5, 2e5, 4e5),
        where="LINKS.toml: links[1]",
    )
    with pytest.raises(
        InputError, match=r"LINKS\.toml: links\[1\]\.beam\.axis: the spring frame is at link 'link_5'"
    ):
        SerialRobot.from_urdf(ARM6, "tool0", k_theta=1e7, links=(spring,))


@pytest.mark.fuzz
@given(data=st.data())
def test_mutated_links_files_load_or_are_refused_by_name(data):
    raw = data.draw(st.one_of(mutated_spec(LINKS_TOML), toml_text_mutations(LINKS_TOML)))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.toml"
        path.write_bytes(raw)
        try:
            springs = read_links_toml(path)
            robot = SerialRobot.from_urdf(ARM6, "tool0", k_theta=1e7, links=springs)
        except InputError as e:
            assert str(e).startswith(f"{path}: ") or str(e).startswith("links["), str(e)
            return
    C = robot.compliance6(np.radians([10.0, 20.0, -30.0, 10.0, 40.0, 0.0]))
    assert np.all(np.isfinite(C)) and np.array_equal(C, C.T) and np.all(np.diag(C) > 0)


def _light_arm(**kw) -> SerialRobot:
    """The test-bed's arm with aluminium tubes for upper arm and forearm (50 x 2 mm, 40 x 2 mm)."""
    from stiffmap.models import arm6

    def tube(length, D, t, **more):
        I = math.pi * D**3 * t / 8
        return Beam(length, 7.0e4, 2.6e4, math.pi * D * t, I, I, 2 * I, **more)

    links = (
        LinkSpring("link_2", "upper", None, np.eye(3), beam=tube(360.0, 50.0, 2.0)),
        LinkSpring("link_3", "fore", None, np.eye(3), beam=tube(190.0, 40.0, 2.0, **kw)),
    )
    return SerialRobot(arm6.model().chain, arm6.K_THETA, links=links)


def _design_rows(robot, rng, m: int = 20):
    """m configurations (the test-bed arm's positions, by IK) x 9 loads from its bracket."""
    from stiffmap.models import arm6

    Q = arm6.model().configurations_for(arm6.positions20()[:m]).q
    lever = np.asarray(arm6.LOAD_POINT_MM)
    forces = [np.eye(3)[i] * s * 5.0 for i in range(3) for s in (1, -1)] + [
        rng.normal(size=3) * 3 for _ in range(3)
    ]
    rows_q = np.repeat(Q, len(forces), axis=0)
    W = np.array([np.concatenate([f, np.cross(lever, f)]) for _ in Q for f in forces])
    return rows_q, W


def test_joint_and_link_parameters_fitted_together_and_what_cannot_be_separated_is_named(rng):
    from stiffmap.errors import DesignError
    from stiffmap.models.joint_fit import fit_joint_compliances, joint_identifiability

    robot = _light_arm()
    Qr, W = _design_rows(robot, rng)
    J = robot.chain.jacobian_many(Qr)
    cols = robot.link_columns(Qr)
    names = [f"k{i}" for i in range(1, 7)]
    # An Euler-Bernoulli forearm twists at its end about joint 4's axis, through joint 4's origin:
    # its G and k4 move the point alike.
    rep = joint_identifiability(J, W, joint_names=names, links=cols)
    assert not rep.determined and ("k4", "G_fore") in rep.confounded, rep.confounded
    assert rep.message.startswith("joint and link parameters k4, G_fore cannot be determined")
    with pytest.raises(DesignError, match="k4, G_fore change the measured displacements only in a fixed"):
        fit_joint_compliances(J, W, robot.deflection(Qr, W), joint_names=names, links=cols)
    # G_fore held at its value (1/G), the others fitted from noisy deflections: within 4 standard errors.
    sd = np.array([1e-3, 1e-3, 1e-3, 1e-5, 1e-5, 1e-5])  # mm, rad
    D = robot.deflection(Qr, W) + rng.normal(size=(len(W), 6)) * sd
    f = fit_joint_compliances(
        J, W, D, np.broadcast_to(sd, D.shape), joint_names=names, links=cols, fixed={"G_fore": 1 / 2.6e4}
    )
    true = dict(robot.params())
    for name in (*names, "E_upper", "G_upper", "E_fore"):
        j = f.names.index(name)
        assert abs(f.stiffness[j] - true[name]) < 4 * f.stiffness_std[j], (name, f.stiffness[j], true[name])
    assert f.stiffness_std[f.names.index("E_upper")] < 0.05 * 7e4  # the upper arm's E to a few %
    assert 0.6 < f.reduced_chi2 < 1.5
    np.testing.assert_allclose(D - f.predict(J, W, cols), f.residuals, atol=1e-12)


def test_spring_columns_carry_the_springs_compliance(rng):
    """The form a leg's assembly takes a flexible link in: six columns of unit compliance."""
    from stiffmap.models.links import spring_columns

    J = rng.normal(size=(3, 2, 6, 6))
    A = rng.normal(size=(2, 6, 6))
    C = A @ np.swapaxes(A, 1, 2) + np.eye(6)
    cols = spring_columns(J, C)
    ref = np.einsum("nsij,sjk,nslk->nil", J, C, J)
    assert cols.shape == (3, 6, 12)
    np.testing.assert_allclose(
        cols @ np.swapaxes(cols, 1, 2), ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max()
    )
