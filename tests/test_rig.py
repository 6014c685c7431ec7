"""stiffmap.rig: rig.json round trips, errors naming the key, a rig of one camera, covariances."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers.random_matrices import random_rotation

from stiffmap.camera import CameraModel, save_camera
from stiffmap.errors import InputError
from stiffmap.geometry import transform_from
from stiffmap.io import dumps_json
from stiffmap.rig import EXTRINSIC_NAMES, Rig, RigCamera, load_rig, save_rig

LEFT = CameraModel((640, 480), 533.0, 533.2, 341.6, 234.3, (-0.289, 0.103, 0.001, -0.0003, 0.0))
RIGHT = CameraModel((1280, 960), 1070.0, 1071.0, 650.0, 470.0, (-0.2, 0.1, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0))


def _spd(n: int, rng: np.random.Generator) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T / n + 1e-3 * np.eye(n)


def _rig(rng: np.random.Generator, cov: bool = True) -> Rig:
    cams = (
        RigCamera("left", LEFT, np.eye(4)),
        RigCamera("right", RIGHT, transform_from(random_rotation(rng), rng.normal(0, 300, 3))),
        RigCamera("top", LEFT, transform_from(random_rotation(rng), rng.normal(0, 300, 3))),
    )
    rig = Rig(cams)
    n = len(rig.param_names)
    return Rig(cams, cov=_spd(n, rng) if cov else None, info={"rms_px": {"left": 0.1}, "views": []})


def _obj(rig: Rig) -> dict:
    return json.loads(dumps_json(rig.to_dict()))


def test_param_names_and_slices_agree(rng):
    rig = _rig(rng)
    names = rig.param_names
    assert len(names) == 9 + (12 + 6) + (9 + 6)
    for k, c in enumerate(rig.cameras):
        s = rig.intrinsic_slice(k)
        assert names[s] == tuple(f"{c.name}.{p}" for p in c.camera.param_names)
        e = rig.extrinsic_slice(k)
        if k == 0:
            assert e is None
        else:
            assert names[e] == tuple(f"{c.name}.{p}" for p in EXTRINSIC_NAMES)
            assert e.start == s.stop
    assert rig.index("top") == 2
    with pytest.raises(ValueError, match="no camera 'bottom' in the rig .cameras: left, right, top."):
        rig.index("bottom")


def test_rig_json_round_trip(rng, tmp_path):
    for _ in range(5):
        rig = _rig(rng)
        back = Rig.from_dict(_obj(rig))
        assert back.names == rig.names
        for a, b in zip(back.cameras, rig.cameras, strict=True):
            assert a.camera == b.camera  # image size, intrinsics, distortion
            np.testing.assert_allclose(a.cam2rig, b.cam2rig, rtol=0, atol=1e-12)
        np.testing.assert_allclose(back.cov, rig.cov, rtol=1e-15, atol=0)
        assert back.info == rig.info
    # save_rig writes atomically and keeps a different earlier file.
    path = tmp_path / "rig.json"
    assert save_rig(rig, path) is None
    assert load_rig(path).names == rig.names
    other = _rig(rng)
    backup = save_rig(other, path)
    assert backup is not None and load_rig(backup).cov is not None
    np.testing.assert_allclose(load_rig(path).cov, other.cov, rtol=1e-15)


def test_a_camera_json_is_a_rig_of_one_camera(tmp_path):
    cov = np.diag([0.1, 0.1, 0.2, 0.2, 1e-4, 1e-3, 1e-6, 1e-6, 1e-2])
    cam = CameraModel(LEFT.image_size, LEFT.fx, LEFT.fy, LEFT.cx, LEFT.cy, LEFT.dist, cov=cov)
    save_camera(cam, tmp_path / "camera.json")
    rig = load_rig(tmp_path / "camera.json")
    assert rig.names == ("camera",) and len(rig) == 1
    np.testing.assert_array_equal(rig.cameras[0].cam2rig, np.eye(4))
    assert rig.cameras[0].camera == cam
    assert rig.param_names == tuple(f"camera.{p}" for p in cam.param_names)
    np.testing.assert_allclose(rig.calibration_cov, cov)
    assert Rig.single(cam).to_dict()["cameras"][0]["name"] == "camera"


def test_calibration_cov_without_a_joint_one_is_the_cameras_blocks(rng):
    rig = _rig(rng, cov=False)
    assert rig.calibration_cov is None  # no camera knows its uncertainty
    cov_r = _spd(12, rng)
    right = CameraModel(RIGHT.image_size, RIGHT.fx, RIGHT.fy, RIGHT.cx, RIGHT.cy, RIGHT.dist, cov=cov_r)
    cams = list(rig.cameras)
    cams[1] = RigCamera("right", right, cams[1].cam2rig)
    C = Rig(tuple(cams)).calibration_cov
    s = Rig(tuple(cams)).intrinsic_slice(1)
    np.testing.assert_allclose(C[s, s], cov_r)
    mask = np.zeros_like(C, dtype=bool)
    mask[s, s] = True
    assert np.all(C[~mask] == 0)  # the other cameras and every cam2rig taken as exact
    # With a joint covariance, that one.
    joint = _rig(rng)
    assert joint.calibration_cov is joint.cov


def _load_error(tmp_path, obj) -> tuple:
    """``obj`` written as rig.json and loaded: its path and the one-line InputError's text."""
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(obj))
    with pytest.raises(InputError) as info:
        load_rig(path)
    return path, str(info.value)


