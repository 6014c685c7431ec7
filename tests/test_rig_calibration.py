"""Rig calibration: rigs rendered by the test-bed with known truth, the Jacobian, the printout, bad input."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest
from helpers.finite_difference import central_jacobian
from helpers.rig_views import (
    BOARD,
    LEFT,
    OM_100MM,
    T_100MM,
    noisy_detections,
    rendered_rig,
    rig_views,
    true_rig,
)

from stiffmap.errors import InputError
from stiffmap.geometry import invert_transform, matrix_from_rotvec, rotvec_from_matrix
from stiffmap.posemath import perturb_pose
from stiffmap.rig import Rig
from stiffmap.sim.calibration_views import RIG_MAX_INCIDENCE_DEG, rig_calibration_views
from stiffmap.sim.render import true_corners
from stiffmap.sim.scene import two_camera_rig
from stiffmap.targets import Chessboard
from stiffmap.vision import BoardDetection, calibrate_camera
from stiffmap.vision.fuse import fuse_poses
from stiffmap.vision.pose import estimate_pose
from stiffmap.vision.rig_calibration import (
    NO_IMAGE,
    _evaluate,
    _layout,
    _matlab_extrinsics_jacobian,
    _Problem,
    _x0,
    calibrate_rig,
    matlab_extrinsics,
)

SIZES = [(640, 480), (640, 480)]
NAMES = ["left", "right"]


def _extrinsic_errors(res, truth: Rig) -> tuple[np.ndarray, np.ndarray]:
    """Error of the right camera's cam2rig as its (t, r) perturbation from the truth, and its 1 sigma."""
    T = res.rig.cameras[1].cam2rig
    T0 = truth.cameras[1].cam2rig
    e = np.r_[T[:3, 3] - T0[:3, 3], rotvec_from_matrix(T[:3, :3] @ T0[:3, :3].T)]
    s = res.rig.extrinsic_slice(1)
    return e, np.sqrt(np.diag(res.rig.cov[s, s]))


def _intrinsic_errors(res, truth: Rig) -> np.ndarray:
    """Normalised errors of every camera's parameters (error / 1 sigma)."""
    out = []
    for k, c in enumerate(res.rig.cameras):
        s = res.rig.intrinsic_slice(k)
        out.append((c.camera.params - truth.cameras[k].camera.params) / np.sqrt(np.diag(res.rig.cov[s, s])))
    return np.concatenate(out)


# ------------------------------------------------------------------------------- test-bed
def test_two_camera_rig_looks_at_one_point_from_60_degrees():
    rig = two_camera_rig(LEFT, 650.0, 60.0)
    assert rig.names == ("left", "right")
    target = np.array([0.0, 0.0, 650.0, 1.0])
    T = rig.cameras[1].cam2rig
    # The right camera is 650 mm from the point, on its optical axis, to the left one's right.
    p = invert_transform(T) @ target
    np.testing.assert_allclose(p[:3], [0.0, 0.0, 650.0], atol=1e-9)
    assert T[0, 3] > 0
    assert np.degrees(np.arccos(T[2, 2])) == pytest.approx(60.0, abs=1e-9)
    assert np.linalg.norm(T[:3, 3]) == pytest.approx(650.0, abs=1e-9)  # 2 d sin(30 deg)
    with pytest.raises(ValueError, match="angle_deg"):
        two_camera_rig(LEFT, 650.0, 0.0)


@pytest.mark.parametrize("kind", ["60deg", "100mm"])
def test_rig_views_are_seen_whole_by_the_cameras_that_take_them(kind):
    rig = true_rig(kind)
    views = rig_views(kind, 1)
    assert len(views) == 15
    assert [v.cameras for v in views] == [(0, 1)] * 13 + [(0,), (1,)]
    for v in views:
        for k in v.cameras:
            cam = rig.cameras[k].camera
            T = v.board2cam(rig, k)
            uv = true_corners(cam, BOARD, T)
            assert uv.min() > 20 and uv[:, 0].max() < 620 and uv[:, 1].max() < 460, (v.index, k)
            centre = T[:3, :3] @ [120.0, 75.0, 0.0] + T[:3, 3]
            incidence = np.degrees(np.arccos(T[:3, 2] @ centre / np.linalg.norm(centre)))
            assert incidence < (RIG_MAX_INCIDENCE_DEG if len(v.cameras) > 1 else 60.0) + 1e-6
    # Seeded: the same seed gives the same views.
    again = rig_calibration_views(rig, 15, board=BOARD, margin_mm=20.0, rng=np.random.default_rng(1))
    assert all(np.array_equal(a.board2rig, b.board2rig) for a, b in zip(views, again, strict=True))


