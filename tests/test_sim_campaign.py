"""Virtual campaigns: the directory, the truth, determinism, and the round trip through
stiffmap's campaign derivation (must-show: every K within 2 % of truth.json)."""

from __future__ import annotations

import gzip
import json

import cv2
import numpy as np
import pytest
from helpers.board_scenes import scaled_camera
from helpers.corner_round_trip import round_trip_from_true_corners

from stiffmap.camera import load_camera, reference_camera
from stiffmap.campaign.positions import plan
from stiffmap.campaign.simulated import write_campaign
from stiffmap.campaign.simulated_sensor import write_sensor_campaign
from stiffmap.campaign.spec import load_spec
from stiffmap.campaign.truth import TRUTH_NAME, load_truth
from stiffmap.errors import InputError
from stiffmap.loads import paper9
from stiffmap.models.presets import paper48
from stiffmap.models.prr3 import PRR3
from stiffmap.sim.render import Photometry
from stiffmap.sim.robot import VirtualRobot, delta_robot, smooth_field, with_rotational_compliance
from stiffmap.sim.scene import default_scene
from stiffmap.sim.testbed import SimConfig

#: A handful of paper48 positions: the centre, the nearest and farthest corners, both planes' extremes.
HANDFUL = np.array(
    [[-66.67, 66.67, -310.0], [-200.0, -200.0, -200.0], [200.0, 200.0, -400.0], [200.0, -200.0, -200.0]]
)


def _config(**kw) -> SimConfig:
    base = dict(
        scene=default_scene(),
        robot=delta_robot(),
        positions=HANDFUL,
        loads=tuple(paper9()),
        repeats=3,
        seed=7,
    )
    base.update(kw)
    return SimConfig(**base)


def test_round_trip_recovers_every_K_within_2_percent(tmp_path):
    # Must-show "round trip" on the path available before the vision code: the campaign
    # is written (campaign.toml, camera.json, truth.json, true corners), read back by the
    # campaign spec, every image measured by solvePnP on its true corners, displacements
    # and K derived by the campaign runner, and compared with truth.json.
    write_campaign(tmp_path / "c", _config(), render_images=False)
    res = round_trip_from_true_corners(tmp_path / "c")
    assert len(res) == len(HANDFUL)
    for K, _, K_true in res:
        err = np.linalg.norm(K - K_true) / np.linalg.norm(K_true)
        # Only the robot's per-image jitter (1 um) remains: measured errors ~0.1-0.3 %.
        assert err < 0.02


def test_round_trip_with_corner_noise_is_consistent_with_its_uncertainty(tmp_path):
    # With 0.02 px of corner noise the identified K scatters; the campaign's own standard
    # errors must account for it (|K - K_true| within 4.5 standard errors, 36 entries).
    write_campaign(tmp_path / "c", _config(repeats=4), render_images=False)
    res = round_trip_from_true_corners(tmp_path / "c", noise_px=0.02, seed=3)
    z = np.concatenate([np.abs(K - Kt).ravel() / Ks.ravel() for K, Ks, Kt in res])
    assert z.max() < 4.5
    assert 0.3 < np.sqrt(np.mean(z**2)) < 2.0  # neither over- nor under-confident


def test_six_by_six_field_with_offset_load_round_trip(tmp_path):
    # A platform with rotational compliance, loads hung 30 mm below the tool point: the
    # boards turn, and the measured point (the tool point, via point_mm) still moves by
    # the translational compliance the truth states.
    rb = VirtualRobot(
        with_rotational_compliance(smooth_field, 3.0e4, coupling_n=30.0),
        load_point_mm=(0.0, 0.0, -30.0),
    )
    write_campaign(tmp_path / "c", _config(robot=rb, repeats=2), render_images=False)
    truth = json.loads((tmp_path / "c" / TRUTH_NAME).read_text())
    assert truth["robot"]["field"] == "6x6" and "K_tcp" in truth["positions"][0]
    for K, _, K_true in round_trip_from_true_corners(tmp_path / "c"):
        assert np.linalg.norm(K - K_true) / np.linalg.norm(K_true) < 0.02


