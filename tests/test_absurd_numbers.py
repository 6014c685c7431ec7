"""Finite but absurd numbers in camera.json and rig.json: refused by the reader, naming the key.

Before, they reached the linear algebra: a camera 1e200 mm from the rig's first one gave "math
domain error" in the fusion, a covariance of 1e308 "eigenvalues did not converge" in the
reader's own check (C + C^T overflowed), a std fx of 1e10 "singular matrix", of 1e200 a
1-sigma "nan, nan, nan" printed with exit 0. The limits (:func:`stiffmap.camera.sigma_limits`,
:data:`stiffmap.rig.MAX_RIG_MM`) are wide: a rig whose every uncertainty sits just below them
still fuses its cameras' poses into finite numbers.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers.board_scenes import exact_corners
from helpers.rig_scenes import board2cams, board_in_rig, rig_camera, stereo_rig

from stiffmap.camera import CameraModel, sigma_limits
from stiffmap.cli import main
from stiffmap.errors import InputError
from stiffmap.io import dumps_json
from stiffmap.rig import MAX_RIG_MM, Rig
from stiffmap.targets import Chessboard
from stiffmap.vision.detection import BoardDetection
from stiffmap.vision.fuse import fuse_poses
from stiffmap.vision.pose import estimate_pose

BOARD = Chessboard(8, 6, 10.0)


def _rig_dict(rig: Rig) -> dict:
    return json.loads(dumps_json(rig.to_dict()))


def _std_at(camera: CameraModel, factor: float) -> dict:
    """``camera.json``'s std, each at ``factor`` times its limit."""
    s = sigma_limits(camera) * factor
    return {"fx": s[0], "fy": s[1], "cx": s[2], "cy": s[3], "dist": list(s[4:])}


def _extrinsic_limits(rig: Rig) -> np.ndarray:
    return np.array([2 * MAX_RIG_MM] * 3 + [2 * np.pi] * 3)


@pytest.mark.parametrize(
    "change, key",
    [
        (lambda d: d["cameras"][1]["cam2rig"][0].__setitem__(3, 1e200), "cameras[1].cam2rig"),
        (lambda d: d["cameras"][1]["cam2rig"][2].__setitem__(3, -2 * MAX_RIG_MM), "cameras[1].cam2rig"),
        (lambda d: d["cameras"][1].__setitem__("std", {"fx": 1e10}), "std.fx"),
        (lambda d: d["cameras"][1].__setitem__("std", {"fx": 1e200}), "std.fx"),
        (lambda d: d["cameras"][0].__setitem__("std", {"dist": [0, 0, 0, 5.0, 0]}), "std.dist[3]"),
    ],
    ids=["cam2rig 1e200", "cam2rig 200 m", "std fx 1e10", "std fx 1e200", "std p2 5"],
)
def test_absurd_rig_numbers_are_refused_naming_the_key(change, key):
    d = _rig_dict(stereo_rig(rig_camera()))
    change(d)
    with pytest.raises(InputError) as e:
        Rig.from_dict(d, source="rig.json")
    assert str(e.value).startswith("rig.json") and f"key '{key}'" in str(e.value)


@pytest.mark.parametrize("value", [1e308, 1e200, 1e12])
def test_a_huge_covariance_is_refused_by_the_reader_not_its_linear_algebra(value):
    rig = stereo_rig(rig_camera())
    n = len(rig.param_names)
    d = _rig_dict(rig)
    d["cov"] = {"params": list(rig.param_names), "matrix": (np.eye(n) * value).tolist()}
    with pytest.raises(InputError, match=r"key 'cov.matrix': a 1-sigma of .* for left.fx is not a"):
        Rig.from_dict(d, source="rig.json")
    cam = rig_camera().to_dict()
    cam["cov"] = {"matrix": (np.eye(9) * value).tolist()}
    with pytest.raises(InputError, match="key 'cov.matrix': a 1-sigma of .* for fx is not a"):
        CameraModel.from_dict(cam)


def _view(camera: CameraModel, T: np.ndarray, rng: np.random.Generator):
    uv = exact_corners(camera, BOARD, T) + rng.normal(size=(BOARD.n_corners, 2)) * 0.1
    n = BOARD.n_corners
    det = BoardDetection(board=BOARD, corners=uv, ids=np.arange(n), residual_px=np.zeros(n))
    return estimate_pose(det, BOARD, camera, refine="corners")


@pytest.mark.parametrize("joint", [False, True], ids=["cameras' std", "joint cov"])
def test_uncertainties_just_inside_the_limits_fuse_into_finite_poses(joint):
    """The limits keep what the linear algebra can carry: every 1-sigma at 99.9 % of its limit,
    read, and both cameras' poses of a board fused into a finite pose and covariance."""
    base = stereo_rig(rig_camera())
    d = _rig_dict(base)
    if joint:
        s = np.concatenate([sigma_limits(base.cameras[0].camera), sigma_limits(base.cameras[1].camera)])
        s = np.concatenate([s, _extrinsic_limits(base)]) * 0.999
        d["cov"] = {"params": list(base.param_names), "matrix": np.diag(s**2).tolist()}
    else:
        for c, rc in zip(d["cameras"], base.cameras, strict=True):
            c["std"] = _std_at(rc.camera, 0.999)
    rig = Rig.from_dict(d)
    assert rig.calibration_cov_source == ("cov" if joint else "cameras")
    T_rig = board_in_rig(BOARD)
    rng = np.random.default_rng(3)
    poses = {
        k: _view(c.camera, T, rng)
        for k, (c, T) in enumerate(zip(rig.cameras, board2cams(rig, T_rig), strict=True))
    }
    fused = fuse_poses(rig, poses, board=BOARD)
    assert np.all(np.isfinite(fused.board2rig)) and np.all(np.isfinite(fused.cov))
    assert np.all(np.linalg.eigvalsh(fused.cov) > 0)
    # Corners within 0.1 px: the fused pose is the board's, whatever the calibration's uncertainty.
    np.testing.assert_allclose(fused.board2rig[:3, 3], T_rig[:3, 3], atol=0.05)
    for c in rig.cameras:  # and just past the limits, the reader says so
        past = c.camera.to_dict()
        past["std"] = _std_at(c.camera, 1.001)
        with pytest.raises(InputError, match="key 'std.fx'"):
            CameraModel.from_dict(past)


def test_load_n_beyond_a_plausible_load_is_a_user_error(capsys):
    assert main.main(["model", "delta", "--load-n", "1e10"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "error: --load-n 1e+10 N is beyond +-1e+09 N: not a plausible load"
