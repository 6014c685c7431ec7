"""OpenCV's fisheye lens model (``CameraModel(model="fisheye")``, :mod:`stiffmap.lens`).

Checked against OpenCV's own ``cv2.fisheye`` (an independent implementation), by round trips
over every pixel of a 150-degree lens, by central differences of every Jacobian, at folds and
beyond 90 degrees off axis, and through camera.json (old files unchanged).
"""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers.finite_difference import central_jacobian
from helpers.fuzz_vision import mutated_json_value
from hypothesis import given

from stiffmap.camera import (
    FIELD_SAFETY,
    CameraModel,
    UndistortionError,
    invertible_field,
    load_camera,
    pixel_rays,
    plausibility_problems,
    save_camera,
)
from stiffmap.errors import InputError
from stiffmap.geometry import transform_from
from stiffmap.lens import MAX_THETA, fisheye_theta_d, fisheye_theta_end
from stiffmap.posemath import perturb_pose, projection_jacobian

#: A 150-degree fisheye: 640x480 px, f = 300 px, the image corner 74 degrees off axis.
FISH = CameraModel((640, 480), 300.0, 300.5, 322.4, 238.7, (0.03, -0.01, 0.002, -0.0003), model="fisheye")


def _directions(rng, n: int, max_deg: float) -> np.ndarray:
    """Unit rays up to ``max_deg`` off the optical axis, (n, 3)."""
    theta = rng.uniform(0.0, math.radians(max_deg), n)
    phi = rng.uniform(-np.pi, np.pi, n)
    return np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]


def test_projection_matches_opencv_fisheye_out_to_85_degrees(rng):
    P = _directions(rng, 600, 85.0) * rng.uniform(50.0, 3000.0, (600, 1))  # mm
    ours = FISH.project(P)
    ref, _ = cv2.fisheye.projectPoints(
        P.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), FISH.matrix, FISH.dist_array
    )
    np.testing.assert_allclose(ours, ref.reshape(-1, 2), rtol=0, atol=1e-9)  # px


def test_every_pixel_of_a_150_degree_fisheye_has_its_ray():
    u, v = np.meshgrid(np.arange(640.0), np.arange(480.0))
    uv = np.stack([u, v], axis=-1)
    rays = FISH.rays_from_pixels(uv)  # every pixel: no UndistortionError
    np.testing.assert_allclose(FISH.pixels_from_normalized(FISH.distort(rays)), uv, rtol=0, atol=1e-9)  # px
    # The same rays as OpenCV's own iterative inverse.
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-15)
    ref = cv2.fisheye.undistortPoints(
        uv[::7, ::7].reshape(-1, 1, 2), FISH.matrix, FISH.dist_array, criteria=crit
    )
    np.testing.assert_allclose(rays[::7, ::7].reshape(-1, 2), ref.reshape(-1, 2), rtol=0, atol=1e-12)
    # The corner pixel, 401 px from the principal point, sees 74 degrees off axis (the k's shrink it).
    theta = math.atan(np.hypot(*rays[0, 0]))
    assert fisheye_theta_d(theta, FISH.dist)[0] == pytest.approx(np.hypot(322.4 / 300.0, 238.7 / 300.5))
    assert math.degrees(theta) > 74.0
    field = invertible_field(FISH)
    assert not field.folds and field.image_share() == 1.0
    assert field.describe() == "the lens model is one to one over the whole field of view"
    # The ray cache (renderer and photometric fit): exact rays, the whole image valid.
    rm = pixel_rays(FISH)
    assert rm.covers_image
    rows, cols = np.arange(-1.0, 481.0), np.arange(-1.0, 641.0)  # with the renderer's halo
    rx, ry = rm.block(rows, cols)
    exact = FISH.rays_from_pixels(np.stack(np.meshgrid(cols, rows), axis=-1))
    np.testing.assert_allclose(np.stack([rx, ry], axis=-1), exact, rtol=0, atol=1e-15)
    cx, cy = rm.correction_maps
    # float32 corrections of rays up to 2.9: 3e-7 of a ray, 1e-4 px at f = 300 px.
    np.testing.assert_allclose(rm.px[None, :] + cx, rays[..., 0], rtol=0, atol=4e-7)
    np.testing.assert_allclose(rm.py[:, None] + cy, rays[..., 1], rtol=0, atol=4e-7)


