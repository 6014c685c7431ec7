"""The virtual test-bed with several cameras: the scene's rig, its images and the campaign it writes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from stiffmap.campaign.spec import load_spec
from stiffmap.geometry import invert_transform, transform_from
from stiffmap.kinds import preset_points
from stiffmap.rig import load_rig
from stiffmap.sim.plan import RIG_MARGIN_PX, rig_scene
from stiffmap.sim.scene import default_scene, demo_scene, with_cameras

PAPER48 = np.array(preset_points("paper48"))


@pytest.mark.parametrize("n, angle", [(2, 60.0), (3, 50.0)])
def test_with_cameras_turns_copies_of_the_camera_about_the_vertical(n, angle):
    scene = default_scene()
    sc = with_cameras(scene, n, angle_deg=angle, distance_scale=1.2)
    cams = sc.cameras
    assert len(cams) == n and sc.rig is not None and sc.rig.names == tuple(f"cam{k + 1}" for k in range(n))
    axes = [T[:3, 2] for _, _, T in cams]
    # Consecutive cameras are angle/(n-1) apart about the base z axis, and keep the scene
    # camera's downward look (the z component of the optical axis).
    for a, b in zip(axes, axes[1:], strict=False):
        ha, hb = a[:2] / np.linalg.norm(a[:2]), b[:2] / np.linalg.norm(b[:2])
        step = np.degrees(np.arctan2(ha[0] * hb[1] - ha[1] * hb[0], ha @ hb))
        assert step == pytest.approx(angle / (n - 1), abs=1e-9)
        assert b[2] == pytest.approx(scene.cam2base[2, 2], abs=1e-12)
    # The optical axes all pass through one point (the pivot): their pairwise closest distance is 0.
    c0, a0 = cams[0][2][:3, 3], axes[0]
    for _, _, T in cams[1:]:
        c1, a1 = T[:3, 3], T[:3, 2]
        nrm = np.cross(a0, a1)
        assert abs((c1 - c0) @ nrm) / np.linalg.norm(nrm) < 1e-6
    # The rig's cam2rig are the cameras' poses relative to the first (rig frame = first camera).
    for rc, (_, _, T) in zip(sc.rig.cameras, cams, strict=True):
        np.testing.assert_allclose(rc.cam2rig, invert_transform(cams[0][2]) @ T, atol=1e-9)
    assert sc.cam2base is cams[0][2] or np.allclose(sc.cam2base, cams[0][2])


def test_targets_of_each_camera_are_the_same_boards_seen_from_it():
    sc = with_cameras(demo_scene(), 2, distance_scale=1.2)
    tcp2base = transform_from(np.eye(3), [50.0, -100.0, -300.0])
    t0 = {t.name: t.board2cam for t in sc.targets(tcp2base, 0)}
    t1 = {t.name: t.board2cam for t in sc.targets(tcp2base, 1)}
    cam2rig = sc.rig.cameras[1].cam2rig
    for name in ("fixed", "mobile"):
        # board2rig through camera 1 = board2cam of camera 0 (the rig frame).
        np.testing.assert_allclose(cam2rig @ t1[name], t0[name], atol=1e-9)


def test_rig_scene_steps_back_until_both_boards_are_in_every_view():
    scene = default_scene()
    with pytest.raises(ValueError):
        with_cameras(scene, 2, angle_deg=60.0).check_visible(PAPER48, border_px=20.0 + RIG_MARGIN_PX)
    sc = rig_scene(scene, 2, PAPER48)
    sc.check_visible(PAPER48, border_px=20.0 + RIG_MARGIN_PX)
    d0 = np.linalg.norm(scene.cam2base[:3, 3] - np.array([0.0, 0.0, -310.0]))
    d1 = np.linalg.norm(sc.cam2base[:3, 3] - np.array([0.0, 0.0, -310.0]))
    assert 1.0 < d1 / d0 < 1.3  # the smallest step back that does it (the default scene: 1.1)
    assert rig_scene(scene, 1, PAPER48) is scene
    with pytest.raises(ValueError, match="cameras must be 1 to 8"):
        rig_scene(scene, 9, PAPER48)


def test_simulate_with_two_cameras_writes_a_rig_campaign(tmp_path):
    from stiffmap.cli.main import main

    out = tmp_path / "sim"
    rc = main(
        [
            "simulate",
            str(out),
            "--cameras",
            "2",
            "--select",
            "1,2",
            "--repeats",
            "1",
            "--truth-only",
            "--json",
        ]
    )
    assert rc in (0, None)
    spec = load_spec(out)
    assert spec.camera is None and spec.cameras.rig == "rig.json"
    assert "{camera}" in spec.images.loaded
    rig = load_rig(out / "rig.json")
    truth = json.loads((out / "truth.json").read_text())
    np.testing.assert_allclose(
        np.array(truth["rig"]["cameras"][1]["cam2rig"]), rig.cameras[1].cam2rig, atol=1e-12
    )
    assert not (out / "camera.json").exists()