# ---------------------------------------------------------------------------- known truth
@pytest.fixture(scope="module")
def rendered_results():
    """Two rendered 60-degree rigs (seeds 1, 2) and their calibrations (more: benchmarks)."""
    out = []
    for seed in (1, 2):
        r = rendered_rig("60deg", seed)
        out.append((r, calibrate_rig(r.detections, BOARD, r.sizes, camera_names=NAMES)))
    return out


def test_rendered_rigs_recover_camera_poses_within_their_uncertainty(rendered_results):
    z_ext, z_int = [], []
    for r, res in rendered_results:
        assert res.outliers == () and res.n_used == (14, 14)
        e, s = _extrinsic_errors(res, r.rig)
        z = e / s
        # Each of the 6 components within 4 sigma; sigma ~0.05-0.13 mm and ~0.01-0.02 deg.
        assert np.all(np.abs(z) < 4.0), z
        assert np.all(s[:3] < 0.3) and np.all(np.degrees(s[3:]) < 0.05), s
        zi = _intrinsic_errors(res, r.rig)
        assert np.all(np.abs(zi) < 4.0), zi
        z_ext.append(z)
        z_int.append(zi)
        # The per-camera residuals are the renderer's corner noise (~0.02 px).
        for c in res.rig.cameras:
            assert c.camera.rms_px < 0.06
        # The views' relative poses scatter as their covariances say (variance ratio seen
        # 0.67-0.98 over four renders): no excess dispersion, pose --rig's test unchanged.
        rel = res.rig.info["relative_poses"]["right"]
        assert rel["views"] == 13 and rel["left_out"] == [] and 0.5 < rel["variance_ratio"] < 1.5, rel
        assert rel["p_value"] > 0.05 and not np.any(res.rig.dispersion)
    # The stated uncertainty is the real one: normalised errors of RMS about 1 (seen: 0.71
    # for the poses, 0.86 for the intrinsics over these two rigs; 1.06 and 0.97 over six;
    # test_noise_model_gives_calibrated_uncertainty checks it closely).
    rms_ext = float(np.sqrt(np.mean(np.square(z_ext))))
    rms_int = float(np.sqrt(np.mean(np.square(z_int))))
    assert 0.5 < rms_ext < 1.6, rms_ext
    assert 0.5 < rms_int < 1.6, rms_int


