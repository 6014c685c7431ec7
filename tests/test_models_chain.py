"""Kinematic chains through Pinocchio (stiffmap.models.chain): Jacobians, units, IK, bad URDFs."""

from __future__ import annotations

import math
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from stiffmap.errors import InputError
from stiffmap.models.chain import Chain, JointSpec

ARM6 = str(files("stiffmap.models") / "robots" / "arm6.urdf")


def _fd_jacobian(chain: Chain, q: np.ndarray, h: float) -> np.ndarray:
    """Central differences of the forward kinematics: velocity rows, and angular rows from R(q+h) R(q-h)^T."""
    J = np.zeros((6, chain.n))
    for k in range(chain.n):
        dq = np.zeros(chain.n)
        dq[k] = h
        pp, Rp = chain.forward(q + dq)
        pm, Rm = chain.forward(q - dq)
        J[:3, k] = (pp - pm) / (2 * h)
        J[3:, k] = Rotation.from_matrix(Rp @ Rm.T).as_rotvec() / (2 * h)
    return J


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (30.0, -20.0, 120.0)])
def test_arm_jacobian_matches_central_differences_at_random_configurations(offset):
    chain = Chain.from_urdf(ARM6, "tool0", offset)
    rng = np.random.default_rng(13)
    for _ in range(5):
        q = rng.uniform(chain.lower, chain.upper)
        J = chain.jacobian(q)
        Jn = _fd_jacobian(chain, q, 1e-5)
        # Each column relative to its own size (a joint's lever arm): the 1e-6.
        rel = np.linalg.norm(J - Jn, axis=0) / np.linalg.norm(J, axis=0)
        assert rel.max() < 1e-6, rel


def test_urdf_metres_become_millimetres_once():
    """At q = 0 the flange is at x = 70 + 190 + 190 + 65 mm, z = 352 + 360 mm (the URDF's metres)."""
    chain = Chain.from_urdf(ARM6, "tool0", (0.0, 0.0, 100.0))
    p, R = chain.forward(np.zeros(6))
    # tool0's z axis points along +x at q = 0, so the 100 mm offset adds along x.
    np.testing.assert_allclose(p, [70 + 190 + 190 + 65 + 100, 0, 352 + 360], atol=1e-9)
    np.testing.assert_allclose(R[:, 2], [1, 0, 0], atol=1e-12)
    # Joint 1 (about z) moves the point by its distance from the z axis per rad.
    np.testing.assert_allclose(chain.jacobian(np.zeros(6))[:3, 0], [0, 615.0, 0], atol=1e-9)
    assert chain.joint_names == tuple(f"joint_{k}" for k in range(1, 7))
    np.testing.assert_allclose(chain.lower[1], -1.5708)


