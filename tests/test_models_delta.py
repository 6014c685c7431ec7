"""Delta robot model: kinematics, Jacobian, stiffness, default geometry, bad poses."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from helpers.finite_difference import central_jacobian
from helpers.mechanism_checks import assert_jacobian_matches_fd, random_reachable_poses

from stiffmap.models import DeltaRobot, Mechanism, PoseError
from stiffmap.models.presets import paper48

BOX_LO = (-250.0, -250.0, -450.0)
BOX_HI = (250.0, 250.0, -180.0)


def test_delta_is_a_mechanism():
    d = DeltaRobot()
    assert isinstance(d, Mechanism)
    assert (d.name, d.dim) == ("delta", 3)


def test_ik_closes_every_leg_and_fk_inverts_it(rng):
    d = DeltaRobot()
    P = random_reachable_poses(d, rng, 300, BOX_LO, BOX_HI, margin=0.0)
    L = d.legs(P)
    # |C_i - B_i| = b and |B_i - A_i| = a for every leg (mm).
    np.testing.assert_allclose(np.linalg.norm(L.C - L.B, axis=2), d.forearm_length, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(L.B - L.A, axis=2), d.arm_length, atol=1e-9)
    # Elbow-out branch everywhere: each elbow is farther from the z axis than its actuator axis
    # would put an inward-folded one (radial coordinate of B above that of A minus a).
    radial_B = np.einsum("nij,nij->ni", L.B, L.A) / d.base_radius
    assert np.all(radial_B > d.base_radius - 0.2 * d.arm_length)
    np.testing.assert_allclose(d.forward_kinematics(L.theta), P, atol=1e-8)
    # And the other way: random actuator angles -> FK -> IK gives the angles back.
    th = d.inverse_kinematics(P).q + rng.normal(scale=0.01, size=P.shape)
    P2 = d.forward_kinematics(th)
    np.testing.assert_allclose(d.inverse_kinematics(P2).q, th, atol=1e-10)


def test_jacobian_matches_central_differences(rng):
    d = DeltaRobot()
    P = random_reachable_poses(d, rng, 200, BOX_LO, BOX_HI)
    J = assert_jacobian_matches_fd(d, P, h=1e-3, atol=1e-6)
    # The forward-kinematic Jacobian dP/dtheta is its inverse (FD of forward_kinematics).
    th = d.inverse_kinematics(P).q
    Jf = central_jacobian(d.forward_kinematics, th, 1e-6)
    Jinv = np.linalg.inv(J)
    scale = np.linalg.norm(Jinv, axis=(1, 2))[:, None, None]
    np.testing.assert_allclose(Jinv / scale, Jf / scale, rtol=0, atol=1e-6)


def test_rigid_links_give_gosselin_stiffness(rng):
    d = DeltaRobot(k_theta=3.3e5)
    P = random_reachable_poses(d, rng, 100, BOX_LO, BOX_HI)
    J = d.jacobian(P)
    K = d.stiffness(P)
    Kg = d.k_theta * np.einsum("nji,njk->nik", J, J)  # K = J^T K_theta J (Gosselin 1990)
    np.testing.assert_allclose(K, Kg, rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(K, np.swapaxes(K, 1, 2))
    assert np.all(np.linalg.eigvalsh(K) > 0)


def _generalised_fk(d: DeltaRobot, theta, w, e, P0):
    """Tool position for actuator angles theta (rad), arm-tip deflections w (mm, in the leg plane,
    perpendicular to the arm) and forearm elongations e (mm), by Newton from P0: independent of
    the model's closed forms."""
    phi = np.asarray(d.leg_angles)
    E = np.stack([np.cos(phi), np.sin(phi), np.zeros(3)], axis=1)
    z = np.array([0.0, 0.0, 1.0])
    arm = np.cos(theta)[:, None] * E - np.sin(theta)[:, None] * z
    tang = -np.sin(theta)[:, None] * E - np.cos(theta)[:, None] * z
    B = d.base_radius * E + d.arm_length * arm + w[:, None] * tang
    P = P0.copy()
    for _ in range(50):
        D = P + d.platform_radius * E - B
        f = np.einsum("ij,ij->i", D, D) - (d.forearm_length + e) ** 2
        step = np.linalg.solve(2 * D, f)
        P = P - step
        if np.max(np.abs(step)) < 1e-13:
            break
    return P