def test_fisheye_jacobians_match_central_differences(rng):
    theta, phi = np.radians(rng.uniform(0.0, 80.0, 60)), rng.uniform(-np.pi, np.pi, 60)
    xy = np.tan(theta)[:, None] * np.c_[np.cos(phi), np.sin(phi)]  # ideal x/z, y/z
    xy = np.r_[xy, [[1e-9, -2e-9], [0.0, 0.0], [3e-8, 1e-8]]]  # the series about the axis
    _, J = FISH.distort_with_jacobian(xy)
    fd = central_jacobian(FISH.distort, xy, 1e-6)
    np.testing.assert_allclose(J, fd, rtol=1e-6, atol=1e-8)
    # d(u, v) / d(fx, fy, cx, cy, k1..k4), points held fixed in the camera frame.
    Jc = FISH.projection_param_jacobian(xy)
    steps = np.array([1e-3, 1e-3, 1e-3, 1e-3, 1e-6, 1e-6, 1e-6, 1e-6])
    fd = central_jacobian(
        lambda p: np.stack(
            [FISH.with_params(q).pixels_from_normalized(FISH.with_params(q).distort(xy)) for q in p]
        ),
        FISH.params[None, :],
        steps,
    )[0]
    np.testing.assert_allclose(Jc, fd, rtol=1e-6, atol=1e-6)  # px per unit parameter
    # The pose's projection Jacobian through the fisheye model (points up to 70 degrees off axis).
    T = transform_from(np.eye(3), [-40.0, 25.0, 120.0])
    q = np.c_[rng.uniform(-300, 300, (30, 2)), np.zeros(30)]
    _, Jp = projection_jacobian(T, q, FISH)
    fd = central_jacobian(
        lambda d: np.stack([projection_jacobian(perturb_pose(T, di), q, FISH)[0] for di in d]),
        np.zeros((1, 6)),
        np.array([1e-4, 1e-4, 1e-4, 1e-7, 1e-7, 1e-7]),
    )[0]
    np.testing.assert_allclose(Jp, fd, rtol=1e-6, atol=1e-5)  # px per mm or rad


def test_a_fisheye_polynomial_that_folds_ends_its_field_at_the_fold():
    # theta_d' = 1 + 3 k1 theta^2 is 0 at theta = 1 / sqrt(-3 k1): 66.1 degrees for k1 = -0.25.
    cam = CameraModel((640, 480), 300.0, 300.0, 320.0, 240.0, (-0.25, 0.0, 0.0, 0.0), model="fisheye")
    theta_fold = 1.0 / math.sqrt(0.75)
    end, folds = fisheye_theta_end(cam.dist)
    assert folds and end == pytest.approx(theta_fold, abs=1e-9)
    field = invertible_field(cam)
    rho_end = fisheye_theta_d(FIELD_SAFETY * theta_fold, cam.dist)[0]
    np.testing.assert_allclose(field.rho, rho_end, rtol=1e-12)  # a disc
    assert field.folds and 0.5 < field.image_share() < 1.0  # the corners (76 degrees) are beyond it
    assert "invertible out to" in field.describe()
    with pytest.raises(UndistortionError, match=r"at \(0, 0\) px, 400 px from the principal point"):
        cam.rays_from_pixels(np.array([0.0, 0.0]))
    rm = pixel_rays(cam)
    assert not rm.covers_image and rm.valid_map[240, 320] and not rm.valid_map[0, 0]


def test_pixels_of_a_lens_wider_than_180_degrees_beyond_90_degrees_have_no_ray():
    # f = 150 px: the image corner is 400 px = 153 degrees off axis, the side 320 px = 122 degrees.
    cam = CameraModel((640, 480), 150.0, 150.0, 320.0, 240.0, (0.0, 0.0, 0.0, 0.0), model="fisheye")
    field = invertible_field(cam)
    assert not field.folds
    share = field.image_share()
    # Inside the disc of radius f * 89.5 degrees (234 px), less the safety margin: pi 234^2 / (640 480).
    assert share == pytest.approx(np.pi * (150.0 * MAX_THETA) ** 2 / (640 * 480), rel=0.03)
    assert "89.5 degrees off axis" in field.describe() and f"{100 * share:.1f} %" in field.describe()
    ray = cam.rays_from_pixels(np.array([320.0 + 150.0 * math.radians(80.0), 240.0]))
    assert math.degrees(math.atan(ray[0])) == pytest.approx(80.0, abs=1e-9)
    with pytest.raises(UndistortionError, match="90 degrees or more off axis"):
        cam.rays_from_pixels(np.array([0.0, 240.0]))


