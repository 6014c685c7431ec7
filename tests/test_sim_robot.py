"""Virtual robot: stiffness fields, compliant motion (3x3 and 6x6), repeatability."""

from __future__ import annotations

import numpy as np
import pytest

from stiffmap.geometry import displacement_from_poses, transform_from
from stiffmap.models.delta import DeltaRobot
from stiffmap.models.presets import paper48
from stiffmap.sim.robot import (
    VirtualRobot,
    delta_robot,
    smooth_field,
    translational_stiffness,
    with_rotational_compliance,
)


def test_smooth_field_is_symmetric_positive_definite_and_smooth():
    P = paper48()
    K = smooth_field(P)
    assert K.shape == (48, 3, 3)
    np.testing.assert_allclose(K, np.swapaxes(K, 1, 2), atol=1e-12)  # N/mm
    w = np.linalg.eigvalsh(K)
    assert w.min() > 0.5 and w.max() < 15.0  # N/mm
    # At the reference point the principal stiffnesses are 2, 4, 9 N/mm.
    np.testing.assert_allclose(
        np.linalg.eigvalsh(smooth_field([[0.0, 0.0, -300.0]])[0]), [2, 4, 9], atol=1e-12
    )
    # Smooth: 1 mm away K changes by < 1 %.
    for e in np.eye(3):
        d = smooth_field(P + e) - K
        assert np.max(np.linalg.norm(d, axis=(1, 2)) / np.linalg.norm(K, axis=(1, 2))) < 0.01


def test_delta_robot_is_the_models_stiffness():
    rb = delta_robot({"k_theta": 3.0e5})
    P = paper48()[:5]
    np.testing.assert_allclose(rb.stiffness(P), DeltaRobot(k_theta=3.0e5).stiffness(P), rtol=1e-14)
    assert rb.model == "delta" and rb.params["k_theta"] == 3.0e5
    assert all(np.isfinite(v) for v in rb.params.values())  # rigid links (inf) left out


def test_three_by_three_motion_is_compliance_times_force(rng):
    rb = VirtualRobot(smooth_field, repeatability_mm=0.0, repeatability_rad=0.0, jitter_mm=0.0)
    K = rb.stiffness([[50.0, -20.0, -250.0]])[0]
    F = rng.normal(size=3) * 3
    T0 = transform_from(np.eye(3), [50.0, -20.0, -250.0])
    T1 = rb.image_pose(T0, rng, K, F)
    np.testing.assert_allclose(T1[:3, 3] - T0[:3, 3], np.linalg.solve(K, F), atol=1e-12)  # mm
    np.testing.assert_array_equal(T1[:3, :3], np.eye(3))
    np.testing.assert_allclose(K @ (T1[:3, 3] - T0[:3, 3]), F, atol=1e-10)  # N


def test_six_by_six_motion_and_its_translational_stiffness(rng):
    # Loads hung 30 mm below the tool point on a platform with rotational compliance
    # and coupling: the tool point moves by (C_tt + C_tr [r]x) F and the body turns.
    field6 = with_rotational_compliance(smooth_field, 2.0e4, coupling_n=40.0)
    r = (0.0, 0.0, -30.0)
    rb = VirtualRobot(field6, repeatability_mm=0, repeatability_rad=0, jitter_mm=0, load_point_mm=r)
    p = np.array([100.0, 50.0, -300.0])
    K6 = rb.stiffness([p])[0]
    assert K6.shape == (6, 6)
    F = np.array([1.0, -2.0, 3.0])
    u, w = rb.compliant_motion(K6, F)
    wrench = np.r_[F, np.cross(r, F)]
    np.testing.assert_allclose(K6 @ np.r_[u, w], wrench, atol=1e-10)
    K3 = translational_stiffness(K6, r)
    np.testing.assert_allclose(K3 @ u, F, atol=1e-10)
    # The rotation changes the measured displacement of a board point away from the tcp
    # by w x (point - tcp); at the tool point it is exactly u.
    T0 = transform_from(np.eye(3), p)
    T1 = rb.image_pose(T0, rng, K6, F)
    np.testing.assert_allclose(displacement_from_poses(T0, T1), np.r_[u, w], atol=1e-12)
    off = np.array([25.0, -15.0, 50.0])
    d = displacement_from_poses(T0, T1, off)[:3]
    R1 = T1[:3, :3]
    np.testing.assert_allclose(d, u + (R1 - np.eye(3)) @ off, atol=1e-12)
    assert np.linalg.norm(w) > 1e-5  # the coupling and the lever really turn the platform


def test_repeatability_statistics():
    rb = VirtualRobot(smooth_field, repeatability_mm=0.02, repeatability_rad=1e-4, jitter_mm=0.0)
    rng = np.random.default_rng(5)
    T = np.array([rb.reach([0.0, 0.0, -300.0], rng) for _ in range(4000)])
    dt = T[:, :3, 3] - [0.0, 0.0, -300.0]
    np.testing.assert_allclose(dt.std(axis=0), 0.02, rtol=0.05)  # mm
    assert np.abs(dt.mean(axis=0)).max() < 0.002  # mm
    ang = np.arccos(np.clip((np.trace(T[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1, 1))
    assert np.sqrt(np.mean(ang**2)) == pytest.approx(np.sqrt(3) * 1e-4, rel=0.05)  # rad


def test_bad_fields_and_values_are_refused():
    with pytest.raises(ValueError, match="shape"):
        VirtualRobot(lambda p: np.ones((len(p), 2, 2))).stiffness([[0.0, 0.0, -300.0]])
    with pytest.raises(ValueError, match="not positive definite"):
        VirtualRobot(lambda p: -smooth_field(p)).stiffness([[0.0, 0.0, -300.0]])
    with pytest.raises(ValueError, match="not finite"):
        VirtualRobot(lambda p: smooth_field(p) * np.nan).stiffness([[0.0, 0.0, -300.0]])
    with pytest.raises(ValueError, match="repeatability_mm"):
        VirtualRobot(smooth_field, repeatability_mm=-1.0)
    with pytest.raises(ValueError, match="k_rot"):
        with_rotational_compliance(smooth_field, 0.0)
    with pytest.raises(ValueError, match="3x3 or 6x6"):
        translational_stiffness(np.eye(4))
    # The Delta model names an unreachable pose.
    with pytest.raises(ValueError, match="-900"):
        delta_robot().stiffness([[0.0, 0.0, -300.0], [0.0, 0.0, -900.0]])