def test_campaign_directory_images_and_determinism(tmp_path, monkeypatch):
    # Quarter-resolution camera (same field of view) to keep the test fast.
    cam = scaled_camera(reference_camera(), 0.25)
    cfg = _config(
        scene=default_scene(cam),
        positions=HANDFUL[:2],
        loads=tuple(paper9()[:3]),
        repeats=1,
        border_px=4.0,
        photometry=Photometry(clutter=True),
        calibration_views=4,  # few, to keep the test fast (a campaign takes 20 by default)
    )
    a = write_campaign(tmp_path / "a", cfg, workers=1)
    b = write_campaign(tmp_path / "b", cfg, workers=2)
    # On a local Dask cluster whose workers are taken not to see the folder: they send every
    # image back and this process writes it (docs/scaling.md).
    monkeypatch.setattr("stiffmap.sim.render_pool._cluster_sees", lambda cluster, out: False)
    c = write_campaign(tmp_path / "c", cfg, workers=2, dask="local")
    assert a.n_images == b.n_images == c.n_images == 2 * 3 * 1 * 2
    assert a.calibration.calibrated and a.calibration.n_views == a.calibration.n_used == 4
    files_a = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file())
    for other in ("b", "c"):
        files = sorted(p.relative_to(tmp_path / other) for p in (tmp_path / other).rglob("*") if p.is_file())
        assert files == files_a
        for rel in files_a:  # byte-identical, whatever the number of processes or where they run
            assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / other / rel).read_bytes(), rel
    # The spec reads back with stiffmap's parser and names exactly the images written.
    spec = load_spec(tmp_path / "a")
    tasks = plan(spec, tmp_path / "a")
    assert all(not t.missing for t in tasks) and sum(len(t.images) for t in tasks) == 12
    assert spec.targets.fixed.board == "9x6" and spec.targets.mobile.board == "6x5"
    np.testing.assert_allclose(spec.positions.resolve(), HANDFUL[:2])
    np.testing.assert_allclose(
        [ld.force for ld in spec.loads.resolve(spec.g)], [ld.force for ld in paper9()[:3]]
    )
    # camera.json: the camera calibrated from the rendered views (stiffmap calibrate's
    # calibration), close to the true one but not it, with its covariance; truth.json keeps
    # the true camera (same keys as camera.json) beside the calibrated one.
    assert sorted(p.name for p in (tmp_path / "a" / "calibration").iterdir()) == [
        f"view{k:02d}.png" for k in range(1, 5)
    ]
    on_disk = json.loads((tmp_path / "a" / "camera.json").read_text())
    calibrated = load_camera(tmp_path / "a" / "camera.json")
    assert calibrated.to_dict() != cam.to_dict() and "cov" in on_disk
    assert [v["image"] for v in on_disk["views"]] == [f"calibration/view{k:02d}.png" for k in range(1, 5)]
    # Measured at this quarter resolution (648x486, 4 views): fx, fy within 0.04 %, the
    # principal point within 0.3 px, RMS 0.02 px.
    for k in ("fx", "fy"):
        assert getattr(calibrated, k) == pytest.approx(getattr(cam, k), rel=2e-3)  # 0.2 %
    for k in ("cx", "cy"):
        assert getattr(calibrated, k) == pytest.approx(getattr(cam, k), abs=1.5)  # px
    assert calibrated.rms_px < 0.1  # px
    truth = load_truth(tmp_path / "a")
    assert truth.data["camera"] == cam.to_dict() and truth.camera == cam
    assert truth.data["calibrated_camera"] == on_disk and truth.calibrated_camera == calibrated
    cal = truth.data["calibration"]
    assert cal["camera_json"] == "calibrated" and cal["board"] == "11x8" and cal["n_used"] == 4
    assert cal["relative_error"]["fx"] == pytest.approx(calibrated.fx / cam.fx - 1, rel=1e-9)
    assert truth.calibration == a.calibration
    assert [v["file"] for v in cal["views"]] == [f"calibration/view{k:02d}.png" for k in range(1, 5)]
    # Each view's true pose is where its board is: the views' true corners (in the side
    # file) are what the calibration's detection finds, to a tenth of a pixel.
    views = json.loads(gzip.decompress((tmp_path / "a" / "truth_corners.json.gz").read_bytes()))
    view = views["calibration"][0]
    assert view["file"] == cal["views"][0]["file"]
    np.testing.assert_allclose(view["calibration"]["board2cam"], cal["views"][0]["board2cam"], atol=1e-12)
    img = cv2.imread(str(tmp_path / "a" / view["file"]), cv2.IMREAD_GRAYSCALE)
    ok, found = cv2.findChessboardCornersSB(img, (11, 8))
    assert ok
    uv = np.asarray(view["calibration"]["corners_px"])
    assert np.linalg.norm(found.reshape(-1, 1, 2) - uv[None], axis=2).min(axis=1).max() < 0.3  # px
    # truth.json: K per position.
    np.testing.assert_allclose(truth.K, delta_robot().stiffness(HANDFUL[:2]), rtol=1e-12)
    assert [e["position"] for e in truth.data["positions"]] == HANDFUL[:2].tolist()
    # The true corners are where the boards are: a dark/light alternation around each corner.
    corners = truth.corners()
    im = truth.images()[1]
    assert im["state"] == "loaded" and im["file"] in corners
    img = cv2.imread(str(tmp_path / "a" / im["file"]), cv2.IMREAD_GRAYSCALE)
    uv = corners[im["file"]]["mobile"]["corners_px"]
    ok, found = cv2.findChessboardCornersSB(img, (6, 5))
    assert ok
    d = np.linalg.norm(found.reshape(-1, 1, 2) - uv[None], axis=2).min(axis=1)
    assert d.max() < 0.3  # px, quarter-resolution image
    # The loaded platform moved by K^-1 F (load 1: 0.5 kg along +y, mostly along the
    # camera axis) up to the robot's per-image jitter (1 um); the fixed board did not move.
    un = truth.images()[0]
    du = np.asarray(im["tcp2base"])[:3, 3] - np.asarray(un["tcp2base"])[:3, 3]
    np.testing.assert_allclose(du, np.linalg.solve(truth.K[0], paper9()[0].force), atol=0.01)  # mm
    cu = corners[un["file"]]
    assert np.abs(corners[im["file"]]["fixed"]["corners_px"] - cu["fixed"]["corners_px"]).max() < 1e-9
    assert np.abs(uv - cu["mobile"]["corners_px"]).max() > 0.02  # px
    # The side file is a deterministic gzip (no time stamp).
    raw = (tmp_path / "a" / "truth_corners.json.gz").read_bytes()
    assert raw[4:8] == b"\x00\x00\x00\x00" and json.loads(gzip.decompress(raw))["images"]