def test_fisheye_camera_json_round_trip_and_pinhole_files_unchanged(tmp_path):
    C = np.diag([0.5, 0.5, 0.3, 0.3, 1e-4, 4e-4, 1e-3, 2e-3])
    C[4, 5] = C[5, 4] = -1.5e-4
    cam = CameraModel(FISH.image_size, *FISH.params[:4], FISH.dist, cov=C, rms_px=0.03, model="fisheye")
    assert cam.param_names == ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4")
    save_camera(cam, tmp_path / "camera.json")
    data = json.loads((tmp_path / "camera.json").read_text())
    assert data["model"] == "fisheye" and data["cov"]["params"][4:] == ["k1", "k2", "k3", "k4"]
    back = load_camera(tmp_path / "camera.json")
    assert back == cam and back.model == "fisheye"
    np.testing.assert_array_equal(back.cov, C)
    # A pinhole camera's file has no "model" key, as it always had, and reads as "opencv".
    pin = CameraModel((640, 480), 657.5, 658.0, 303.0, 242.6, (-0.25, 0.12, 0.0, 0.0, 0.0))
    save_camera(pin, tmp_path / "pin.json")
    assert "model" not in json.loads((tmp_path / "pin.json").read_text())
    assert load_camera(tmp_path / "pin.json").model == "opencv"
    # A strong but real fisheye calibration (the udacity set's, k3 -24.5, k4 41.1) is plausible.
    real = CameraModel(
        (1280, 720), 1172.1, 1169.0, 650.5, 390.0, (-0.283, 4.70, -24.48, 41.12), model="fisheye"
    )
    assert plausibility_problems(real) == []


_FISH_JSON = {"image_size": [640, 480], "fx": 300.0, "fy": 300.5, "cx": 322.4, "cy": 238.7}


@pytest.mark.parametrize(
    "change, key, what",
    [
        ({"model": "kannala-brandt"}, "'model'", "must be one of 'opencv', 'fisheye'"),
        ({"model": 3}, "'model'", "got 3"),
        (
            {"dist": [0.03, -0.01, 0.002, 0.0, 0.0]},
            "'dist'",
            "4 numbers [k1, k2, k3, k4] (the fisheye model)",
        ),
        ({"dist": [0.03, -0.01, 0.002, 5000.0]}, "'dist[3]'", "k4 = 5000 is not a plausible radial"),
        ({"cov": {"params": ["fx", "p1"], "matrix": [[1.0, 0.0], [0.0, 1.0]]}}, "'cov.params'", "'p1'"),
        ({"dist": [-3.0, 0.0, 0.0, 0.0]}, "'dist'", "folds over"),
    ],
)
def test_a_bad_fisheye_camera_json_names_the_key(tmp_path, change, key, what):
    path = tmp_path / "cam.json"
    path.write_text(
        json.dumps({**_FISH_JSON, "model": "fisheye", "dist": [0.03, -0.01, 0.002, 0.0], **change})
    )
    with pytest.raises(InputError) as info:
        load_camera(path)
    text = str(info.value)
    assert str(path) in text and key in text and what in text, text


@pytest.mark.fuzz
@given(mutated_json_value(json.dumps({**_FISH_JSON, "model": "fisheye", "dist": [0.03, -0.01, 0.002, 0.0]})))
def test_a_mutated_fisheye_camera_json_is_refused_by_key_or_maps_its_pixels(data):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "camera.json"
        path.write_bytes(data)
        try:
            cam = load_camera(path)
        except InputError as e:
            assert str(path) in str(e) and "\n" not in str(e)
            return
    # A camera that passes the checks maps its principal point's neighbourhood both ways.
    uv = np.array([[cam.cx, cam.cy], [cam.cx + 5.0, cam.cy - 3.0]])
    np.testing.assert_allclose(
        cam.pixels_from_normalized(cam.distort(cam.rays_from_pixels(uv))), uv, atol=1e-6
    )
