"""Camera model: NumPy projection against OpenCV, undistortion round trip, camera.json."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from helpers.finite_difference import central_jacobian

from stiffmap.camera import (
    FIELD_SAFETY,
    CameraModel,
    _dist12,
    _distort,
    invertible_field,
    load_camera,
    pixel_rays,
    reference_camera,
    save_camera,
)
from stiffmap.errors import InputError
from stiffmap.geometry import transform_from as make_transform

DISTS = [
    (-0.09, 0.11, 0.0, 0.0, 0.0),  # the reference study's camera
    (-0.25403, 0.12143, -0.00021, 0.00002, 0.0),  # Bouguet's calibration example
    (0.1, -0.05, 1e-3, -2e-3, 0.01, 0.02, -0.01, 0.005),  # rational model
    (0.1, -0.05, 1e-3, -2e-3, 0.01, 0.02, -0.01, 0.005, 1e-3, -1e-3, 2e-3, 5e-4),  # thin prism
]


@pytest.mark.parametrize("dist", DISTS)
def test_projection_matches_opencv(dist, rng):
    cam = CameraModel((2592, 1944), 3733.27, 3722.85, 1466.77, 904.81, dist)
    P = np.c_[rng.uniform(-200, 200, size=(500, 2)), rng.uniform(500, 900, size=500)]
    ours = cam.project(P)
    ref, _ = cv2.projectPoints(P.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.matrix, cam.dist_array)
    np.testing.assert_allclose(ours, ref.reshape(-1, 2), atol=1e-8)  # px


@pytest.mark.parametrize("dist", DISTS)
def test_undistort_inverts_distort_over_the_image(dist):
    cam = CameraModel((2592, 1944), 3733.27, 3722.85, 1466.77, 904.81, dist)
    u, v = np.meshgrid(np.linspace(0, 2591, 40), np.linspace(0, 1943, 30))
    uv = np.stack([u, v], axis=-1)
    rays = cam.rays_from_pixels(uv)
    back = cam.pixels_from_normalized(cam.distort(rays))
    np.testing.assert_allclose(back, uv, atol=1e-9)  # px


def test_the_cached_ray_map_is_the_camera_rays(rng):
    # One cached map per camera, shared by the renderer (float64 blocks, halo outside the
    # image included) and the photometric fit (float32 corrections at every pixel).
    cam = CameraModel((640, 480), 900.0, 905.0, 322.5, 236.0, (-0.12, 0.08, 0.0005, -0.0003, 0.0))
    rays = pixel_rays(cam)
    assert pixel_rays(CameraModel(**{**cam.to_dict(), "image_size": (640, 480)})) is rays
    rows = np.arange(-1.0, 481.0)
    cols = np.arange(-1.0, 641.0)
    rx, ry = rays.block(rows, cols)
    U, V = np.meshgrid(cols, rows)
    exact = cam.rays_from_pixels(np.stack([U, V], axis=-1))
    assert np.abs(rx - exact[..., 0]).max() * cam.fx < 2e-6  # px
    assert np.abs(ry - exact[..., 1]).max() * cam.fy < 2e-6
    cx, cy = rays.correction_maps
    assert cx.dtype == np.float32 and cx.shape == (480, 640)
    np.testing.assert_allclose(rays.px[None, :] + cx, exact[1:-1, 1:-1, 0], rtol=0, atol=2e-9)
    np.testing.assert_allclose(rays.py[:, None] + cy, exact[1:-1, 1:-1, 1], rtol=0, atol=2e-9)


def test_distortion_jacobian_matches_finite_differences(rng):
    d = _dist12(np.asarray(DISTS[3]))
    xy = rng.uniform(-0.4, 0.4, size=(50, 2))
    _, J = _distort(xy, d, jacobian=True)
    fd = central_jacobian(lambda p: _distort(p, d, jacobian=False)[0], xy, 1e-6)
    np.testing.assert_allclose(J, fd, rtol=1e-6, atol=1e-9)


def test_rectangle_outline_bounds_the_rendered_board_under_distortion():
    """The sampled outline holds the projected corners and bulges past them under barrel distortion."""
    cam = CameraModel((2592, 1944), 3733.27, 3722.85, 1466.77, 904.81, (-0.3, 0.1, 0, 0, 0))
    T = make_transform(np.eye(3), [-150.0, -100.0, 600.0])
    uv = cam.project_rectangle(T, (0.0, 0.0, 300.0, 200.0), samples=9)
    corners = cam.project(
        np.array([[0, 0, 600], [300, 0, 600], [300, 200, 600], [0, 200, 600]]) + [-150, -100, 0]
    )
    np.testing.assert_allclose(uv[[0, 8, 17, 18]], corners, atol=1e-9)
    mid_top = cam.project(np.array([0.0, -100.0, 600.0]))
    np.testing.assert_allclose(uv[4], mid_top, atol=1e-9)
    # Barrel distortion bows the top edge outwards (up): a box of the corners alone would cut it.
    assert mid_top[1] < min(corners[0, 1], corners[1, 1]) - 1.0
    behind = make_transform(np.eye(3), [0.0, 0.0, -1.0])
    with pytest.raises(ValueError, match="behind the camera"):
        cam.project_rectangle(behind, (0.0, 0.0, 10.0, 10.0))


def test_camera_json_round_trip(tmp_path):
    cam = CameraModel(
        (640, 480),
        657.46,
        657.95,
        303.14,
        242.57,
        (-0.254, 0.121, -2e-4, 2e-5, 0.0),
        std={"fx": 0.1, "fy": 0.1, "cx": 0.2, "cy": 0.2, "dist": [1e-3, 3e-3, 4e-5, 4e-5, 0.0]},
        rms_px=0.17,
        residual_std_px=(0.12, 0.12),
        views=({"image": "Image1.tif", "used": True, "rms_px": 0.15, "reason": ""},),
    )
    path = tmp_path / "camera.json"
    save_camera(cam, path)
    assert load_camera(path) == cam
    assert reference_camera().image_size == (2592, 1944)


@pytest.mark.parametrize(
    "content, expected",
    [
        ("{not json", "not valid JSON"),
        ('{"fx": 1}', "missing keys 'image_size'"),
        ('{"image_size": [640], "fx": 1, "fy": 1, "cx": 1, "cy": 1, "dist": [0,0,0,0,0]}', "'image_size'"),
        ('{"image_size": [640, 480], "fx": "a", "fy": 1, "cx": 1, "cy": 1, "dist": [0,0,0,0,0]}', "'fx'"),
        ('{"image_size": [640, 480], "fx": -5, "fy": 1, "cx": 1, "cy": 1, "dist": [0,0,0,0,0]}', "positive"),
        ('{"image_size": [640, 480], "fx": 5, "fy": 1, "cx": 1, "cy": 1, "dist": [0,0,0]}', "'dist'"),
    ],
)
def test_malformed_camera_json_names_file_and_key(tmp_path, content, expected):
    path = tmp_path / "cam.json"
    path.write_text(content)
    with pytest.raises(InputError, match=expected) as info:
        load_camera(path)
    assert str(path) in str(info.value)


#: A real wide-angle calibration (the hidden check's second camera: k1 -0.30, k2 0.15, k3 -0.075):
#: its polynomial folds over inside the corners of its own image.
STRONG_LENS = CameraModel((1280, 720), 560.0, 560.0, 640.0, 360.0, (-0.30, 0.15, 0.0, 0.0, -0.075))


def test_invertible_field_ends_where_the_radial_polynomial_stops_growing():
    k1, k2, _, _, k3 = STRONG_LENS.dist
    # d/dr [r (1 + k1 r^2 + k2 r^4 + k3 r^6)] = 1 + 3 k1 r^2 + 5 k2 r^4 + 7 k3 r^6: its first positive root.
    roots = np.roots([7 * k3, 5 * k2, 3 * k1, 1.0])
    r_fold = min(np.sqrt(z.real) for z in roots if abs(z.imag) < 1e-12 and z.real > 0)
    r_end = FIELD_SAFETY * r_fold
    rho_end = r_end * (1 + k1 * r_end**2 + k2 * r_end**4 + k3 * r_end**6)
    field = invertible_field(STRONG_LENS)
    assert field.folds
    np.testing.assert_allclose(field.rho, rho_end, rtol=0.01)  # a circle: radial model
    share = field.image_share()
    assert 0.5 < share < 1.0, share  # the image corners are beyond it
    assert "invertible out to" in field.describe()
    # A tame lens has no fold in its image.
    assert invertible_field(reference_camera()).image_share() == 1.0


def test_ray_map_is_exact_inside_the_field_and_marked_invalid_beyond():
    rm = pixel_rays(STRONG_LENS)
    assert not rm.covers_image
    valid = rm.valid_map
    assert 0.5 < valid.mean() < 1.0
    rng = np.random.default_rng(4)
    rows, cols = rng.integers(0, 720, 400), rng.integers(0, 1280, 400)
    ok = valid[rows, cols]
    cx, cy = rm.correction_maps
    rays = np.stack([rm.px[cols] + cx[rows, cols], rm.py[rows] + cy[rows, cols]], axis=-1)[ok]
    back = STRONG_LENS.pixels_from_normalized(STRONG_LENS.distort(rays))
    np.testing.assert_allclose(back, np.stack([cols, rows], axis=-1)[ok], atol=1e-4)
    # The corner pixels are beyond the fold: their rays are marked, not silently wrong.
    assert not valid[0, 0] and not valid[-1, -1]
    assert invertible_field(STRONG_LENS).contains_pixels(np.array([640.0, 360.0]))


# ------------------------------------------------------------------ the calibration's covariance
_COV_CAM = {"image_size": [640, 480], "fx": 657.5, "fy": 658.0, "cx": 303.0, "cy": 242.6}


def _cov_json(cov, dist=(-0.25, 0.12, 0.0, 0.0, 0.0), **extra):
    return {**_COV_CAM, "dist": list(dist), "cov": cov, **extra}


def test_camera_json_cov_round_trip_and_fallbacks(tmp_path):
    rng = np.random.default_rng(5)
    M = rng.normal(size=(9, 9))
    C = M @ M.T * 1e-4
    cam = CameraModel.from_dict(
        _cov_json({"params": list(CameraModel((640, 480), 1, 1, 1, 1).param_names), "matrix": C.tolist()})
    )
    np.testing.assert_array_equal(cam.calibration_cov, C)
    assert cam.calibration_cov_source == "cov"
    save_camera(cam, tmp_path / "camera.json")
    np.testing.assert_array_equal(load_camera(tmp_path / "camera.json").cov, C)
    # A subset, in another order: the others exact (0).
    sub = CameraModel.from_dict(_cov_json({"params": ["fy", "fx"], "matrix": [[4.0, 1.0], [1.0, 9.0]]}))
    assert sub.cov[0, 0] == 9.0 and sub.cov[1, 1] == 4.0 and sub.cov[0, 1] == 1.0 and sub.cov[2:].sum() == 0
    # Without cov: std as a diagonal (correlations unknown), or nothing.
    std = CameraModel(
        (640, 480),
        657.5,
        658.0,
        303.0,
        242.6,
        std={"fx": 0.1, "fy": 0.2, "cx": None, "cy": 0.3, "dist": [1e-3, 0, 0, 0, 0]},
    )
    np.testing.assert_allclose(np.diag(std.calibration_cov), [0.01, 0.04, 0, 0.09, 1e-6, 0, 0, 0, 0])
    assert std.calibration_cov_source == "std"
    assert CameraModel((640, 480), 657.5, 658.0, 303.0, 242.6).calibration_cov is None


@pytest.mark.parametrize(
    "cov, key, what",
    [
        ([[1.0]], "'cov'", "must be an object"),
        ({"params": ["fx", "zz"], "matrix": [[1, 0], [0, 1]]}, "'cov.params'", "'zz' is not a parameter"),
        ({"params": ["fx", "k4"], "matrix": [[1, 0], [0, 1]]}, "'cov.params'", "'k4' is not a parameter"),
        ({"params": ["fx", "fx"], "matrix": [[1, 0], [0, 1]]}, "'cov.params'", "distinct"),
        ({"params": ["fx", "fy"], "matrix": [[1, 0, 0], [0, 1, 0]]}, "'cov.matrix'", "square 2x2"),
        ({"params": ["fx", "fy"], "matrix": [[1, 0], [0, "a"]]}, "'cov.matrix[1][1]'", "finite number"),
        ({"params": ["fx", "fy"], "matrix": [[1, 0.5], [0.4, 1]]}, "'cov.matrix'", "not symmetric"),
        ({"params": ["fx", "fy"], "matrix": [[-1, 0], [0, 1]]}, "'cov.matrix[0][0]'", "variance of fx"),
        ({"params": ["fx", "fy"], "matrix": [[1, 2], [2, 1]]}, "'cov.matrix'", "not positive semi-definite"),
        ({"params": ["fx", "fy"], "matrix": [[0, 1e-3], [1e-3, 1]]}, "'cov.matrix'", "zero variance"),
    ],
)
def test_camera_json_cov_is_checked_naming_the_key(tmp_path, cov, key, what):
    path = tmp_path / "camera.json"
    path.write_text(json.dumps(_cov_json(cov)))
    with pytest.raises(InputError) as e:
        load_camera(path)
    msg = str(e.value)
    assert "\n" not in msg and str(path) in msg and key in msg and what in msg, msg