def _whitened(err: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """L^-1 err with cov = L L^T: independent N(0, 1) components when cov is the errors' covariance."""
    d = np.sqrt(np.diag(cov))
    return np.linalg.solve(np.linalg.cholesky(cov / np.outer(d, d)), err / d)


def test_noise_model_gives_calibrated_uncertainty():
    """Exact corners plus Gaussian noise: the covariance is the spread of the errors."""
    rng = np.random.default_rng(7)
    w_all, w_ext, ratios, zero = [], [], [], 0
    for seed in (1, 2):
        rig, views = true_rig("60deg"), rig_views("60deg", seed)
        for _ in range(5):
            dets = noisy_detections(rig, views, 0.1, rng)
            res = calibrate_rig(dets, BOARD, SIZES, camera_names=NAMES)
            e, _ = _extrinsic_errors(res, rig)
            intr = [
                c.camera.params - t.camera.params for c, t in zip(res.rig.cameras, rig.cameras, strict=True)
            ]
            # Over the whole of param_names (left's intrinsics, right's, right's cam2rig).
            w_all.append(_whitened(np.concatenate([*intr, e]), res.rig.cov))
            s = res.rig.extrinsic_slice(1)
            w_ext.append(_whitened(e, res.rig.cov[s, s]))
            # The residual variance estimates the noise (0.1 px per axis).
            assert res.rig.cameras[0].camera.residual_std_px[0] == pytest.approx(0.1, rel=0.1)
            # Independent corner noise: the views' relative poses scatter as their covariances
            # say, so no excess dispersion (zero in 10 of 10 draws; ratios 0.67-1.11).
            ratios.append(res.rig.info["relative_poses"]["right"]["variance_ratio"])
            zero += not np.any(res.rig.dispersion)
    # Whitened errors: 240 independent N(0, 1) draws (RMS 0.91-1.09 at 95 %; seen 0.96), and
    # 60 of the poses alone (0.82-1.17 at 95 %; seen 0.77-1.04 over three noise seeds).
    rms_all = float(np.sqrt(np.mean(np.square(w_all))))
    rms_ext = float(np.sqrt(np.mean(np.square(w_ext))))
    assert 0.88 < rms_all < 1.12, rms_all
    assert 0.7 < rms_ext < 1.3, rms_ext
    # Mean of 10 ratios, each of 72 degrees of freedom (sd 0.17): 1 within 0.2.
    assert abs(np.mean(ratios) - 1.0) < 0.2, ratios
    assert zero >= 8, zero


@pytest.mark.parametrize("move", ["0.3 mm along z", "0.03 deg about y"])
def test_a_camera_moved_a_little_is_still_caught_on_a_rendered_rig(rendered_results, move):
    """The rendered 60-degree rig (seed 1), its 13 calibration views posed from their corners
    in each camera and fused: silent with the calibrated rig; with the right camera moved by
    0.3 mm along z or 0.03 degree about y -- its weakest axes, about 5 sigma of the views'
    relative pose (calibration 1 sigma 0.05-0.13 mm, 0.01-0.02 deg) -- every view warned
    (chi2 seen 120-140 at least, limit 27.9). The rig's dispersion is zero there, so the test
    is as sharp as before it."""
    r, res = rendered_results[0]
    rig = res.rig
    d = [0.0, 0.0, 0.3, 0.0, 0.0, 0.0] if move.endswith("z") else [0.0, 0.0, 0.0, 0.0, np.radians(0.03), 0.0]
    right = rig.cameras[1]
    moved = replace(rig, cameras=(rig.cameras[0], replace(right, cam2rig=perturb_pose(right.cam2rig, d))))
    shared = [
        v for v in range(len(r.views)) if all(isinstance(r.detections[k][v], BoardDetection) for k in (0, 1))
    ]
    assert len(shared) == 13

    def fused(rg):
        return [
            fuse_poses(
                rg,
                {
                    k: estimate_pose(r.detections[k][v], BOARD, rg.cameras[k].camera, refine="corners")
                    for k in (0, 1)
                },
                board=BOARD,
            )
            for v in shared
        ]

    assert not any(f.consistency_warning for f in fused(rig))
    assert all(f.consistency_warning for f in fused(moved))


def test_100mm_stereo_rig_is_recovered_well_within_the_real_photographs_tolerance():
    """Two similar cameras 100 mm apart, nearly parallel (as the public left/right samples)."""
    r = rendered_rig("100mm", 1, 14)
    res = calibrate_rig(r.detections, BOARD, r.sizes, camera_names=NAMES)
    om, T, om_std, T_std = res.extrinsics_matlab(1)
    # The real check: T within 1.5 mm of the published one, the rotation within 0.5 degrees;
    # from rendered views the errors are ~0.01 mm and ~0.01 degrees, within their 4 sigma.
    dT = T - T_100MM
    angle = np.degrees(
        np.linalg.norm(rotvec_from_matrix(matrix_from_rotvec(om) @ matrix_from_rotvec(OM_100MM).T))
    )
    assert np.linalg.norm(dT) < 0.1, dT
    assert angle < 0.05, angle
    assert np.all(np.abs(dT) < 4 * T_std), (dT, T_std)
    assert np.all(np.abs(om - OM_100MM) < 4 * om_std + 1e-9), (om - OM_100MM, om_std)
    assert np.linalg.norm(T) == pytest.approx(100.0, abs=0.2)


# ------------------------------------------------------------------------ one camera, Jacobian
@pytest.mark.parametrize("model", ["k3", "fix-k3"])
def test_a_rig_of_one_camera_is_calibrate_camera(model):
    dets = list(rendered_rig("60deg", 1).detections[0])
    one = calibrate_camera(dets, BOARD, SIZES[0], model=model)
    res = calibrate_rig([dets], BOARD, [SIZES[0]], camera_names=["cam"], model=model)
    cam = res.rig.cameras[0].camera
    assert len(res.rig) == 1 and res.rig.param_names == tuple(f"cam.{p}" for p in one.camera.param_names)
    sd = np.sqrt(np.diag(one.camera.cov))
    free = sd > 0
    # The same optimum (OpenCV works on float32 corners: 1e-3 sigma apart) and covariance.
    assert np.all(np.abs(cam.params - one.camera.params)[free] < 2e-3 * sd[free])
    np.testing.assert_allclose(cam.cov, one.camera.cov, rtol=1e-4, atol=1e-9 * sd.max() ** 2)
    assert cam.rms_px == pytest.approx(one.camera.rms_px, rel=1e-6)
    assert [v.used for v in res.views[0]] == [v.used for v in one.views]
    # One camera prints as calibrate does.
    text = res.matlab_text()
    assert text.startswith("Calibration results after optimization (with uncertainties):")
    assert (
        f"Focal Length:          fc = [ {cam.fx:.5f}   {cam.fy:.5f} ] +/- [ {3 * cam.std['fx']:.5f}" in text
    )
    assert "om = [" not in text


def test_bundle_adjustment_jacobian_matches_finite_differences_in_the_rig_convention():
    """d uv / d(cam2rig perturbation), d(board2rig perturbation), d(intrinsics), away from zero too."""
    rig = true_rig("60deg")
    views = rig_views("60deg", 1)[:4]
    q = BOARD.object_points()[::5]
    obs, points = [], {}
    for i, v in enumerate(views):
        for k in v.cameras:
            T = v.board2cam(rig, k)
            points[(k, i)] = (q, rig.cameras[k].camera.project(q @ T[:3, :3].T + T[:3, 3]))
            obs.append((k, i))
    cams = [c.camera for c in rig.cameras]
    p = _Problem(
        cams,
        [c.cam2rig for c in rig.cameras],
        {i: v.board2rig for i, v in enumerate(views)},
        obs,
        points,
        [list(range(9))] * 2,
    )
    layout = _layout(p)
    cam_off, ext_off, view_off, n_a, n = layout
    rng = np.random.default_rng(3)
    x = _x0(p, layout)
    x[n_a - 6 :] += rng.normal(0, 0.02, n - n_a + 6)  # extrinsics and board poses away from zero
    _, J = _evaluate(p, x, layout)
    J = J.toarray()

    # The extrinsic block against a projection written independently: the right camera's
    # cam2rig moved by perturb_pose (t added, R <- Exp(r) R, rig frame), as Rig.param_names says.
    def project_all(d):
        c2r = perturb_pose(p.cam2rig[1], x[ext_off[1] : ext_off[1] + 6] + d)
        out = []
        for k, i in obs:
            Tb = perturb_pose(p.board2rig[i], x[view_off[i] : view_off[i] + 6])
            Tc = np.eye(4) if k == 0 else c2r
            X = (Tb[:3, :3] @ q.T).T + Tb[:3, 3]
            out.append(cams[k].project((X - Tc[:3, 3]) @ Tc[:3, :3]).reshape(-1))
        return np.concatenate(out)

    # d/dd at the iterate's own perturbation: the left Jacobian maps it; at d = 0 of a re-based
    # problem it is the plain (t, r) perturbation. Check both through the evaluation itself.
    Jn = central_jacobian(lambda d: project_all(d), np.zeros(6), 1e-6)
    np.testing.assert_allclose(J[:, ext_off[1] : ext_off[1] + 6], Jn, rtol=1e-5, atol=1e-6)
    steps = 1e-5 * np.maximum(1.0, np.abs(x))  # px, unitless, mm and rad
    Jfull = central_jacobian(lambda y: _evaluate(p, y, layout, jacobian=False)[0], x, steps)
    scale = np.abs(Jfull).max(axis=0)
    assert np.all(np.abs(J - Jfull).max(axis=0) <= 1e-5 * scale + 1e-7)


def test_matlab_om_t_and_their_sigma_follow_the_covariance():
    rig = true_rig("100mm")
    c2r = rig.cameras[1].cam2rig

    def om_t(d):
        r2c = invert_transform(perturb_pose(c2r, d))
        return np.r_[rotvec_from_matrix(r2c[:3, :3]), r2c[:3, 3]]

    G = _matlab_extrinsics_jacobian(c2r)
    np.testing.assert_allclose(G, central_jacobian(om_t, np.zeros(6), 1e-6), atol=1e-6)
    n = len(rig.param_names)
    cov = np.eye(n) * 1e-8
    s = rig.extrinsic_slice(1)
    cov[s, s] = np.diag([0.04, 0.01, 0.09, 1e-6, 4e-6, 1e-8])
    om, T, om_std, T_std = matlab_extrinsics(Rig(rig.cameras, cov=cov), 1)
    np.testing.assert_allclose(om, OM_100MM, atol=1e-12)
    np.testing.assert_allclose(T, T_100MM, atol=1e-9)
    # Nearly parallel cameras: om's sigma is r's; T's is t's plus the rotation moving the
    # 100 mm baseline (T_z: 0.3 mm and 100 mm x 2 mrad about y).
    np.testing.assert_allclose(om_std, [1e-3, 2e-3, 1e-4], rtol=0.02)
    np.testing.assert_allclose(T_std, [0.2, 0.1, np.hypot(0.3, 100 * 2e-3)], rtol=0.02)


def test_matlab_text_prints_each_camera_and_om_t_with_three_sigma(rendered_results):
    r, res = rendered_results[0]
    text = res.matlab_text()
    assert text.startswith("Stereo calibration parameters after optimization:")
    for c in res.rig.cameras:
        assert f"Intrinsic parameters of {c.name} camera:" in text
        assert (
            f"fc_{c.name} = [ {c.camera.fx:.5f}   {c.camera.fy:.5f} ] +/- [ {3 * c.camera.std['fx']:.5f}"
            in text
        )
    assert "Extrinsic parameters (position of right camera wrt left camera):" in text
    om, T, om_std, T_std = res.extrinsics_matlab(1)
    num = r"(-?\d+\.\d+)"
    m = re.search(
        r"Rotation vector:\s+om = \[ " + r"\s+".join([num] * 3) + r" \] \+/- \[ " + r"\s+".join([num] * 3),
        text,
    )
    assert m, text
    np.testing.assert_allclose([float(x) for x in m.groups()], np.r_[om, 3 * om_std], atol=6e-6)
    m = re.search(
        r"Translation vector:\s+T = \[ " + r"\s+".join([num] * 3) + r" \] \+/- \[ " + r"\s+".join([num] * 3),
        text,
    )
    assert m, text
    np.testing.assert_allclose([float(x) for x in m.groups()], np.r_[T, 3 * T_std], atol=6e-6)
    # om, T take points from the left camera's frame to the right one's: the truth's rig2right.
    r2c = invert_transform(r.rig.cameras[1].cam2rig)
    assert np.all(np.abs(T - r2c[:3, 3]) < 4 * T_std)


# -------------------------------------------------------------------- outliers, missing views
def test_an_outlier_view_is_named_and_left_out_of_its_camera_only():
    r = rendered_rig("60deg", 1)
    dets = [list(row) for row in r.detections]
    d = dets[1][4]
    rng = np.random.default_rng(0)
    dets[1][4] = BoardDetection(BOARD, d.corners + rng.normal(0, 0.7, d.corners.shape), d.ids, d.residual_px)
    res = calibrate_rig(dets, BOARD, r.sizes, camera_names=NAMES, view_names=[f"v{i + 1}" for i in range(15)])
    assert len(res.outliers) == 1
    view, camera, why = res.outliers[0]
    assert (view, camera) == ("v5", "right") and why.startswith("outlier: view RMS")
    assert not res.views[1][4].used and res.views[1][4].reason == why
    assert res.views[0][4].used  # the left camera keeps the view
    assert res.rig.info["outliers"] == [{"view": "v5", "camera": "right", "reason": why}]
    assert res.rig.info["views"][4]["rms_px"]["right"] is None
    e, s = _extrinsic_errors(res, r.rig)
    assert np.all(np.abs(e / s) < 4.0)


def test_a_view_missing_for_one_camera_still_serves_the_other():
    r = rendered_rig("60deg", 2)
    dets = [list(row) for row in r.detections]
    dets[1][2] = None  # the right camera has no image of view 3
    res = calibrate_rig(dets, BOARD, r.sizes, camera_names=NAMES)
    assert res.views[1][2].reason == NO_IMAGE and not res.views[1][2].used
    assert res.views[0][2].used and res.n_used == (14, 13)
    right = res.rig.cameras[1].camera
    assert len(right.views) == 13  # camera.json's views: the images it has
    assert res.board2rig[2] is not None
    e, s = _extrinsic_errors(res, r.rig)
    assert np.all(np.abs(e / s) < 4.0)


@pytest.mark.parametrize("turned", ["two views", "every view"])
def test_a_symmetric_board_numbered_from_the_other_end_in_one_camera_is_renumbered(turned):
    """An 8x6 board looks the same turned by 180 degrees: its numbering may differ between cameras."""
    board = Chessboard(8, 6, 30.0)
    rig = true_rig("60deg")
    views = rig_calibration_views(rig, 12, board=board, margin_mm=20.0, rng=np.random.default_rng(4))
    dets = noisy_detections(rig, views, 0.05, np.random.default_rng(5), board=board)
    n = board.n_corners
    for v in (1, 4) if turned == "two views" else [v for v in range(12) if dets[1][v] is not None]:
        d = dets[1][v]  # as a camera turned upside down would number them
        dets[1][v] = BoardDetection(board, d.corners[::-1], np.arange(n), d.residual_px)
    res = calibrate_rig(dets, board, SIZES, camera_names=NAMES)
    assert res.outliers == () and res.n_used == (11, 11)
    e, s = _extrinsic_errors(res, rig)
    assert np.all(np.abs(e / s) < 4.0), e / s
    assert max(c.camera.rms_px for c in res.rig.cameras) < 0.1  # px: the corners' noise, 0.07


def test_bad_input_is_named():
    r = rendered_rig("60deg", 1)
    dets = [list(row) for row in r.detections]
    few = [dets[0], [d if i in (13, 14) else "board not found" for i, d in enumerate(dets[1])]]
    with pytest.raises(InputError, match=r"camera right: calibration needs at least 3 views .* got 1"):
        calibrate_rig(few, BOARD, r.sizes, camera_names=NAMES)
    # The right camera sees enough views, but shares only one with the left.
    apart = [
        [d if i < 8 else None for i, d in enumerate(dets[0])],
        [d if i >= 7 else None for i, d in enumerate(dets[1])],
    ]
    with pytest.raises(
        InputError, match=r"camera right shares 1 usable view\(s\) with camera left.*at least 2"
    ):
        calibrate_rig(apart, BOARD, r.sizes, camera_names=NAMES)
    with pytest.raises(ValueError, match="camera names must be different"):
        calibrate_rig(dets, BOARD, r.sizes, camera_names=["a", "a"])
    with pytest.raises(ValueError, match="one entry per view"):
        calibrate_rig([dets[0], dets[1][:-1]], BOARD, r.sizes, camera_names=NAMES)