def test_link_compliances_match_virtual_work(rng):
    # Independent check of 1/k_leg = (n.t)^2/k_theta + (n.t/a)^2/k_arm + 1/k_forearm: the
    # compliance C = G diag(1/k) G^T from the Jacobian G of the generalised forward kinematics in
    # (theta, w, e), by central differences (principle of virtual work).
    d = DeltaRobot(k_theta=2.0e5, k_arm=800.0, k_forearm=5000.0)
    kdiag = np.repeat([d.k_theta, d.k_arm, d.k_forearm], 3)
    P = random_reachable_poses(d, rng, 8, BOX_LO, BOX_HI, margin=0.2)
    for p in P:
        th0 = d.inverse_kinematics(p).q[0]
        q0 = np.concatenate([th0, np.zeros(6)])
        h = np.array([1e-6] * 3 + [1e-4] * 6)
        G = central_jacobian(lambda q, p=p: _generalised_fk(d, *np.split(q, 3), p), q0, h)
        C = G @ np.diag(1 / kdiag) @ G.T
        np.testing.assert_allclose(np.linalg.inv(d.stiffness(p)), C, rtol=1e-6, atol=1e-9 * np.abs(C).max())


def test_compliances_in_series_lower_stiffness():
    P = paper48()
    K0 = DeltaRobot().stiffness(P)
    K1 = DeltaRobot(k_arm=2000.0, k_forearm=20000.0).stiffness(P)
    # K0 - K1 is positive semi-definite: adding compliance in series can only soften the robot.
    assert np.all(np.linalg.eigvalsh(K0 - K1) > -1e-9)
    assert np.all(np.linalg.det(K1) < np.linalg.det(K0))


def test_default_geometry_holds_reference_grid_far_from_singularities():
    d = DeltaRobot()
    m = d.evaluate(paper48())
    assert m.valid.all() and all(r == "" for r in m.reasons)
    # The whole box the grid spans, densely: both singularity measures stay >= 0.4.
    g = np.linspace(-200, 200, 21)
    box = np.array([(x, y, z) for z in np.linspace(-400, -200, 11) for y in g for x in g])
    s, p = d.singularity_measures(box)
    assert d.evaluate(box).valid.all()
    assert s.min() >= 0.4 and p.min() >= 0.4


def test_default_stiffness_is_of_the_order_the_reference_study_measured():
    # Reference vision study, Section 5: largest det K = 873.27 (N/mm)^3 at the centre of the upper
    # plane; stiffness higher in the centre than at the border; Table III principal stiffnesses of
    # the order of 0.5-20 N/mm.
    m = DeltaRobot().evaluate(paper48())
    centre = np.argmin(np.linalg.norm(m.points - [-66.67, 66.67, -200.0], axis=1))
    assert m.det[centre] == pytest.approx(873.27, rel=0.01)
    assert m.det.max() == pytest.approx(m.det[centre], rel=1e-9)
    assert m.points[np.argmax(m.det), 2] == -200.0
    upper = m.points[:, 2] == -200.0
    corner = upper & (np.abs(m.points[:, 0]) == 200) & (np.abs(m.points[:, 1]) == 200)
    inner = upper & (np.abs(m.points[:, 0]) < 100) & (np.abs(m.points[:, 1]) < 100)
    assert m.det[corner].max() < m.det[inner].min()
    assert 0.5 <= m.eigenvalues.min() and m.eigenvalues.max() <= 25.0


def test_static_error_is_compliance_times_force(rng):
    d = DeltaRobot()
    P = paper48()
    F = rng.normal(scale=5.0, size=P.shape)
    u = d.static_error(P, F)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", d.stiffness(P), u), F, atol=1e-9)
    np.testing.assert_allclose(d.static_error(P, 2 * F), 2 * u, rtol=1e-12)
    np.testing.assert_allclose(d.static_error(P[3], F[3]), u[3], rtol=1e-12)
    np.testing.assert_allclose(d.evaluate(P).static_error(F), u, rtol=1e-12)


def test_unreachable_single_pose_is_named():
    d = DeltaRobot()
    for call in (d.stiffness, d.jacobian, lambda p: d.static_error(p, [0, 0, -5.0])):
        with pytest.raises(PoseError, match=r"pose \(0, 0, 0\) mm unreachable: leg 1 too close") as e:
            call([0.0, 0.0, 0.0])
        assert e.value.pose == (0.0, 0.0, 0.0)
    with pytest.raises(PoseError, match=r"point 1: pose \(0, 0, -2000\) mm unreachable: leg 1 too far"):
        d.stiffness([[0, 0, -300.0], [0, 0, -2000.0]])