@pytest.mark.parametrize(
    ("change", "key", "what"),
    [
        (lambda o: o.pop("cameras"), None, "expected a JSON object with the key 'cameras'"),
        (lambda o: o.update(cameras=[]), "'cameras'", "non-empty list"),
        (lambda o: o["cameras"].__setitem__(1, 3), "'cameras[1]'", "must be an object"),
        (lambda o: o["cameras"][1].pop("name"), "'cameras[1].name'", "non-empty name"),
        (
            lambda o: o["cameras"][2].update(name="left"),
            "'cameras[2].name'",
            "'left' is the name of an earlier",
        ),
        (lambda o: o["cameras"][1].pop("cam2rig"), "'cameras[1].cam2rig'", "missing"),
        (lambda o: o["cameras"][1].update(cam2rig=[[1, 0, 0]]), "'cameras[1].cam2rig'", "4x4 list"),
        (
            lambda o: o["cameras"][1].update(cam2rig=(2 * np.eye(4)).tolist()),
            "'cameras[1].cam2rig'",
            "last row must be [0, 0, 0, 1]",
        ),
        (
            lambda o: o["cameras"][0].update(cam2rig=transform_from(np.eye(3), [1, 0, 0]).tolist()),
            "'cameras[0].cam2rig'",
            "must be the identity",
        ),
        (lambda o: o["cameras"][2].update(fx=-5), "'fx'", "cameras[2] (top)"),
        (lambda o: o["cov"]["params"].__setitem__(0, "left.zoom"), "'cov.params'", "'left.zoom'"),
    ],
)
def test_rig_json_errors_name_the_key(rng, tmp_path, change, key, what):
    obj = _obj(_rig(rng))
    change(obj)
    path, msg = _load_error(tmp_path, obj)
    assert str(path) in msg and what in msg and "\n" not in msg, msg
    if key:
        assert key in msg, msg


def test_a_covariance_in_another_order_is_read_in_the_rig_order(rng):
    rig = _rig(rng)
    obj = _obj(rig)
    order = rng.permutation(len(rig.param_names))
    obj["cov"] = {
        "params": [rig.param_names[i] for i in order],
        "matrix": rig.cov[np.ix_(order, order)].tolist(),
    }
    np.testing.assert_allclose(Rig.from_dict(obj).cov, rig.cov, rtol=1e-15)


def _with_dispersion(rig: Rig, rng: np.random.Generator) -> Rig:
    """The rig with a random dispersion over each camera's cam2rig perturbation after the first."""
    D = np.zeros((len(rig.param_names),) * 2)
    for k in range(1, len(rig)):
        s = rig.extrinsic_slice(k)
        D[s, s] = _spd(6, rng)
    return Rig(rig.cameras, cov=rig.cov, info=rig.info, dispersion=D)


def test_the_dispersion_round_trips_and_an_older_file_has_none(rng, tmp_path):
    rig = _with_dispersion(_rig(rng), rng)
    obj = _obj(rig)
    names = [f"{c}.{p}" for c in ("right", "top") for p in EXTRINSIC_NAMES]
    assert obj["dispersion"]["params"] == names  # over the cam2rig perturbations only
    back = Rig.from_dict(obj)
    np.testing.assert_allclose(back.dispersion, rig.dispersion, rtol=1e-15, atol=0)
    assert "dispersion" not in back.info
    # A file written before the dispersion existed: loaded, dispersion unknown (None).
    del obj["dispersion"]
    assert Rig.from_dict(obj).dispersion is None
    # Over a subset of the cameras (the others' zero), in any order.
    obj["dispersion"] = {"params": names[6:][::-1], "matrix": np.diag(np.arange(1.0, 7.0)).tolist()}
    D = Rig.from_dict(obj).dispersion
    s = rig.extrinsic_slice(2)
    np.testing.assert_array_equal(np.diag(D)[s], np.arange(6.0, 0.0, -1.0))
    assert np.count_nonzero(D) == 6


@pytest.mark.parametrize(
    ("change", "key", "what"),
    [
        (lambda o: o.update(dispersion=[1, 2]), "'dispersion'", "must be an object"),
        (
            lambda o: o["dispersion"]["params"].__setitem__(0, "left.fx"),
            "'dispersion.params'",
            "'left.fx' is not a parameter of the cameras' poses",
        ),
        (
            lambda o: o["dispersion"]["matrix"][0].__setitem__(0, -1.0),
            "'dispersion.matrix[0][0]'",
            "variance of right.tx must be zero or positive",
        ),
    ],
)
def test_a_bad_dispersion_is_named(rng, tmp_path, change, key, what):
    obj = _obj(_with_dispersion(_rig(rng), rng))
    change(obj)
    path, msg = _load_error(tmp_path, obj)
    assert str(path) in msg and key in msg and what in msg and "\n" not in msg, msg
    # A rig of one camera has no poses between cameras.
    one = {"cameras": [obj["cameras"][0]], "dispersion": {"matrix": [[1.0]]}}
    with pytest.raises(InputError, match="'dispersion'.*one camera"):
        Rig.from_dict(one)