def test_prismatic_chain_from_joints_is_in_mm():
    """A cylindrical robot (turn about z, lift along z, reach along x): closed-form FK and Jacobian."""
    chain = Chain.from_joints(
        [
            JointSpec("turn", "revolute", (0, 0, 1)),
            JointSpec("lift", "prismatic", (0, 0, 1), xyz_mm=(0, 0, 100)),
            JointSpec("reach", "prismatic", (1, 0, 0), xyz_mm=(50, 0, 0)),
        ],
        (10.0, 0.0, 0.0),
        name="cylindrical",
    )
    q = np.array([0.4, 30.0, 200.0])
    p, _ = chain.forward(q)
    r = 50 + 200 + 10
    np.testing.assert_allclose(p, [r * math.cos(0.4), r * math.sin(0.4), 130.0], atol=1e-9)
    J = chain.jacobian(q)
    np.testing.assert_allclose(J[:3, 0], [-r * math.sin(0.4), r * math.cos(0.4), 0], atol=1e-9)
    np.testing.assert_allclose(J[:, 1], [0, 0, 1, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(J[:3, 2], [math.cos(0.4), math.sin(0.4), 0], atol=1e-12)
    assert chain.joint_types == ("revolute", "prismatic", "prismatic")


def test_reach_holds_every_configuration_and_is_nearly_reached():
    """arm6's reach (a sphere about joint_1's origin, the sum of the distances between its joints'
    origins and the tool point): 20000 configurations drawn within the joint limits all lie inside
    it, the farthest within 1 % of it (0.04 % measured); a chain with an unlimited prismatic joint
    (the cylindrical robot of the test above) has no finite reach."""
    chain = Chain.from_urdf(ARM6, "tool0", (0.0, 0.0, 100.0))
    centre, radius = chain.reach_mm()
    np.testing.assert_allclose(centre, [0.0, 0.0, 0.0], atol=1e-9)  # joint_1's <origin xyz="0 0 0"/>
    Q = np.random.default_rng(5).uniform(chain.lower, chain.upper, (20000, chain.n))
    d = np.linalg.norm(chain.forward_many(Q)[0] - centre, axis=1)
    assert d.max() <= radius < 1.01 * d.max()
    joints = [JointSpec("turn", "revolute", (0, 0, 1)), JointSpec("lift", "prismatic", (0, 0, 1))]
    cylindrical = Chain.from_joints(joints, (10.0, 0.0, 0.0))
    assert cylindrical.reach_mm()[1] == math.inf


def test_inverse_kinematics_returns_the_configuration_of_the_seed_branch():
    chain = Chain.from_urdf(ARM6, "tool0", (0.0, 0.0, 80.0))
    q = np.radians([20.0, 30.0, -60.0, 15.0, 50.0, -30.0])
    p, R = chain.forward(q)
    r = chain.inverse(p, R, q0=q + 0.15)
    assert r.converged and r.position_error_mm < 1e-8 and r.rotation_error_rad < 1e-10
    np.testing.assert_allclose(r.q, q, atol=1e-9)
    # Position only (a redundant task): the point is reached, whatever the wrist does.
    r3 = chain.inverse(p + [5.0, -5.0, 5.0], q0=q)
    assert r3.converged
    np.testing.assert_allclose(chain.forward(r3.q)[0], p + [5.0, -5.0, 5.0], atol=1e-8)


def test_bad_urdfs_are_named(tmp_path):
    bad_xml = tmp_path / "broken.urdf"
    bad_xml.write_text("<robot name='x'><link name='a'/><joint")
    with pytest.raises(InputError, match=r"broken\.urdf: not a valid XML file"):
        Chain.from_urdf(bad_xml, "a")
    not_urdf = tmp_path / "scene.urdf"
    not_urdf.write_text("<scene/>")
    with pytest.raises(InputError, match=r"scene\.urdf: not a URDF: the root element is <scene>"):
        Chain.from_urdf(not_urdf, "a")
    dangling = tmp_path / "dangling.urdf"
    dangling.write_text(
        "<robot name='x'><link name='a'/><joint name='j' type='revolute'><parent link='a'/>"
        "<child link='missing'/><axis xyz='0 0 1'/><limit lower='-1' upper='1' effort='1' velocity='1'/>"
        "</joint></robot>"
    )
    with pytest.raises(
        InputError, match=r"dangling\.urdf: joint 'j' names child link 'missing', which the file"
    ):
        Chain.from_urdf(dangling, "a")
    with pytest.raises(InputError, match=r"arm6\.urdf: no frame 'flange9'.*links are: base_link, link_1"):
        Chain.from_urdf(ARM6, "flange9")
    with pytest.raises(InputError, match=r"no joint moves frame 'base_link'"):
        Chain.from_urdf(ARM6, "base_link")
    with pytest.raises(InputError, match=r"arm6\.urdf: .*5 value\(s\); stiffmap_arm6 has 6 joints \(joint_1"):
        Chain.from_urdf(ARM6, "tool0").forward(np.zeros(5))
    floating = tmp_path / "float.urdf"
    floating.write_text(
        "<robot name='x'><link name='a'/><link name='b'/><joint name='free' type='floating'>"
        "<parent link='a'/><child link='b'/></joint></robot>"
    )
    with pytest.raises(
        InputError, match=r"float\.urdf: joint 'free' \(on the chain from 'a' to 'b'\) is floating"
    ):
        Chain.from_urdf(floating, "b")
    with pytest.raises(InputError, match=r"nowhere\.urdf: cannot read"):
        Chain.from_urdf(tmp_path / "nowhere.urdf", "a")


def test_a_one_joint_chain_has_a_six_by_one_jacobian():
    # Pinocchio returns a one-joint chain's Jacobian as a vector; the chain keeps it 6 x 1
    # (a leg reduced to its actuator, found by the legs TOML fuzz test).
    c = Chain.from_joints([JointSpec("p", "prismatic", (0.0, 0.6, 0.8), (10.0, 0.0, 0.0))])
    J = c.jacobian([5.0])
    assert J.shape == (6, 1)
    h = 1e-6
    fd = (c.forward([5.0 + h])[0] - c.forward([5.0 - h])[0]) / (2 * h)
    np.testing.assert_allclose(J[:3, 0], fd, rtol=0, atol=1e-9)
    res = c.inverse([10.0, 6.0, 8.0], q0=[1.0])
    assert res.converged and res.q[0] == pytest.approx(10.0, abs=1e-9)


ROBOTS = Path(__file__).parent / "robots"


@pytest.mark.parametrize(
    "chain",
    [
        pytest.param(lambda: Chain.from_urdf(ARM6, "tool0", (30.0, -20.0, 120.0)), id="arm6"),
        pytest.param(
            lambda: Chain.from_urdf(ROBOTS / "palletizer_4ax.urdf", "tool0", (10.0, 0, 5.0)), id="mimics"
        ),
        pytest.param(
            lambda: Chain.from_urdf(
                ROBOTS / "cluttered_mm.urdf", "r_tool0", (0, 0, 40.0), base_frame="base_link"
            ),
            id="prismatic",
        ),
    ],
)
def test_many_configurations_at_once_are_pinocchio_s_one_by_one(chain):
    """``forward_many``, ``jacobian_many`` and ``mimic_jacobian_many`` (NumPy over all the
    configurations at once) equal Pinocchio's ``forward``, ``jacobian`` and ``mimic_jacobian``
    called configuration by configuration (mm, rad), at 200 random configurations."""
    c = chain()
    lo = np.where(np.isfinite(c.lower), c.lower, -np.pi)
    hi = np.where(np.isfinite(c.upper), c.upper, np.pi)
    Q = np.random.default_rng(7).uniform(lo, hi, size=(200, c.n))
    p, R = c.forward_many(Q)
    one = [c.forward(q) for q in Q]
    assert np.allclose(p, [o[0] for o in one], rtol=0, atol=1e-9)
    assert np.allclose(R, [o[1] for o in one], rtol=0, atol=1e-12)
    assert np.allclose(c.jacobian_many(Q), [c.jacobian(q) for q in Q], rtol=0, atol=1e-9)
    assert np.allclose(c.mimic_jacobian_many(Q), [c.mimic_jacobian(q) for q in Q], rtol=0, atol=1e-9)
    assert c.forward_many(Q[:0])[0].shape == (0, 3) and c.jacobian_many(Q[:1]).shape == (1, 6, c.n)
