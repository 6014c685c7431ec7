"""A series of images against the same reference: each image's displacement, and a stage manifest's steps."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.board_scenes import look_at_pose

from stiffmap.errors import InputError
from stiffmap.geometry import displacement_from_poses, matrix_from_rotvec
from stiffmap.targets import Chessboard
from stiffmap.vision import (
    BoardPose,
    ImageMeasurement,
    compliant_displacement,
    displacement_per_image,
    validate_stage,
    validate_stage_series,
)

MOBILE = Chessboard(7, 6, 10.0)
M0 = look_at_pose(500, MOBILE, tilt_deg=(10, -15, 5), offset_mm=(20, 10))
COV = np.diag([1e-6, 1e-6, 1e-4, 1e-8, 1e-8, 1e-9])


def _moved(delta) -> np.ndarray:
    T = M0.copy()
    T[:3, 3] += delta[:3]
    T[:3, :3] = matrix_from_rotvec(delta[3:]) @ M0[:3, :3]
    return T


def _seen(name: str, T: np.ndarray) -> ImageMeasurement:
    pose = BoardPose(
        board2cam=T,
        cov=COV,
        rms_px=0.0,
        n_corners=42,
        residuals_px=np.zeros((42, 2)),
        sigma_px=0.0,
        condition=1.0,
        iterations=0,
    )
    return ImageMeasurement(image=name, mobile=pose)


def _failed(name: str) -> ImageMeasurement:
    return ImageMeasurement(image=name, error=f"{name}: no 7x6 chessboard found in the image")


def test_each_image_against_the_mean_reference():
    d1 = np.array([0.5, -0.2, 0.3, 1e-3, -2e-3, 5e-4])
    d2 = np.array([0.4, -0.1, 0.2, 2e-3, 0.0, -1e-3])
    refs = [_seen("ref0", M0), _failed("ref1")]
    images = [_seen("a", _moved(d1)), _failed("b"), _seen("c", _moved(d2))]
    q = np.array([30.0, 25.0, -40.0])  # a point of the target, mm
    res = displacement_per_image(refs, images, q)
    assert [d is None for d in res.displacements] == [False, True, False]
    for d, delta in zip((res.displacements[0], res.displacements[2]), (d1, d2), strict=True):
        truth = displacement_from_poses(M0, _moved(delta), q)
        np.testing.assert_allclose(d.vector, truth, atol=1e-12)  # mm, rad
        assert d.frame == "cam" and d.n == 1
    s = res.summary
    assert s.n == 2
    np.testing.assert_allclose(s.d, (res.displacements[0].d + res.displacements[2].d) / 2, atol=1e-12)
    same = compliant_displacement(refs, [images[0], images[2]], q, pairing="mean-reference")
    np.testing.assert_array_equal(s.cov, same.cov)
    assert res.n_ok == 3 and res.n_images == 5  # one reference and one image failed


def test_without_a_reference_or_a_measured_image():
    with pytest.raises(InputError, match=r"no reference image could be measured \(ref0\); nothing"):
        displacement_per_image([_failed("ref0")], [_seen("a", M0)])
    res = displacement_per_image([_seen("ref0", M0)], [_failed("a")])
    assert res.displacements == (None,) and res.summary is None and res.n_ok == 1


def test_stage_series_takes_nominal_zero_as_reference():
    axis = np.array([0.8, 0.1, 0.59]) / np.linalg.norm([0.8, 0.1, 0.59])
    nominals = [2.0, 0.0, 5.0, 2.0, 0.0, 5.0]  # mm, in the manifest's order
    ms = [_seen(f"im{i}", _moved(np.r_[n * axis, 0, 0, 0])) for i, n in enumerate(nominals)]
    res = validate_stage_series(ms, nominals)
    ref = validate_stage([ms[1], ms[4]], [(2.0, ms[0]), (5.0, ms[2]), (2.0, ms[3]), (5.0, ms[5])])
    assert res.n_reference == ref.n_reference == 2
    assert [s.nominal_mm for s in res.steps] == [2.0, 5.0]
    for a, b in zip(res.steps, ref.steps, strict=True):
        np.testing.assert_array_equal(a.norm_mm, b.norm_mm)
        assert a.images == b.images
    assert res.rms_error_mm < 1e-9  # mm: exact poses
    with pytest.raises(ValueError):
        validate_stage_series(ms, nominals[:-1])  # one nominal per image