def test_map_flags_bad_points_and_keeps_the_others():
    d = DeltaRobot()
    P = np.array([[0, 0, -300.0], [0, 0, 0.0], [50, -20, -350.0], [900, 0, -300.0]])
    m = d.evaluate(P)
    np.testing.assert_array_equal(m.valid, [True, False, True, False])
    assert [bool(r) for r in m.reasons] == [False, True, False, True]
    assert all(r.startswith("unreachable: ") for r in np.array(m.reasons)[~m.valid])
    assert np.all(np.isnan(m.K[~m.valid])) and np.all(np.isfinite(m.K[m.valid]))
    assert np.all(np.isnan(m.det[~m.valid])) and np.all(np.isfinite(m.det[m.valid]))
    np.testing.assert_allclose(m.K[m.valid], d.stiffness(P[m.valid]), rtol=1e-12)
    u = m.static_error([0, 0, -1.0])
    assert np.all(np.isnan(u[~m.valid])) and np.all(np.isfinite(u[m.valid]))


def test_workspace_boundary_is_a_serial_singularity(rng):
    # Bisect along random rays from the centre to the edge of the workspace: just inside it a leg
    # is stretched (arm and forearm aligned), the pose is flagged singular with the leg named.
    d = DeltaRobot()
    c = np.array([0.0, 0.0, -300.0])
    for _ in range(5):
        v = rng.normal(size=3)
        v /= np.linalg.norm(v)
        lo, hi = 0.0, 2000.0
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if d.inverse_kinematics(c + mid * v).reachable[0] else (lo, mid)
        p = c + lo * v
        s, _ = d.singularity_measures(p)
        assert s[0] < 1e-3
        m = d.evaluate(p)
        assert not m.valid[0]
        assert m.reasons[0].startswith("singular: arm and forearm of leg ")
        with pytest.raises(PoseError, match="serial singularity"):
            d.stiffness(p)
        # A few mm inside, the pose is regular again and the stiffness is large along the leg.
        assert d.evaluate(c + (lo - 5.0) * v).valid[0]


def test_coplanar_forearms_are_a_parallel_singularity():
    # With forearms shorter than R + a - r, the platform can sit level with the elbows: all three
    # forearms horizontal and radial, coplanar, no vertical stiffness. cos(theta) = (r + b - R)/a.
    d = DeltaRobot(base_radius=200.0, platform_radius=50.0, arm_length=250.0, forearm_length=200.0)
    th = math.acos((50.0 + 200.0 - 200.0) / 250.0)
    p = np.array([0.0, 0.0, -250.0 * math.sin(th)])
    np.testing.assert_allclose(d.inverse_kinematics(p).q, [[th] * 3], atol=1e-12)
    _, par = d.singularity_measures(p)
    assert par[0] < 1e-12
    m = d.evaluate(p)
    assert not m.valid[0] and "parallel singularity" in m.reasons[0]
    with pytest.raises(PoseError, match="forearms nearly coplanar"):
        d.static_error(p, [0, 0, -1.0])
    # 20 mm lower the pose is regular, with a small vertical stiffness.
    q = p - [0, 0, 20.0]
    K = d.stiffness(q)
    assert K[2, 2] < 0.1 * min(K[0, 0], K[1, 1])


@pytest.mark.parametrize(
    "name",
    ["base_radius", "platform_radius", "arm_length", "forearm_length", "k_theta", "k_arm", "k_forearm"],
)
@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan])
def test_non_positive_parameters_are_refused(name, bad):
    with pytest.raises(ValueError, match=f"{name} must be a positive number"):
        DeltaRobot().with_params(**{name: bad})


def test_with_params_is_immutable_and_checks_names():
    d = DeltaRobot()
    d2 = d.with_params(k_theta=1e5, k_arm=math.inf)
    assert d.k_theta == 2.77e5 and d2.k_theta == 1e5 and d2.arm_length == d.arm_length
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.k_theta = 1.0  # type: ignore[misc]
    with pytest.raises(ValueError, match=r"unknown Delta parameter\(s\) ktheta; valid: base_radius, "):
        d.with_params(ktheta=1.0)
    with pytest.raises(ValueError, match="three different directions"):
        DeltaRobot(leg_angles=(0.0, 0.0, 1.0))
    with pytest.raises(ValueError, match=r"points must have shape \(N, 3\)"):
        d.stiffness([[1.0, 2.0]])
    with pytest.raises(ValueError, match="row 1 is not finite"):
        d.evaluate([[0, 0, -300.0], [0, math.nan, -300.0]])
