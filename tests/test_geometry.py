"""Geometry: transforms, the paper's Euler angles, rotation vectors, displacements."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from helpers.random_matrices import random_rotation
from scipy.spatial.transform import Rotation

from stiffmap import geometry as g


def _random_transform(rng):
    return g.transform_from(random_rotation(rng), rng.uniform(-500, 500, size=3))


def test_invert_and_concat_round_trip(rng):
    for _ in range(50):
        a2b = _random_transform(rng)
        b2c = _random_transform(rng)
        a2c = g.concat(a2b, b2c)
        p = rng.uniform(-100, 100, size=(7, 3))
        np.testing.assert_allclose(
            g.transform_points(a2c, p), g.transform_points(b2c, g.transform_points(a2b, p)), atol=1e-9
        )
        np.testing.assert_allclose(g.concat(a2b, g.invert_transform(a2b)), np.eye(4), atol=1e-12)
        np.testing.assert_allclose(g.invert_transform(a2b), np.linalg.inv(a2b), atol=1e-10)


def test_euler_matches_paper_definition(rng):
    # Eqs. 3-5 of the reference paper: psi = atan2(Vz, Wz), phi = asin(-Uz), theta = atan2(Uy, Ux).
    for _ in range(100):
        ang = np.array([rng.uniform(-np.pi, np.pi), rng.uniform(-1.5, 1.5), rng.uniform(-np.pi, np.pi)])
        R = g.matrix_from_euler(ang)
        U, V, W = R[:, 0], R[:, 1], R[:, 2]
        np.testing.assert_allclose(
            g.euler_from_matrix(R),
            [np.arctan2(V[2], W[2]), np.arcsin(-U[2]), np.arctan2(U[1], U[0])],
            atol=1e-12,
        )
        np.testing.assert_allclose(g.euler_from_matrix(R), ang, atol=1e-10)
        # R = Rz(theta) Ry(phi) Rx(psi), built from elementary rotations.
        cx, sx = np.cos(ang[0]), np.sin(ang[0])
        cy, sy = np.cos(ang[1]), np.sin(ang[1])
        cz, sz = np.cos(ang[2]), np.sin(ang[2])
        Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
        Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
        Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
        np.testing.assert_allclose(R, Rz @ Ry @ Rx, atol=1e-12)


def test_euler_gimbal_lock_round_trip():
    for phi in (np.pi / 2, -np.pi / 2):
        R = g.matrix_from_euler([0.3, phi, -0.7])
        back = g.euler_from_matrix(R)
        np.testing.assert_allclose(g.matrix_from_euler(back), R, atol=1e-12)
        assert back[0] == 0.0


def test_one_exponential_agrees_with_opencv_and_scipy():
    # The rotation-vector exponential written once (OpenCV's operations): the same values as
    # cv2.Rodrigues, which it replaced in vision, and as scipy's, which it replaced in
    # geometry, to rounding, over angles from 1e-12 rad to a half turn and beyond, and 0.
    rng = np.random.default_rng(11)
    r = np.concatenate([rng.normal(scale=s, size=(400, 3)) for s in (1e-12, 1e-8, 1e-5, 1e-2, 0.5, 3.0)])
    r = np.vstack([r, np.zeros(3)])
    ours = g.matrix_from_rotvec(r)
    cv = np.array([cv2.Rodrigues(v.reshape(3, 1))[0] for v in r])
    np.testing.assert_allclose(ours, cv, rtol=0, atol=1e-15)
    np.testing.assert_allclose(ours, Rotation.from_rotvec(r).as_matrix(), rtol=0, atol=2e-15)
    np.testing.assert_array_equal(g.matrix_from_rotvec(np.zeros(3)), np.eye(3))
    assert g.matrix_from_rotvec(r.reshape(7, 343, 3)).shape == (7, 343, 3, 3)


def test_rotvec_round_trip_and_small_angle(rng):
    for _ in range(100):
        R = random_rotation(rng)
        np.testing.assert_allclose(g.matrix_from_rotvec(g.rotvec_from_matrix(R)), R, atol=1e-10)
    r = np.array([1e-4, -2e-4, 3e-5])
    R = g.matrix_from_rotvec(r)
    # First order: R = I + [r]x
    skew = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
    np.testing.assert_allclose(R, np.eye(3) + skew, atol=1e-7)
    np.testing.assert_allclose(g.rotvec_from_matrix(R), r, atol=1e-15)


def test_one_logarithm_agrees_with_scipy_to_the_bit():
    # One matrix is taken on floats (the pose fits' path), several by SciPy: the same values,
    # over angles from 1e-12 rad to a half turn, within 1e-12 of a half turn, and 0.
    rng = np.random.default_rng(12)
    r = np.concatenate([rng.normal(scale=s, size=(300, 3)) for s in (1e-12, 1e-8, 1e-5, 1e-3, 0.5, 3.0)])
    axis = rng.normal(size=(200, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    r = np.vstack([r, axis * (np.pi - 10.0 ** rng.uniform(-12, -1, size=(200, 1))), np.zeros(3)])
    R = g.matrix_from_rotvec(r)
    one = np.array([g.rotvec_from_matrix(m) for m in R])
    np.testing.assert_array_equal(one, Rotation.from_matrix(R).as_rotvec())
    np.testing.assert_array_equal(one, g.rotvec_from_matrix(R))
    np.testing.assert_allclose(g.matrix_from_rotvec(one), R, rtol=0, atol=1e-14)
    assert np.linalg.norm(one, axis=1).max() <= np.pi
    # A reflection or a null frame is refused by both paths.
    for bad in (np.diag([1.0, 1.0, -1.0]), -np.eye(3), np.zeros((3, 3))):
        for arg in (bad, bad[None]):
            with pytest.raises(ValueError):
                g.rotvec_from_matrix(arg)


def test_cam2base_from_fixed_is_eq1_of_the_paper(rng):
    # The paper's fixed-target pose on the robot (section 3.1).
    fixed2base = np.array([[1, 0, 0, -75.63], [0, 0, 1, 188.10], [0, -1, 0, 31.00], [0, 0, 0, 1.0]])
    cam2base_true = _random_transform(rng)
    fixed2cam = g.concat(fixed2base, g.invert_transform(cam2base_true))
    np.testing.assert_allclose(g.cam2base_from_fixed(fixed2base, fixed2cam), cam2base_true, atol=1e-10)
    # Any point of the fixed target maps to the same base coordinates both ways.
    p = rng.uniform(-50, 50, size=3)
    via_cam = g.transform_points(
        g.cam2base_from_fixed(fixed2base, fixed2cam), g.transform_points(fixed2cam, p)
    )
    np.testing.assert_allclose(via_cam, g.transform_points(fixed2base, p), atol=1e-9)


def test_displacement_from_poses(rng):
    T0 = _random_transform(rng)
    d = np.array([0.1, -0.25, 0.05])
    r = np.array([2e-4, -1e-4, 5e-4])
    T1 = T0.copy()
    T1[:3, :3] = g.matrix_from_rotvec(r) @ T0[:3, :3]
    T1[:3, 3] = T0[:3, 3] + d
    np.testing.assert_allclose(g.displacement_from_poses(T0, T1), np.r_[d, r], atol=1e-12)
    # Displacement of another point of the body equals the rigid transport to first order.
    p = np.array([30.0, -10.0, 5.0])
    offset = T0[:3, :3] @ p
    exact = g.displacement_from_poses(T0, T1, point=p)
    approx = g.displacement_at_point(np.r_[d, r], offset)
    # mm; the neglected second-order term is about |r|^2 |offset| = 3e-7 * 32 mm = 1e-5 mm.
    np.testing.assert_allclose(exact, approx, atol=2e-5)


def test_stiffness_in_frame_preserves_physics(rng):
    K = rng.normal(size=(3, 3)) + 5 * np.eye(3)
    a2b = _random_transform(rng)
    Kb = g.stiffness_in_frame(K, a2b)
    R = a2b[:3, :3]
    dx = rng.normal(size=3)
    # Force in b from a displacement in b equals the rotated force in a.
    np.testing.assert_allclose(Kb @ (R @ dx), R @ (K @ dx), atol=1e-10)


@pytest.mark.parametrize(
    "bad, msg",
    [
        (np.eye(3), "shape"),
        (np.full((4, 4), np.nan), "NaN"),
        (np.diag([1.0, 1.0, -1.0, 1.0]), "rotation"),
        (np.ones((4, 4)), "last row"),
    ],
)
def test_as_transform_rejects_bad_input(bad, msg):
    with pytest.raises(ValueError, match=msg):
        g.as_transform(bad)


def test_mean_transform_of_small_scatter(rng):
    T0 = _random_transform(rng)
    Ts = []
    for _ in range(200):
        T = T0.copy()
        T[:3, :3] = g.matrix_from_rotvec(rng.normal(scale=1e-3, size=3)) @ T0[:3, :3]
        T[:3, 3] += rng.normal(scale=0.01, size=3)
        Ts.append(T)
    M = g.mean_transform(Ts)
    g.as_transform(M)  # a proper rigid transform
    # Scatter 1e-3 rad and 0.01 mm over 200 draws: the mean is within ~4 standard errors.
    assert np.linalg.norm(g.rotvec_from_matrix(M[:3, :3] @ T0[:3, :3].T)) < 4 * 1e-3 * np.sqrt(3 / 200)
    np.testing.assert_allclose(M[:3, 3], np.mean([T[:3, 3] for T in Ts], axis=0), atol=1e-12)
    np.testing.assert_allclose(g.mean_transform([T0]), T0, atol=1e-12)
    with pytest.raises(ValueError, match="shape"):
        g.mean_transform(np.eye(4))