def test_output_directory_rules(tmp_path):
    cfg = _config(positions=HANDFUL[:1], loads=tuple(paper9()[:3]), repeats=1)
    out = tmp_path / "c"
    write_campaign(out, cfg, render_images=False)
    with pytest.raises(InputError, match="not empty"):
        write_campaign(out, cfg, render_images=False)
    (out / "extra_user_file.txt").write_text("keep me")
    write_campaign(out, cfg, render_images=False, force=True)  # a previous simulation: allowed
    assert (out / "extra_user_file.txt").read_text() == "keep me"
    # An interrupted simulation (no truth.json yet, the marker written first) can be overwritten.
    (out / "truth.json").unlink()
    (out / "images" / "p01").mkdir(parents=True)
    (out / "images" / "p01" / "half_written.png").write_bytes(b"...")
    (out / "calibration").mkdir()
    (out / "calibration" / "view01.png").write_bytes(b"...")
    write_campaign(out, cfg, render_images=False, force=True)
    assert not (out / "images").exists() and (out / "truth.json").is_file()
    assert not (out / "calibration").exists()
    # Without images there is nothing to calibrate from: camera.json is the true camera, and
    # the truth says why.
    assert load_camera(out / "camera.json") == cfg.scene.camera
    t = load_truth(out)
    assert t.calibrated_camera is None and not t.calibration.calibrated
    assert "truth only" in t.calibration.note and t.data["calibrated_camera"] is None
    foreign = tmp_path / "real_campaign"
    (foreign / "images").mkdir(parents=True)
    (foreign / "images" / "img.png").write_bytes(b"raw")
    with pytest.raises(InputError, match="nothing was deleted"):
        write_campaign(foreign, cfg, render_images=False, force=True)
    assert (foreign / "images" / "img.png").read_bytes() == b"raw"


