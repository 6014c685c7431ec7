"""End to end on the virtual test-bed's renderer (stiffmap.sim.render) at the reference camera.

The reference setup: a 12x7 board fixed on the base and an 8x6 board on the platform,
10 mm squares, the reference study's camera (2592x1944 px). Ground truth: the renderer's
exact corner projections and poses.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers.board_scenes import look_at_pose

from stiffmap.camera import reference_camera
from stiffmap.geometry import displacement_from_poses, matrix_from_rotvec
from stiffmap.sim.render import Photometry, Target, encode_image, render
from stiffmap.targets import Chessboard
from stiffmap.vision import PoseTracker, compliant_displacement

CAM = reference_camera()
MOBILE = Chessboard(8, 6, 10.0)
FIXED = Chessboard(12, 7, 10.0)
F = look_at_pose(760, FIXED, tilt_deg=(-8, 18, -3), offset_mm=(-150, 100))
M0 = look_at_pose(700, MOBILE, tilt_deg=(10, -15, 5), offset_mm=(30, -20))


def _loaded(delta):
    T = M0.copy()
    T[:3, :3] = matrix_from_rotvec(delta[3:]) @ M0[:3, :3]
    T[:3, 3] = M0[:3, 3] + delta[:3]
    return T


@pytest.fixture(scope="module")
def sequence(tmp_path_factory):
    """3 unloaded + 3 loaded PNG files of one robot position, and the truth."""
    d = tmp_path_factory.mktemp("testbed")
    rng = np.random.default_rng(2026)
    delta = np.array([0.12, -0.05, 0.2, 3e-4, -1e-4, 2e-4])
    paths, truth = [], []
    for k in range(6):
        T = M0 if k < 3 else _loaded(delta)
        r = render(CAM, [Target(FIXED, F, "fixed"), Target(MOBILE, T, "mobile")], seed=rng)
        p = d / f"img{k}.png"
        p.write_bytes(encode_image(r.image))
        paths.append(p)
        truth.append(r.targets)
    return paths, truth, delta


def test_corners_of_both_boards_against_the_renderers_truth(sequence):
    paths, truth, _ = sequence
    tr = PoseTracker(CAM, MOBILE, FIXED)
    for p, tt in zip(paths, truth, strict=True):
        m = tr.measure(p)
        assert m.ok, m.error
        for det, t in ((m.fixed_detection, tt[0]), (m.mobile_detection, tt[1])):
            err = det.corners - t.corners_px[det.ids]
            if det.board is MOBILE and det.orientation in ("default", "tracked") and err.max() > 1:
                err = det.corners - t.corners_px[::-1][det.ids]  # symmetric 8x6: maybe the turned frame
            assert det.complete
            assert np.sqrt(np.mean(np.sum(err**2, axis=1))) < 0.03  # px
            assert np.abs(err).max() < 0.08  # px


def test_displacement_of_the_reference_setup(sequence):
    paths, truth, delta = sequence
    fixed2base = np.eye(4)
    fixed2base[:3, :3] = matrix_from_rotvec([0.0, 0.0, np.pi / 2])
    fixed2base[:3, 3] = [200.0, -100.0, 50.0]
    tr = PoseTracker(CAM, MOBILE, FIXED, fixed2base)
    ms = [tr.measure(p) for p in paths]
    assert [m.tracked for m in ms] == [False, True, True, True, True, True]
    # The measured frame of the symmetric 8x6 board may be the turned one: compare the
    # displacement of the same physical point (the measured origin).
    S = np.linalg.inv(M0) @ ms[0].mobile2cam
    S = np.round(S, 3)
    d = compliant_displacement(ms[:3], ms[3:], frame="cam")
    true_cam = displacement_from_poses(M0 @ S, _loaded(delta) @ S)
    err = d.vector - true_cam
    # 1 sigma here (3 + 3 frames at 700 mm): about 0.001 mm across, 0.013 mm along, 6e-5 rad.
    assert np.all(np.abs(err[:2]) < 0.005), err  # mm across the optical axis
    assert abs(err[2]) < 0.05, err  # mm along it
    assert np.all(np.abs(err[3:]) < 3e-4), err  # rad
    assert np.all(np.abs(err) < 4 * np.sqrt(np.diag(d.cov)))
    # In the base frame through the fixed target (eq. 1).
    db = compliant_displacement(ms[:3], ms[3:])
    G = fixed2base @ np.linalg.inv(F)
    true_base = displacement_from_poses(G @ M0 @ S, G @ _loaded(delta) @ S)
    assert db.frame == "base"
    np.testing.assert_allclose(db.vector[:3], true_base[:3], atol=0.03)  # mm
    assert db.fixed_shift is not None and np.linalg.norm(db.fixed_shift[:3]) < 0.02
    assert not db.flags


def test_clutter_and_a_colour_camera_do_not_break_detection(tmp_path):
    ph = Photometry(clutter=True, colour=True)
    r = render(CAM, [Target(FIXED, F, "fixed"), Target(MOBILE, M0, "mobile")], photometry=ph, seed=5)
    p = tmp_path / "colour.jpg"
    p.write_bytes(encode_image(r.image, "jpeg", jpeg_quality=92))
    m = PoseTracker(CAM, MOBILE, FIXED).measure(p)
    assert m.ok, m.error
    err = m.fixed_detection.corners - r.targets[0].corners_px[m.fixed_detection.ids]
    assert np.sqrt(np.mean(np.sum(err**2, axis=1))) < 0.1  # px: JPEG and demosaicing
