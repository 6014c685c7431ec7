"""Compliant displacement from image measurements: exact cases, covariance, frames, sequences."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.board_images import quick_board_image
from helpers.board_scenes import (
    close_two_target_poses,
    exact_board_pose,
    look_at_pose,
    moved_pose,
    small_camera,
    two_target_scene,
)

from stiffmap.errors import InputError
from stiffmap.geometry import displacement_from_poses
from stiffmap.targets import Chessboard
from stiffmap.vision import (
    ImageMeasurement,
    PoseTracker,
    compliant_displacement,
    measure_sequence,
    mobile2base_from_poses,
)

MOBILE = Chessboard(7, 6, 10.0)
FIXED = Chessboard(9, 4, 10.0)


def _meas(name, M, cov_m, F=None, cov_f=None, fixed2base=None):
    m2b = m2b_cov = None
    if F is not None and fixed2base is not None:
        m2b, m2b_cov = mobile2base_from_poses(M, cov_m, F, cov_f, fixed2base)
    return ImageMeasurement(
        image=name,
        mobile=exact_board_pose(M, cov_m, 42),
        fixed=None if F is None else exact_board_pose(F, cov_f, 42),
        mobile2base=m2b,
        mobile2base_cov=m2b_cov,
    )


@pytest.fixture
def setup(rng):
    M0, F0, B = two_target_scene(rng, MOBILE, FIXED)
    A = rng.normal(size=(6, 6))
    cov = A @ A.T * 1e-8 + np.diag([1e-6, 1e-6, 1e-4, 1e-8, 1e-8, 1e-9])
    return M0, F0, B, cov


def test_exact_displacement_in_camera_and_base_frames(setup):
    M0, F0, B, cov = setup
    delta = np.array([0.3, -1.2, 2.5, 2e-3, -1e-3, 4e-3])
    M1 = moved_pose(M0, delta)
    q = np.array([35.0, 25.0, -60.0])  # a tool point below the target, mm
    u = [_meas("u", M0, cov, F0, cov, B)]
    lo = [_meas("l", M1, cov, F0, cov, B)]
    d_cam = compliant_displacement(u, lo, q, frame="cam")
    np.testing.assert_allclose(d_cam.vector, displacement_from_poses(M0, M1, q), atol=1e-12)
    d_base = compliant_displacement(u, lo, q)
    assert d_base.frame == "base"
    G = B @ np.linalg.inv(F0)
    np.testing.assert_allclose(d_base.vector, displacement_from_poses(G @ M0, G @ M1, q), atol=1e-10)
    assert d_base.n == 1 and np.all(np.isnan(d_base.d_std))
    assert d_base.fixed_shift is not None and np.allclose(d_base.fixed_shift, 0.0, atol=1e-12)
    assert d_base.flags == ()


def test_repeats_give_mean_std_and_n(setup, rng):
    M0, _, _, cov = setup
    true = np.array([0.05, 0.0, -0.02, 0.0, 1e-4, 0.0])
    u, lo, samples = [], [], []
    for k in range(10):
        drift = rng.normal(scale=[0.01, 0.01, 0.01, 1e-5, 1e-5, 1e-5])
        noise = rng.normal(scale=[0.002, 0.002, 0.01, 2e-6, 2e-6, 1e-6])
        a = moved_pose(M0, drift)
        b = moved_pose(a, true + noise)
        u.append(_meas(f"u{k}", a, cov))
        lo.append(_meas(f"l{k}", b, cov))
        samples.append(displacement_from_poses(a, b))
    d = compliant_displacement(u, lo)
    assert d.pairing == "pairs" and d.n == 10 and d.frame == "cam"
    S = np.array(samples)
    np.testing.assert_allclose(d.vector, S.mean(axis=0), atol=1e-12)
    np.testing.assert_allclose(d.d_std, S[:, :3].std(axis=0, ddof=1), atol=1e-12)
    # Pairing removes the drift between repeats: the spread is that of the noise only.
    assert np.all(d.d_std < [0.004, 0.004, 0.02])
    dm = compliant_displacement(u, lo, pairing="mean-reference")
    assert dm.pairing == "mean-reference"
    np.testing.assert_allclose(dm.d, d.d, atol=2e-6)  # first order: same mean


def test_covariance_of_the_mean_displacement_by_monte_carlo(setup, rng):
    M0, F0, B, cov = setup
    L = np.linalg.cholesky(cov)
    delta = np.array([0.5, 0.2, -1.0, 1e-3, 0.0, -2e-3])
    M1 = moved_pose(M0, delta)
    q = np.array([30.0, 20.0, -50.0])
    draws, covs = [], []
    for _ in range(1500):
        u = [_meas(f"u{k}", moved_pose(M0, L @ rng.normal(size=6)), cov) for k in range(3)]
        lo = [_meas(f"l{k}", moved_pose(M1, L @ rng.normal(size=6)), cov) for k in range(2)]
        d = compliant_displacement(u, lo, q)
        draws.append(d.vector)
        covs.append(d.cov)
    emp = np.cov(np.array(draws).T)
    pred = np.mean(covs, axis=0)
    np.testing.assert_allclose(np.diag(emp) / np.diag(pred), 1.0, atol=0.12)
    np.testing.assert_allclose(np.array(draws).mean(axis=0), displacement_from_poses(M0, M1, q), atol=1e-3)


def test_fixed_target_motion_is_flagged(setup):
    M0, F0, B, cov = setup
    M1 = moved_pose(M0, np.array([0.1, 0.0, 0.0, 0, 0, 0]))
    F1 = moved_pose(F0, np.array([0.05, 0.0, 0.0, 0, 0, 0]))  # 50 sigma of the fixed target
    d = compliant_displacement([_meas("u", M0, cov, F0, cov, B)], [_meas("l", M1, cov, F1, cov, B)])
    assert d.fixed_shift[0] == pytest.approx(0.05, abs=1e-9)
    assert any("fixed target moved" in f for f in d.flags)


def test_failed_images_are_left_out_and_all_failed_is_an_error(setup):
    M0, _, _, cov = setup
    ok = _meas("good.png", M0, cov)
    bad = ImageMeasurement(image="bad.png", error="bad.png: no 7x6 chessboard found in the image")
    d = compliant_displacement([ok, bad], [_meas("l.png", moved_pose(M0, np.full(6, 1e-3)), cov)])
    assert d.n_unloaded == 1 and "bad.png" in d.flags[0]
    with pytest.raises(InputError, match="no usable loaded image"):
        compliant_displacement([ok], [bad])
    with pytest.raises(ValueError, match="point"):
        compliant_displacement([ok], [ok], point=[1.0, 2.0])


def test_rendered_sequence_tracks_and_measures_small_displacements():
    cam = small_camera()
    M0, F = close_two_target_poses(MOBILE, FIXED)
    B = np.eye(4)
    B[:3, 3] = [100.0, 50.0, 0.0]
    delta = np.array([0.05, -0.03, 0.0, 0.0, 0.0, 0.0])  # mm: 0.15 px and 0.09 px here
    frames, poses = [], []
    rng = np.random.default_rng(7)
    for k in range(6):
        T = moved_pose(M0, delta) if k >= 3 else M0
        poses.append(T)
        frames.append(quick_board_image(cam, [(FIXED, F), (MOBILE, T)], rng=rng))
    frames.insert(3, np.full((480, 640), 90, np.uint8))  # a frame without boards
    ms = measure_sequence(frames, cam, MOBILE, FIXED, B, names=[f"f{k}" for k in range(7)])
    assert not ms[3].ok and "no 7x6 chessboard found" in ms[3].error and "no 9x4" in ms[3].error
    good = [m for m in ms if m.ok]
    assert [m.tracked for m in good] == [False, True, True, False, True, True]
    d = compliant_displacement(good[:3], good[3:], frame="cam")
    err = d.d - delta[:3]
    # 640x480 px, 30 px squares: 1 sigma is about 0.0015 mm across the axis, 0.015 mm along it.
    assert np.all(np.abs(err) < [0.006, 0.006, 0.06]), err  # mm
    assert np.all(np.abs(err) < 4 * d.d_sigma)
    db = compliant_displacement(good[:3], good[3:])
    assert db.frame == "base"
    G = B @ np.linalg.inv(F)
    np.testing.assert_allclose(db.d, G[:3, :3] @ d.d, atol=2e-4)


def test_tracker_reports_size_mismatch_and_goes_on():
    cam = small_camera()
    T = look_at_pose(260, MOBILE)
    tr = PoseTracker(cam, MOBILE, camera_source="cam.json")
    m = tr.measure(np.zeros((100, 100), np.uint8), "tiny.png")
    assert not m.ok and m.error.startswith("tiny.png:") and "100x100" in m.error and "640x480" in m.error
    m = tr.measure(quick_board_image(cam, [(MOBILE, T)], rng=np.random.default_rng(1)), "ok.png")
    assert m.ok and m.mobile.n_corners == 42 and m.timings["total"] > 0
    with pytest.raises(ValueError, match="fixed_board"):
        PoseTracker(cam, MOBILE, fixed2base=np.eye(4))