def test_positions_the_scene_or_robot_cannot_serve_are_named(tmp_path):
    far = [[0.0, 0.0, -310.0], [600.0, 0.0, -310.0]]
    with pytest.raises(InputError, match=r"position 2 \(600, 0, -310\) mm.*leaves the image"):
        write_campaign(tmp_path / "a", _config(positions=far, robot=VirtualRobot(smooth_field)))
    with pytest.raises(InputError, match=r"position 2 \(0, 0, -900\) mm: the robot model has no stiffness"):
        write_campaign(tmp_path / "b", _config(positions=[[0.0, 0.0, -310.0], [0.0, 0.0, -900.0]]))
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()  # nothing written


def test_load_truth_refuses_other_files(tmp_path):
    (tmp_path / "truth.json").write_text('{"format": "something else"}')
    with pytest.raises(InputError, match="not a stiffmap simulation"):
        load_truth(tmp_path)
    with pytest.raises(InputError, match="no truth.json"):
        load_truth(tmp_path / "missing")


def test_default_scene_sees_both_boards_at_every_paper48_position():
    sc = default_scene()
    # 40 px from the border with the platform moved 10 mm in any direction (85 px nominal).
    sc.check_visible(paper48(), border_px=40.0, slack_mm=10.0)
    # And resolved: at least 2.3 px per mm on either board everywhere.
    for p in paper48()[[0, 3, 12, 15, 32, 35, 44, 47]]:
        for name, uv in sc.outline_pixels(np.r_[np.c_[np.eye(3), p], [[0, 0, 0, 1]]]).items():
            width_mm = (9 + 1 + 2) * 10.0 if name == "fixed" else (6 + 1 + 2) * 10.0
            assert np.linalg.norm(uv[1] - uv[0]) / width_mm > 2.3, (name, p)
    assert isinstance(sc.camera.to_dict(), dict)


def test_sensor_campaign_is_reproducible_and_names_bad_points(tmp_path):
    pts = [[400.0, 270.0], [300.0, 320.0]]
    a = write_sensor_campaign(tmp_path / "a", PRR3(kj=600.0), pts, directions=("y",), repeats=2, seed=9)
    write_sensor_campaign(tmp_path / "b", PRR3(kj=600.0), pts, directions=("y",), repeats=2, seed=9)
    assert a.n_recordings == 4
    for f in sorted((tmp_path / "a").rglob("*")):
        if f.is_file():
            assert f.read_bytes() == (tmp_path / "b" / f.relative_to(tmp_path / "a")).read_bytes(), f
    truth = load_truth(tmp_path / "a")
    assert truth.camera is None and truth.K.shape == (2, 2, 2)
    np.testing.assert_allclose(truth.K, PRR3(kj=600.0).stiffness(np.array(pts)), rtol=1e-12)
    with pytest.raises(InputError, match=r"position 2 \(400, 900\) mm: the robot model has no stiffness"):
        write_sensor_campaign(tmp_path / "c", PRR3(), [[400.0, 270.0], [400.0, 900.0]])
    assert not (tmp_path / "c").exists()
